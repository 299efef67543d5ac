//! # hil-bridge
//!
//! The wire protocol between the ground simulator and the flight firmware, the host runner that
//! drives QEMU, and the firmware itself. `no_std` at its core; the `std` feature adds host-side
//! helpers. For now it carries the protocol version both sides must agree on.
#![no_std]

/// Protocol version exchanged in the hello handshake; bumped on any incompatible change.
pub const PROTOCOL_VERSION: u16 = 1;

//! # hil-bridge
//!
//! The wire protocol between the ground simulator and the flight firmware, the host runner that
//! drives the firmware under QEMU, and (in `firmware/`, a separate crate for the Cortex-M target)
//! the firmware itself.
//!
//! ## Layers (see `docs/hil-protocol.md` for the byte tables)
//!
//! 1. [`cobs`]: `0x00`-delimited COBS framing of packets on any byte stream, with a fixed-size
//!    reassembly buffer.
//! 2. [`packet`]: `seq` (u16) · postcard message · CRC-32; typed errors for every way bytes can
//!    be wrong.
//! 3. [`msg`]: versioned messages — hello/handshake, frame header and chunks, acknowledgements,
//!    fix or typed no-fix, per-frame cost, status counters, errors.
//! 4. [`target`]: the target's stop-and-wait state machine over `embedded_io` traits, with frame
//!    reassembly and an end-to-end payload CRC.
//! 5. [`convert`]: nav-core results ↔ wire mirrors, bit for bit.
//! 6. [`flight`]: the flight configuration (frame and keypoint budgets) shared by the firmware
//!    and the host runner.
//! 7. [`job`]: the frame jobs of a descent (TRN, keyframe capture, odometry, hazard map) as both
//!    ends run them.
//!
//! With the default `std` feature the crate also holds the host side ([`host`]): the recorded
//! frame set, the QEMU runner and its CLI (`cargo run --release -p hil-bridge -- run`).
//!
//! ## Bounds
//!
//! | name | value | unit |
//! |---|---|---|
//! | [`packet::MAX_CHUNK_BYTES`] | 2048 | bytes of frame payload per chunk |
//! | [`packet::MAX_PACKET_BYTES`] | 2086 | bytes before COBS |
//! | [`packet::MAX_WIRE_BYTES`] | 2097 | bytes on the wire incl. both delimiters |
//! | [`target::TX_PACKET_BYTES`] | 448 | bytes of the target's largest message packet |
//!
//! `no_std`, no heap at its core; nothing panics on any input (the decoder is fuzzed).
#![cfg_attr(not(feature = "std"), no_std)]
#![cfg_attr(
    not(test),
    deny(
        clippy::unwrap_used,
        clippy::expect_used,
        clippy::panic,
        clippy::indexing_slicing
    )
)]

#[cfg(all(test, not(feature = "std")))]
extern crate std;

pub mod cobs;
pub mod convert;
pub mod flight;
pub mod job;
pub mod msg;
pub mod packet;
pub mod target;

#[cfg(feature = "std")]
pub mod host;

/// Protocol version exchanged in the hello handshake; bumped on any incompatible change.
pub const PROTOCOL_VERSION: u16 = 7;

pub use msg::Message;
pub use packet::{PacketError, Received, Receiver, decode_packet, encode_packet, encode_wire};

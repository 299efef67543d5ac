//! Host side (std): the recorded frame set, the host end of the link and the QEMU runner.
//!
//! Ordinary std code: the no-panic lints of the `no_std` core do not apply here.
#![allow(
    clippy::indexing_slicing,
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic
)]

pub mod frames;
pub mod link;
pub mod runner;

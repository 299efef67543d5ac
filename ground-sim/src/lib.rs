//! # ground-sim — Umbra's ground segment
//!
//! Terrain in and out, SAR/InSAR simulation, the reference tile builder and closed-loop
//! evaluation of nav-core. Everything runs on the host with `std`.

pub mod analysis;
pub mod dem;
pub mod matchplot;
pub mod register;
pub mod render;
pub mod terrain;
pub mod tile;

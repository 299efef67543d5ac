//! # ground-sim — Umbra's ground segment
//!
//! Terrain in and out, SAR/InSAR simulation, the reference tile builder and closed-loop
//! evaluation of nav-core. Everything runs on the host with `std`.
//!
//! * [`sar`]: dual-antenna SAR echoes over a DEM and Range-Doppler focusing (paper section II).

pub mod sar;

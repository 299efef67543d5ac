//! The flight code scored against the truth: one frame ([`trn`]), one image pair
//! ([`register`]) and closed-loop hops ([`descent`]).

pub mod calibrate;
pub mod campaign;
pub mod descent;
pub mod navmap;
pub mod register;
pub mod rehearsal;
pub mod shard;
pub mod suite;
pub mod trn;

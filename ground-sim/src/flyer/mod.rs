//! The flyer's side as the ground simulates it: the frames its ranging sensor produces
//! ([`frames`]) and nav-core's flight code run on them in-process ([`onboard`]).

pub mod frames;
pub mod onboard;

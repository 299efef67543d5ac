//! `ground-sim` command-line interface.
fn main() {}

//! Puts `memory.x` on the linker path and links the reference tile and the flight atlas into
//! flash.
//!
//! The tile comes from `UMBRA_HIL_TILE` (a path) or, by default, from the recorded frame set
//! that `cargo run --release -p hil-bridge -- gen` writes to `target/hil/data/tile.bin`.
use std::path::PathBuf;
use std::{env, fs};

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("OUT_DIR"));
    let manifest = PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").expect("manifest dir"));
    fs::copy(manifest.join("memory.x"), out.join("memory.x")).expect("copy memory.x");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=memory.x");
    if env::var_os("CARGO_FEATURE_DEFMT").is_some() {
        println!("cargo:rustc-link-arg=-Tdefmt.x");
    }
    println!("cargo:rerun-if-env-changed=UMBRA_HIL_TILE");
    let tile = env::var_os("UMBRA_HIL_TILE")
        .map(PathBuf::from)
        .unwrap_or_else(|| manifest.join("../../target/hil/data/tile.bin"));
    println!("cargo:rerun-if-changed={}", tile.display());
    let bytes = fs::read(&tile).unwrap_or_else(|e| {
        panic!(
            "reference tile {}: {e}\nwrite it first: cargo run --release -p hil-bridge -- gen",
            tile.display()
        )
    });
    fs::write(out.join("tile.bin"), bytes).expect("write tile");
    // The flight atlas cut from the same map, written beside the tile by `gen`.
    println!("cargo:rerun-if-env-changed=UMBRA_HIL_ATLAS");
    let atlas = env::var_os("UMBRA_HIL_ATLAS")
        .map(PathBuf::from)
        .unwrap_or_else(|| manifest.join("../../target/hil/data/atlas.bin"));
    println!("cargo:rerun-if-changed={}", atlas.display());
    let bytes = fs::read(&atlas).unwrap_or_else(|e| {
        panic!(
            "flight atlas {}: {e}\nwrite it first: cargo run --release -p hil-bridge -- gen",
            atlas.display()
        )
    });
    fs::write(out.join("atlas.bin"), bytes).expect("write atlas");
}

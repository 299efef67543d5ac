//! Fuzz the reference-tile parser: any byte string must give `Ok` or a typed error, never a
//! panic, and a parsed tile's accessors must be usable for every index.
#![no_main]

use libfuzzer_sys::fuzz_target;
use nav_core::Tile;

fuzz_target!(|data: &[u8]| {
    if let Ok(tile) = Tile::parse(data) {
        for i in 0..tile.len() {
            let k = tile.keypoint(i);
            assert!(k.x_px.is_finite() && k.scale_px > 0.0);
            assert!(tile.descriptor(i).iter().all(|v| v.is_finite()));
        }
    }
});

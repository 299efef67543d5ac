//! Fuzz the atlas reader: any byte string must give `Ok` or a typed error, never a panic; a
//! parsed index must rank tiles for any prior, and both tile sources must read every entry
//! without panicking.
#![no_main]

use libfuzzer_sys::fuzz_target;
use nav_core::Prior;
use nav_core::atlas::{Atlas, BufferedAtlas, MappedAtlas, TileSource};

fuzz_target!(|data: &[u8]| {
    if let Ok(a) = Atlas::parse(data) {
        let p = Prior {
            center_tile_px: [data.len() as f32 * 0.37, 10.0],
            sigma_px: 4.0,
            heading_rad: 0.0,
            heading_sigma_rad: 0.1,
            scale: 0.5,
            scale_sigma: 0.02,
        };
        let c = a.select(&p, 200, 200);
        assert!(c.as_slice().len() <= nav_core::atlas::MAX_ATLAS_CANDIDATES);
        let mut store = [0u8; 65_536];
        if let Ok(mut b) = BufferedAtlas::new(data, data, &mut store) {
            for i in 0..a.len().min(8) {
                let _ = b.tile(i as u16).map(|t| t.len());
            }
        }
    }
    let _ = MappedAtlas::<8>::new(data);
});

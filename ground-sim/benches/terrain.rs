//! Criterion bench: the default 4 km × 4 km, 5 m (800 × 800) presets. Target ≤ 2 s on 2 cores.

use criterion::{Criterion, criterion_group, criterion_main};
use ground_sim::terrain::{Preset, TerrainParams, generate};
use indicatif::ProgressBar;

fn bench_presets(c: &mut Criterion) {
    let mut g = c.benchmark_group("terrain_800x800");
    g.sample_size(10);
    for preset in [Preset::Shackleton, Preset::Shoemaker] {
        let p = TerrainParams::new(preset);
        g.bench_function(format!("{preset:?}"), |b| {
            b.iter(|| generate(&p, &ProgressBar::hidden()).map(|(d, _)| d.width()))
        });
    }
    g.finish();
}

criterion_group!(benches, bench_presets);
criterion_main!(benches);

//! SAR simulation benchmarks.
//!
//! * `echo/fast` vs `echo/time_domain`: one antenna's raw echoes of a 12×12-node Gaussian hill
//!   (242 facets, both channels); their ratio is the fast method's speed-up over the oracle.
//! * `focus/rda`: range-Doppler focusing of those echoes.
//! * `pipeline/flat_1km`: a whole 1 km × 1 km, 5 m scene, both antennas, echoes + focusing.
//!
//! The full 4 km × 4 km, 5 m scene takes tens of seconds, too long for criterion's ten samples:
//! with `UMBRA_BENCH_FULL=1` it runs once first and prints its stage timings. (The CLI does
//! the same: `ground-sim sar --synthetic bowl --size-m 4000 --out DIR`, timings in
//! `DIR/report.json`.)

use std::hint::black_box;
use std::time::Duration;

use criterion::{Criterion, criterion_group};
use ground_sim::sar::echo::EchoSimulator;
use ground_sim::sar::geometry::{AcquisitionPlan, Antenna, Geometry, SarDem};
use ground_sim::sar::pipeline::{SimOptions, simulate_with};
use ground_sim::sar::rda::RdaProcessor;
use ground_sim::sar::scene::{
    AnalyticSurface, Scatterers, analytic_dem, build_facets, facet_scatterers,
};
use ground_sim::sar::{SarConfig, SarResult};
use indicatif::ProgressBar;

struct Small {
    sim: EchoSimulator,
    rda: RdaProcessor,
    scat: Scatterers,
    yz: [f64; 2],
    zref: f64,
}

fn small_scene() -> SarResult<Small> {
    let cfg = SarConfig {
        noise_equivalent_sigma0_db: f64::NEG_INFINITY,
        ..SarConfig::default()
    };
    let d = cfg.derived()?;
    let dem: SarDem = analytic_dem(AnalyticSurface::Hill, 12, 5.0)?;
    let g = Geometry::new(&dem, &cfg, &d)?;
    let plan = AcquisitionPlan::new(&dem, &cfg, &d, g)?;
    let facets = build_facets(&dem, &plan.geometry)?;
    let (scat, _) = facet_scatterers(&facets, &plan.geometry, &cfg, 1.0);
    Ok(Small {
        sim: EchoSimulator::new(&cfg, &d, plan.window, plan.pulses)?,
        rda: RdaProcessor::new(&cfg, &d, &plan)?,
        scat,
        yz: plan.geometry.antenna_yz(Antenna::A1),
        zref: plan.geometry.reference_height_m,
    })
}

fn bench_echo(c: &mut Criterion) {
    let s = match small_scene() {
        Ok(s) => s,
        Err(e) => {
            eprintln!("small scene setup failed: {e}");
            return;
        }
    };
    let hidden = ProgressBar::hidden();
    let mut g = c.benchmark_group("echo");
    g.bench_function("fast", |b| {
        b.iter(|| black_box(s.sim.simulate_fast(&s.scat, Antenna::A1, s.yz, &hidden)))
    });
    g.bench_function("time_domain", |b| {
        b.iter(|| black_box(s.sim.simulate_time_domain(&s.scat, Antenna::A1, s.yz)))
    });
    g.finish();
    let raw = match s.sim.simulate_fast(&s.scat, Antenna::A1, s.yz, &hidden) {
        Ok(r) => r,
        Err(e) => {
            eprintln!("echo failed: {e}");
            return;
        }
    };
    c.bench_function("focus/rda", |b| {
        b.iter(|| black_box(s.rda.focus(&raw, s.yz, s.zref, &hidden)))
    });
}

fn bench_pipeline(c: &mut Criterion) {
    let cfg = SarConfig::default();
    let Ok(dem) = analytic_dem(AnalyticSurface::Bowl, 201, 5.0) else {
        return;
    };
    c.bench_function("pipeline/bowl_1km_both_antennas", |b| {
        b.iter(|| black_box(simulate_with(&dem, &cfg, &SimOptions::default())))
    });
}

fn full_scene_once() {
    if std::env::var_os("UMBRA_BENCH_FULL").is_none() {
        return;
    }
    let cfg = SarConfig::default();
    match analytic_dem(AnalyticSurface::Bowl, 401, 10.0)
        .and_then(|dem| simulate_with(&dem, &cfg, &SimOptions::default()))
    {
        Ok(p) => eprintln!(
            "full 4 km scene, 5 m mesh, both antennas, {} channel(s): scene {:.2} s, echoes {:.2} s, focusing {:.2} s, total {:.2} s, peak RSS {:?} MiB",
            cfg.polarisations.len(),
            p.timings.scene_s,
            p.timings.echoes_s,
            p.timings.focusing_s,
            p.timings.total_s,
            ground_sim::sar::products::peak_memory_mib()
        ),
        Err(e) => eprintln!("full scene failed: {e}"),
    }
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(10).measurement_time(Duration::from_secs(8));
    targets = bench_echo, bench_pipeline
}

fn main() {
    full_scene_once();
    benches();
    Criterion::default().configure_from_args().final_summary();
}

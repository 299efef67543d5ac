//! End-to-end checks of the SAR chain against closed forms and the time-domain oracle.
//! Scenes are small so the whole module runs in seconds with the test profile.

use super::config::{Polarisation, SarConfig};
use super::geometry::{Antenna, SarDem};
use super::pipeline::{EchoMethod, SimOptions, simulate_with};
use super::psf::run_point_target;
use super::scattering::TwoScaleModel;
use super::scene::{AnalyticSurface, analytic_dem};
use super::slc::Slc;

fn quiet(mut cfg: SarConfig) -> SarConfig {
    cfg.noise_equivalent_sigma0_db = f64::NEG_INFINITY;
    cfg
}

#[test]
fn point_target_meets_the_issue_targets() {
    let r = run_point_target(&SarConfig::default()).unwrap();
    eprintln!(
        "{}",
        serde_json::to_string(&(&r.range, &r.azimuth, r.peak_offset_px)).unwrap()
    );
    let d = &r.derived;
    assert!((d.range_irw_theory_m - 5.71).abs() < 0.01);
    assert!(r.range.irw_error_pct.abs() < 2.0, "range IRW {:?}", r.range);
    assert!(r.range.pslr_db <= -40.0, "range PSLR {}", r.range.pslr_db);
    assert!(r.range.islr_db <= -33.0, "range ISLR {}", r.range.islr_db);
    assert!(
        r.azimuth.pslr_db <= -40.0,
        "azimuth PSLR {}",
        r.azimuth.pslr_db
    );
    assert!(
        r.azimuth.irw_error_pct.abs() < 2.0,
        "azimuth IRW {:?}",
        r.azimuth
    );
    assert!(r.peak_offset_px <= 0.05, "peak offset {}", r.peak_offset_px);
    assert!(
        r.interferometric_phase_error_deg.abs() <= 0.1,
        "phase error {}",
        r.interferometric_phase_error_deg
    );
    // Gains are calibrated (unit target → unit peak) and the carrier phase is kept.
    assert!((r.peak_amplitude_ratio - 1.0).abs() < 0.02);
    assert!(
        r.slc_phase_error_deg.abs() < 1.0,
        "{}",
        r.slc_phase_error_deg
    );
    // JSON carries the keys the issue lists.
    let v: serde_json::Value = serde_json::to_value(&r).unwrap();
    for key in [
        "/range/irw_m",
        "/range/irw_theory_m",
        "/range/pslr_db",
        "/range/islr_db",
        "/azimuth/irw_m",
        "/azimuth/pslr_db",
        "/azimuth/islr_db",
        "/peak_offset_px",
        "/interferometric_phase_error_deg",
    ] {
        assert!(
            v.pointer(key).is_some_and(|x| x.is_number()),
            "missing {key}"
        );
    }
}

fn normalised_error_db(a: &Slc, b: &Slc) -> f64 {
    assert_eq!((a.lines, a.gates), (b.lines, b.gates));
    let (mut num, mut den) = (0.0f64, 0.0f64);
    for (x, y) in a.data.iter().zip(&b.data) {
        num += f64::from((x - y).norm_sqr());
        den += f64::from(y.norm_sqr());
    }
    10.0 * (num / den).log10()
}

#[test]
fn fast_echoes_match_the_time_domain_oracle() {
    let cfg = quiet(SarConfig::default());
    let dem = analytic_dem(AnalyticSurface::Hill, 12, 5.0).unwrap();
    let run = |method| {
        simulate_with(
            &dem,
            &cfg,
            &SimOptions {
                method,
                ..SimOptions::default()
            },
        )
        .unwrap()
    };
    let fast = run(EchoMethod::Fast);
    let oracle = run(EchoMethod::TimeDomain);
    for (f, o) in fast.slcs.iter().zip(&oracle.slcs) {
        let e = normalised_error_db(f, o);
        eprintln!(
            "{:?} {:?}: fast vs oracle {e:.1} dB",
            f.antenna, f.polarisation
        );
        assert!(e < -40.0, "{:?} {:?}: {e:.1} dB", f.antenna, f.polarisation);
        // Phases at the ten brightest oracle pixels.
        let mut idx: Vec<usize> = (0..o.data.len()).collect();
        idx.sort_by(|&a, &b| o.data[b].norm_sqr().total_cmp(&o.data[a].norm_sqr()));
        let mut worst = 0.0f64;
        for &i in &idx[..10] {
            let d = (f.data[i] * o.data[i].conj()).arg().to_degrees();
            worst = worst.max(f64::from(d.abs()));
            assert!(d.abs() < 0.05, "pixel {i}: phase differs by {d}°");
        }
        eprintln!("worst peak phase difference {worst:.4}°");
    }
}

/// Mean of σ0 over the SLC interior (margins of `m` lines/gates dropped).
fn interior_mean_sigma0(slc: &Slc, m: usize) -> f64 {
    let s0 = slc.sigma0();
    let (mut sum, mut n) = (0.0, 0usize);
    for i in m..slc.lines - m {
        for j in m..slc.gates - m {
            sum += f64::from(s0[i * slc.gates + j]);
            n += 1;
        }
    }
    sum / n as f64
}

fn db(x: f64) -> f64 {
    10.0 * x.log10()
}

#[test]
fn flat_scene_sigma0_follows_spm_closed_form() {
    let cfg = quiet(SarConfig::default());
    let dem = analytic_dem(AnalyticSurface::Flat, 96, 5.0).unwrap();
    let pair = simulate_with(&dem, &cfg, &SimOptions::default()).unwrap();
    let model = TwoScaleModel::from_config(&cfg);
    for pol in [Polarisation::HH, Polarisation::VV] {
        let slc = pair.slc(Antenna::A1, pol).unwrap();
        let theta = slc.flat_incidence_rad(slc.gates as f64 / 2.0);
        let want = model.sigma0_spm(pol, theta);
        let got = interior_mean_sigma0(slc, 20);
        eprintln!("{pol:?} flat: {:.3} dB vs SPM {:.3} dB", db(got), db(want));
        assert!(
            (db(got) - db(want)).abs() < 0.4,
            "{pol:?}: {:.2} dB vs SPM {:.2} dB",
            db(got),
            db(want)
        );
    }
    check_flat_interferogram(
        pair.slc(Antenna::A1, Polarisation::HH).unwrap(),
        pair.slc(Antenna::A2, Polarisation::HH).unwrap(),
        pair.plan.geometry.reference_height_m,
    );
}

/// Over flat clutter the A1/A2 pair is coherent and its phase is the flat-Moon phase
/// −4π(R1 − R2)/λ of the ground point at each A1 gate (no co-registration: A2 sees each point
/// ≈ 0.25 gate farther, which costs a little coherence only).
fn check_flat_interferogram(s1: &Slc, s2: &Slc, zref: f64) {
    let (mut acc, mut p1, mut p2) = (super::C64::new(0.0, 0.0), 0.0, 0.0);
    let h1 = s1.antenna_yz_m[1] - zref;
    for i in 20..s1.lines - 20 {
        for j in 20..s1.gates - 20 {
            let r1 = s1.range_of_gate(j as f64);
            let y = s1.antenna_yz_m[0] + (r1 * r1 - h1 * h1).sqrt();
            let r2 =
                ((y - s2.antenna_yz_m[0]).powi(2) + (zref - s2.antenna_yz_m[1]).powi(2)).sqrt();
            let phi = -4.0 * std::f64::consts::PI * (r1 - r2) / s1.wavelength_m;
            let (a, b) = (s1.data[i * s1.gates + j], s2.data[i * s2.gates + j]);
            let (a, b) = (
                super::C64::new(a.re.into(), a.im.into()),
                super::C64::new(b.re.into(), b.im.into()),
            );
            acc += a * b.conj() * super::C64::from_polar(1.0, -phi);
            p1 += a.norm_sqr();
            p2 += b.norm_sqr();
        }
    }
    let coherence = acc.norm() / (p1 * p2).sqrt();
    let phase = acc.arg().to_degrees();
    eprintln!("flat interferogram: coherence {coherence:.4}, residual phase {phase:.3}°");
    assert!(coherence > 0.9, "coherence {coherence}");
    assert!(phase.abs() < 1.0, "residual phase {phase}°");
}

#[test]
fn tilted_scene_sigma0_follows_ka_closed_form() {
    // A plane rising away from the radar at β = 18°: local incidence 26° − 18° = 8° (KA).
    // Per slant-range cell it holds sin θ/sin(θ − β) times more surface than flat ground.
    let cfg = quiet(SarConfig::default());
    let (n, px) = (96usize, 5.0);
    let beta = 18f64.to_radians();
    let z: Vec<f32> = (0..n * n)
        .map(|i| ((i % n) as f64 * px * beta.tan()) as f32)
        .collect();
    let dem = SarDem::new_checked(n, n, px, z, [0.0, 0.0]).unwrap();
    let pair = simulate_with(&dem, &cfg, &SimOptions::default()).unwrap();
    let model = TwoScaleModel::from_config(&cfg);
    let slc = pair.slc(Antenna::A1, Polarisation::HH).unwrap();
    let theta = 26f64.to_radians();
    let local = theta - beta;
    assert!(local < model.switch_angle_rad(Polarisation::HH));
    let want = model.sigma0_ka(Polarisation::HH, local);
    // The slope compresses the scene into fewer gates: average over its middle.
    let s0 = slc.sigma0();
    let (mut sum, mut cnt) = (0.0, 0usize);
    let (j_mid, half) = (slc.gates / 2, slc.gates / 6);
    for i in 20..slc.lines - 20 {
        for j in j_mid - half..j_mid + half {
            sum += f64::from(s0[i * slc.gates + j]);
            cnt += 1;
        }
    }
    let got = sum / cnt as f64 * (theta - beta).sin() / theta.sin();
    eprintln!("tilted: {:.3} dB vs KA {:.3} dB", db(got), db(want));
    assert!(
        (db(got) - db(want)).abs() < 0.5,
        "{:.2} dB vs KA {:.2} dB",
        db(got),
        db(want)
    );
}

#[test]
fn thermal_noise_floor_is_the_configured_nesz() {
    let cfg = SarConfig {
        noise_equivalent_sigma0_db: -20.0,
        polarisations: vec![Polarisation::HH],
        ..SarConfig::default()
    };
    let dem = analytic_dem(AnalyticSurface::Flat, 160, 5.0).unwrap();
    let pair = simulate_with(
        &dem,
        &cfg,
        &SimOptions {
            clutter_scale: 0.0,
            ..SimOptions::default()
        },
    )
    .unwrap();
    for a in Antenna::BOTH {
        let slc = pair.slc(a, Polarisation::HH).unwrap();
        let got = db(interior_mean_sigma0(slc, 4));
        eprintln!("{a:?} noise floor {got:.3} dB");
        assert!((got + 20.0).abs() < 0.3, "{a:?}: noise floor {got:.2} dB");
    }
    // Independent receivers: the two antennas' noise is uncorrelated.
    let (s1, s2) = (
        pair.slc(Antenna::A1, Polarisation::HH).unwrap(),
        pair.slc(Antenna::A2, Polarisation::HH).unwrap(),
    );
    let (mut c, mut p1, mut p2) = (super::C64::new(0.0, 0.0), 0.0, 0.0);
    for (a, b) in s1.data.iter().zip(&s2.data) {
        let (a, b) = (
            super::C64::new(a.re.into(), a.im.into()),
            super::C64::new(b.re.into(), b.im.into()),
        );
        c += a * b.conj();
        p1 += a.norm_sqr();
        p2 += b.norm_sqr();
    }
    assert!(c.norm() / (p1 * p2).sqrt() < 0.05);
}

#[test]
fn avx2_echoes_are_the_baseline_bits() {
    use super::echo::{EchoSimulator, Isa};
    use super::geometry::{AcquisitionPlan, Geometry};
    use super::scene::{build_facets, facet_scatterers};
    let cfg = quiet(SarConfig::default());
    let d = cfg.derived().unwrap();
    let dem = analytic_dem(AnalyticSurface::Hill, 12, 5.0).unwrap();
    let g = Geometry::new(&dem, &cfg, &d).unwrap();
    let plan = AcquisitionPlan::new(&dem, &cfg, &d, g).unwrap();
    let facets = build_facets(&dem, &plan.geometry).unwrap();
    let (scat, _) = facet_scatterers(&facets, &plan.geometry, &cfg, 1.0);
    let sim = EchoSimulator::new(&cfg, &d, plan.window, plan.pulses).unwrap();
    let hidden = indicatif::ProgressBar::hidden();
    #[cfg(target_arch = "x86_64")]
    eprintln!(
        "this CPU has AVX2: {} (without it both runs take the baseline build)",
        std::arch::is_x86_feature_detected!("avx2")
    );
    for antenna in [Antenna::A1, Antenna::A2] {
        let yz = plan.geometry.antenna_yz(antenna);
        let run = |isa| {
            sim.simulate_fast_with(&scat, antenna, yz, &hidden, isa)
                .unwrap()
        };
        let (best, base) = (run(Isa::Detect), run(Isa::Baseline));
        assert_eq!(best.data.len(), base.data.len());
        let differ = best
            .data
            .iter()
            .zip(&base.data)
            .filter(|(a, b)| a.re.to_bits() != b.re.to_bits() || a.im.to_bits() != b.im.to_bits())
            .count();
        assert_eq!(differ, 0, "{antenna:?}: {differ} samples differ");
        assert!(base.data.iter().any(|v| v.norm_sqr() > 0.0));
    }
    // A scatterer the pulses' search on `x` cannot place is an error, not a silent gap.
    let mut bad = scat.clone();
    bad.x_m[0] = f64::NAN;
    let yz = plan.geometry.antenna_yz(Antenna::A1);
    for isa in [Isa::Detect, Isa::Baseline] {
        let e = sim
            .simulate_fast_with(&bad, Antenna::A1, yz, &hidden, isa)
            .unwrap_err();
        assert!(e.to_string().contains("non-finite"), "{e}");
    }
    assert!(sim.simulate_time_domain(&bad, Antenna::A1, yz).is_err());
}

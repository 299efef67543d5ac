//! End-to-end checks of the InSAR chain on small scenes (SAR simulation inside), so the module
//! runs in seconds with the test profile. Full 4 km scenes: `docs/insar.md` (ignored tests).

use super::accuracy::{Accuracy, compare};
use super::pipeline::{ChainRun, InsarConfig, run_from_dem};
use crate::dem::{Dem, GeoRef};
use crate::sar::{Polarisation, SarConfig};

/// A north-up local-metric DEM of `n × n` pixels of `px` metres; `f(x east, y south)` in metres
/// from the upper-left pixel centre. Rows = azimuth, columns = ground range.
pub(super) fn scene(n: usize, px: f64, f: impl Fn(f64, f64) -> f64) -> Dem {
    let z = (0..n * n)
        .map(|i| f((i % n) as f64 * px, (i / n) as f64 * px) as f32)
        .collect();
    Dem::new(n, n, z, GeoRef::local(1000.0, 5000.0, px, "insar test")).unwrap()
}

pub(super) fn quiet() -> SarConfig {
    SarConfig {
        noise_equivalent_sigma0_db: f64::NEG_INFINITY,
        ..SarConfig::default()
    }
}

pub(super) fn chain(dem: &Dem, sar: &SarConfig) -> (ChainRun, Accuracy) {
    let run = run_from_dem(dem, sar, Polarisation::HH, &InsarConfig::default(), false).unwrap();
    let acc = compare(&run.product, &run.truth.grid, Some(&run.truth.window)).unwrap();
    eprintln!(
        "matched rmse {:.3} m slope {:.3}°; rmse {:.3} m bias {:+.3} m crlb {:.3} m slope rmse {:.3}° bias {:+.3}° valid {:.4} coh {:.5} \
         radar coh {:.5} looks {:.2} coreg {:?}",
        acc.height_rmse_window_matched_m,
        acc.slope_rmse_window_matched_deg,
        acc.height_rmse_m,
        acc.height_bias_m,
        acc.crlb_height_m,
        acc.slope_rmse_deg,
        acc.slope_bias_deg,
        acc.valid_fraction,
        acc.coherence_mean,
        run.product.coherence_mean_radar,
        run.product.effective_looks,
        run.product.coreg.check
    );
    (run, acc)
}

#[test]
fn flat_terrain_gives_zero_height() {
    let dem = scene(160, 5.0, |_, _| -2000.0);
    let (run, a) = chain(&dem, &quiet());
    assert!(a.height_bias_m.abs() < 0.5, "bias {}", a.height_bias_m);
    assert!(a.height_rmse_m < 0.5, "rmse {}", a.height_rmse_m);
    assert!(a.valid_fraction > 0.99, "valid {}", a.valid_fraction);
    // The measured A2 − A1 offset agrees with the geometric prediction to 0.02 gate, and
    // coregistration is worth having.
    let c = run.product.coreg.check.unwrap();
    assert!(c.residual_gates.abs() < 0.02, "{c:?}");
    assert!(c.coherence_at_prediction > c.coherence_without_coregistration);
    // The flat phase is removed: the wrapped phase Δφ sits at zero, Δφ0 ramps across range.
    let r = &run.product.radar;
    let mid = r.lines / 2 * r.cols;
    let (first, last) = (
        r.phase_with_flat_rad[mid + 2],
        r.phase_with_flat_rad[mid + r.cols - 3],
    );
    assert!(
        (first - last).abs() > 0.5,
        "flat phase should ramp: {first} … {last}"
    );
    assert!(r.phase_rad[mid + r.cols / 2].abs() < 0.01);
    // With the SAR's default thermal noise (NESZ −30 dB) the mean stays at zero.
    let (_, a) = chain(&dem, &SarConfig::default());
    assert!(a.height_bias_m.abs() < 0.5, "bias {}", a.height_bias_m);
}

/// Mean slope (degrees) of the valid pixels of `d` at least `margin` pixels from the border.
fn mean_slope(d: &Dem, margin: usize) -> f64 {
    let s = crate::dem::stats::slope_deg(d).unwrap();
    let (w, h) = (d.width(), d.height());
    let (mut acc, mut n) = (0.0, 0.0);
    for r in margin..h - margin {
        for c in margin..w - margin {
            let v = s[r * w + c];
            if v.is_finite() {
                acc += f64::from(v);
                n += 1.0;
            }
        }
    }
    acc / n
}

#[test]
fn tilted_planes_give_their_slope() {
    // 8° rising along ground range (facing the radar) and 8° along azimuth.
    let t = 8f64.to_radians().tan();
    for (name, dem) in [
        ("range", scene(160, 5.0, |x, _| -2000.0 + t * x)),
        ("azimuth", scene(160, 5.0, |_, y| -2000.0 + t * y)),
    ] {
        let (run, a) = chain(&dem, &quiet());
        let got = mean_slope(&run.product.dem, 3);
        let want = mean_slope(&run.truth.grid, 3);
        eprintln!("{name}: slope {got:.3}° vs truth {want:.3}°");
        assert!((want - 8.0).abs() < 0.05, "{want}");
        assert!((got - want).abs() < 0.2, "{name}: {got} vs {want}");
        assert!(a.height_rmse_m < 1.0, "{name}: rmse {}", a.height_rmse_m);
    }
}

#[test]
fn a_wall_steeper_than_the_incidence_is_masked_as_eq20_says() {
    // A 35° slope facing the radar (steeper than θ ≈ 26°: layover) across the middle of a
    // 1 km scene, flat elsewhere.
    let t = 35f64.to_radians().tan();
    let dem = scene(200, 5.0, |x, _| -2000.0 + t * (x - 400.0).clamp(0.0, 200.0));
    let (run, a) = chain(&dem, &quiet());
    let p = &run.product;
    eprintln!(
        "eq 20 layover {:.3}, masked {:.3} ({:?}), eq 20 pixels masked {:.3}",
        a.eq20_layover_fraction, a.masked_fraction, p.mask, a.eq20_masked_fraction
    );
    assert!(a.eq20_layover_fraction > 0.1);
    // Every pixel that eq 20 says is in layover is masked (or next to a masked one), and the
    // masked share is at least the eq 20 share.
    assert!(a.eq20_masked_fraction > 0.95, "{}", a.eq20_masked_fraction);
    assert!(a.masked_fraction >= 0.9 * a.eq20_layover_fraction);
    assert!(p.mask.layover > 0.0);
    // The flat parts keep their heights.
    assert!(a.height_rmse_m < 5.0, "rmse {}", a.height_rmse_m);
}

#[test]
fn a_second_look_maps_the_wall_the_first_has_in_layover() {
    use super::pipeline::{LookDirections, mirror_columns, run_from_dem_looks};
    assert_eq!(
        mirror_columns(&[1, 2, 3, 4, 5, 6], 3),
        vec![3, 2, 1, 6, 5, 4]
    );
    // The wall of the test above, 35° facing the east-looking radar: layover for it, a gentle
    // slope facing away for a radar looking west.
    let t = 35f64.to_radians().tan();
    let dem = scene(200, 5.0, |x, _| -2000.0 + t * (x - 400.0).clamp(0.0, 200.0));
    // Masks by geometry and coherence only: the default brightness rule (12 dB below the
    // median) also drops the wall for the west look, where it faces away at a 61° local
    // incidence and is dark though not in shadow (19 % of this small scene).
    let cfg = InsarConfig {
        shadow_below_median_db: f64::INFINITY,
        ..InsarConfig::default()
    };
    let one = run_from_dem_looks(
        &dem,
        &quiet(),
        Polarisation::HH,
        &cfg,
        false,
        LookDirections::One,
    )
    .unwrap();
    let both = run_from_dem_looks(
        &dem,
        &quiet(),
        Polarisation::HH,
        &cfg,
        false,
        LookDirections::Both,
    )
    .unwrap();
    let a1 = compare(&one.product, &one.truth.grid, None).unwrap();
    let a2 = compare(&both.product, &both.truth.grid, None).unwrap();
    let f = both.product.look_fusion.expect("fusion report");
    eprintln!(
        "one look: valid {:.3} rmse {:.2} m; both: valid {:.3} rmse {:.2} m; {f:?}",
        a1.valid_fraction, a1.height_rmse_m, a2.valid_fraction, a2.height_rmse_m
    );
    assert!(one.product.look_fusion.is_none());
    // The east pass loses the wall; the west pass fills it, and the fused map is complete.
    assert!(a1.eq20_layover_fraction > 0.1);
    assert!(f.west_only > 0.8 * a1.eq20_layover_fraction, "{f:?}");
    assert!(a2.valid_fraction > 0.98, "valid {}", a2.valid_fraction);
    assert!(a2.valid_fraction > a1.valid_fraction + 0.1);
    // With the wall's heights in, the map stays within a few metres (the wall seen at a 61°
    // local incidence is noisier than the flat parts). Over radar seeds 1–6 the fused RMSE is
    // 4.6–5.7 m (session 22, once each pass drew its own speckle); a wrong cycle or a missing
    // wall would be hundreds of metres or a hole.
    assert!(a2.height_rmse_m < 6.5, "rmse {}", a2.height_rmse_m);
    let fused_valid = both
        .product
        .labels
        .iter()
        .filter(|&&l| l == super::label::VALID)
        .count();
    let sum = f.both_valid + f.east_only + f.west_only;
    assert!((fused_valid as f64 / both.product.labels.len() as f64 - sum).abs() < 1e-9);
    // The wall's cells come from the west look alone: their share of the valid map is what
    // keeps one look's range shift, and the tile's reference error scales with it.
    let share = f.one_look_share();
    assert!(
        (share - (f.east_only + f.west_only) / sum).abs() < 1e-12 && share > 0.1 && share < 0.9,
        "{share} {f:?}"
    );
    let full = crate::reference::reference_sigma_m(22.4, 1.0)[0];
    let fused = crate::reference::reference_sigma_m(22.4, share)[0];
    assert!(
        (fused - full * share as f32).abs() < 1e-5,
        "{fused} vs {full}"
    );
    // The scene is smaller than a frame's 2 km window: the one window is the map.
    assert!((f.one_look_share_for_frames() - share).abs() < 1e-9);
    assert_eq!(crate::reference::reference_sigma_m(22.4, 0.0), [0.0; 2]);
    // A one-look map, or an unknown share, claims the whole blur term.
    assert_eq!(
        crate::reference::reference_sigma_m(22.4, f64::NAN),
        [full; 2]
    );
}

#[test]
fn a_fresh_crater_is_masked_by_its_geometry_and_the_brightness_rule_adds_to_it() {
    use crate::terrain::crater::make_stamp;
    use crate::terrain::sfd::CraterDraw;
    // A fresh simple crater (Pike's d/D ≈ 0.2, walls up to ≈ 34°) 700 m across in a flat 1.2 km
    // scene. At θ ≈ 26° its far wall faces the radar more steeply than θ (layover) and its
    // near wall faces away at ≤ 34° < 64° (no geometric shadow) but with a local incidence
    // near 60°, so its echo is ≥ 12 dB below the median: what the brightness rule masks.
    let c = CraterDraw {
        d_m: 700.0,
        x_m: 600.0,
        y_m: 600.0,
        u_age: 0.0,
        u_shape: 0.5,
        u_rim: 0.5,
        u_keep: 0.0,
    };
    let stamp = make_stamp(&c, 1.0, 0.0);
    let dem = scene(240, 5.0, |x, y| {
        -2000.0 + f64::from(stamp.at((x - 600.0).hypot(y - 600.0)))
    });
    let cfg = InsarConfig {
        shadow_below_median_db: f64::INFINITY,
        ..InsarConfig::default()
    };
    let run = run_from_dem(&dem, &quiet(), Polarisation::HH, &cfg, false).unwrap();
    let a = compare(&run.product, &run.truth.grid, Some(&run.truth.window)).unwrap();
    let p = &run.product;
    eprintln!(
        "fresh crater: geometric layover {:.4} shadow {:.4}; mask {:?}; masked beyond geometry {:.4}; eq 20 masked {:.3}",
        a.geometric_layover_fraction,
        a.geometric_shadow_fraction,
        p.mask,
        a.masked_outside_geometry_fraction,
        a.eq20_masked_fraction
    );
    assert!(a.geometric_layover_fraction > 0.01, "{a:?}");
    assert_eq!(a.geometric_shadow_fraction, 0.0);
    // Geometry and coherence alone mask some of it; eq 20's steepest rim cells are often missed
    // (the 40 m window averages them with the gentler wall below; measured in docs/insar.md).
    assert!(p.mask.layover > 0.0, "{:?}", p.mask);
    // The same SLCs with the brightness rule (the default) mask more beyond the geometry: the
    // dark near wall. Both figures are printed; docs/insar.md says why the rule stays.
    let cfg = InsarConfig {
        shadow_below_median_db: InsarConfig::default().shadow_below_median_db,
        ..cfg
    };
    let (truth, dark) =
        super::pipeline::process_simulated(&dem, &run.pair, Polarisation::HH, &cfg).unwrap();
    let b = compare(&dark, &truth.grid, Some(&truth.window)).unwrap();
    eprintln!(
        "with the brightness rule: mask {:?}; masked beyond geometry {:.4}; height RMSE {:.2} m vs {:.2} m",
        dark.mask, b.masked_outside_geometry_fraction, b.height_rmse_m, a.height_rmse_m
    );
    assert!(dark.mask.shadow > p.mask.shadow, "{:?}", dark.mask);
    assert!(
        b.masked_outside_geometry_fraction > a.masked_outside_geometry_fraction,
        "{} vs {}",
        b.masked_outside_geometry_fraction,
        a.masked_outside_geometry_fraction
    );
}

#[test]
fn a_preset_crop_meets_the_accuracy_targets() {
    use crate::terrain::{Preset, TerrainParams, generate};
    let mut p = TerrainParams::new(Preset::Shoemaker);
    p.size_m = 1000.0;
    let (dem, _) = generate(&p, &indicatif::ProgressBar::hidden()).unwrap();
    let (_, a) = chain(&dem, &quiet());
    assert!(a.height_rmse_m <= 5.0, "rmse {}", a.height_rmse_m);
    // No RMSE-over-CRLB bound here: without thermal noise the coherence is 0.999 and the
    // error is the chain's own floor (window resolution, speckle centroids: 0.6–1.0 m), which
    // a noise bound does not describe. The bound's size is checked where noise dominates
    // (`stacked_passes_shrink_the_height_error_as_the_crlb_says`).
    assert!(a.slope_rmse_deg <= 3.0, "slope {}", a.slope_rmse_deg);
    assert!(a.valid_fraction >= 0.95, "valid {}", a.valid_fraction);
}

#[test]
fn the_real_lola_tile_runs_through_the_whole_chain() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../shared/data/lola-south-pole-site-5m-256.tif");
    if !path.exists() {
        eprintln!("skipped: ../shared/data not found ({})", path.display());
        return;
    }
    let truth = crate::dem::read_geotiff(&path).unwrap();
    let (run, a) = chain(&truth, &quiet());
    let dir = tempfile::tempdir().unwrap();
    let ctx = super::products::RunContext::default();
    let rep = super::products::write_outputs(dir.path(), &run.product, &run.truth, &ctx).unwrap();
    eprintln!("LOLA: {}", serde_json::to_string(&rep.accuracy).unwrap());
    // Noise-free: no RMSE-over-CRLB bound (see `a_preset_crop_meets_the_accuracy_targets`).
    assert!(a.height_rmse_m <= 5.0, "{a:?}");
    assert!(a.slope_rmse_deg <= 2.0, "slope {}", a.slope_rmse_deg);
    assert!(a.valid_fraction >= 0.95, "valid {}", a.valid_fraction);
    // A reference folder that the closed-loop tools load, and the report keys.
    let r = crate::reference::load(dir.path()).unwrap();
    assert!(r.slope.is_some());
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("report.json")).unwrap())
            .unwrap();
    for k in [
        "height_rmse_m",
        "height_bias_m",
        "slope_rmse_deg",
        "valid_fraction",
        "coherence_mean",
        "crlb_height_m",
        "tile_features",
        "tile_features_on_truth",
    ] {
        assert!(v.get(k).is_some_and(|x| x.is_number()), "report lacks {k}");
    }
    for f in [
        "coherence.tif",
        "mask.tif",
        "slope.tif",
        "reference-dem.tif",
        "fig5a-phase-with-flat.png",
        "fig5b-phase-flat-removed.png",
        "fig6a-insar-dem.png",
        "fig6b-insar-slope.png",
    ] {
        assert!(dir.path().join(f).exists(), "{f} missing");
    }
}

/// The issue's targets on both 4 km presets (about a minute each with the release profile):
/// `cargo test --release -p ground-sim --lib full_presets -- --ignored --nocapture`.
#[test]
#[ignore = "full 4 km scenes; run on demand, figures in docs/insar.md"]
fn full_presets_meet_the_issue_targets() {
    use crate::terrain::{Preset, TerrainParams, generate};
    for preset in [Preset::Shackleton, Preset::Shoemaker] {
        let (dem, _) = generate(
            &TerrainParams::new(preset),
            &indicatif::ProgressBar::hidden(),
        )
        .unwrap();
        let (run, a) = chain(&dem, &quiet());
        eprintln!("{preset:?}: {}", serde_json::to_string(&a).unwrap());
        eprintln!("{preset:?}: mask {:?}", run.product.mask);
        assert!(
            a.height_rmse_m <= 5.0,
            "{preset:?} rmse {}",
            a.height_rmse_m
        );
        if preset == Preset::Shoemaker {
            assert!(a.valid_fraction >= 0.95, "valid {}", a.valid_fraction);
        } else {
            // Masked share versus the eq 20 condition on the truth: every eq 20 pixel masked
            // (within a pixel) and the masked share at least the eq 20 share.
            let eq20 = a.eq20_layover_fraction + a.eq20_shadow_fraction;
            assert!(
                a.masked_fraction >= eq20,
                "masked {} < eq 20 {eq20}",
                a.masked_fraction
            );
        }
        // Slope: reported; the 2° target is not met on the synthetic floors (docs/insar.md).
        eprintln!("{preset:?}: slope RMSE {:.2}°", a.slope_rmse_deg);
    }
}

/// Developer diagnostic: best sub-pixel shift and height scale between an InSAR folder's DEM
/// and its truth. `UMBRA_DIAG_DEM=truth.tif UMBRA_DIAG_DIR=out cargo test … -- --ignored`.
#[test]
#[ignore = "developer diagnostic"]
fn diagnose_shift_and_scale() {
    use crate::dem::read_geotiff;
    let (Ok(t), Ok(d)) = (
        std::env::var("UMBRA_DIAG_DEM"),
        std::env::var("UMBRA_DIAG_DIR"),
    ) else {
        return;
    };
    let truth = read_geotiff(std::path::Path::new(&t)).unwrap();
    let ins = read_geotiff(&std::path::Path::new(&d).join("reference-dem.tif")).unwrap();
    let p = truth.pixel_m().unwrap();
    let (sx, sy) = truth.pixel_centre_m(0.0, 0.0);
    let sample = |x: f64, y: f64| -> f64 {
        let (u, v) = ((x - sx) / p, (sy - y) / p);
        let (i, j) = (u.floor() as usize, v.floor() as usize);
        let (a, b) = (u - i as f64, v - j as f64);
        let g = |ii, jj| f64::from(truth.get(ii, jj).unwrap_or(f32::NAN));
        (1.0 - b) * ((1.0 - a) * g(i, j) + a * g(i + 1, j))
            + b * ((1.0 - a) * g(i, j + 1) + a * g(i + 1, j + 1))
    };
    // Truth as a 4x4-pixel box mean around a shifted centre (bilinear samples on a 5 m lattice).
    let boxed = |x: f64, y: f64| -> f64 {
        let mut acc = 0.0;
        for jj in 0..4 {
            for ii in 0..4 {
                acc += sample(x + (ii as f64 - 1.5) * p, y - (jj as f64 - 1.5) * p);
            }
        }
        acc / 16.0
    };
    for &(dx, dy) in &[
        (0.0, 0.0),
        (5.0, 0.0),
        (-5.0, 0.0),
        (0.0, 5.0),
        (0.0, -5.0),
        (10.0, 0.0),
        (-10.0, 0.0),
        (0.0, 10.0),
        (0.0, -10.0),
    ] {
        let (mut s, mut n) = (0.0, 0.0);
        let (mut sxy, mut sxx, mut mx, mut my) = (0.0, 0.0, 0.0, 0.0);
        let mut pairs = Vec::new();
        for r in 2..ins.height() - 2 {
            for c in 2..ins.width() - 2 {
                let Some(z) = ins.get(c, r) else { continue };
                let (x, y) = ins.pixel_centre_m(c as f64, r as f64);
                let tz = boxed(x + dx, y + dy);
                if tz.is_finite() {
                    s += (f64::from(z) - tz).powi(2);
                    n += 1.0;
                    pairs.push((tz, f64::from(z)));
                }
            }
        }
        for &(a, b) in &pairs {
            mx += a;
            my += b;
        }
        mx /= n;
        my /= n;
        for &(a, b) in &pairs {
            sxy += (a - mx) * (b - my);
            sxx += (a - mx) * (a - mx);
        }
        eprintln!(
            "shift ({dx:+}, {dy:+}) m: rmse {:.3} m, scale {:.4}",
            (s / n).sqrt(),
            sxy / sxx
        );
    }
}

/// Developer diagnostic: pictures of the InSAR DEM minus the window-matched truth.
#[test]
#[ignore = "developer diagnostic"]
fn diagnose_window_error_picture() {
    use crate::dem::read_geotiff;
    use crate::pictures::render::{ColourMap, RasterStyle, raster_image};
    let Ok(d) = std::env::var("UMBRA_DIAG_DIR") else {
        return;
    };
    let dir = std::path::Path::new(&d);
    let ins = read_geotiff(&dir.join("reference-dem.tif")).unwrap();
    let win = read_geotiff(&dir.join("truth-window-dem.tif")).unwrap();
    let e: Vec<f32> = ins
        .heights_m()
        .iter()
        .zip(win.heights_m())
        .map(|(a, b)| a - b)
        .collect();
    let img = raster_image(
        &e,
        ins.width(),
        ins.height(),
        20.0,
        &RasterStyle {
            title: "InSAR - window truth",
            map: ColourMap::Diverging,
            range: (-4.0, 4.0),
            unit: "m",
        },
    );
    img.save(dir.join("diag-window-error.png")).unwrap();
    let s = crate::dem::stats::slope_deg(&win).unwrap();
    let img = raster_image(
        &s,
        ins.width(),
        ins.height(),
        20.0,
        &RasterStyle {
            title: "window truth slope",
            map: ColourMap::Slope,
            range: (0.0, 40.0),
            unit: "deg",
        },
    );
    img.save(dir.join("diag-window-slope.png")).unwrap();
}

/// Developer diagnostic: radar-geometry rows around a line.
#[test]
#[ignore = "developer diagnostic"]
fn diagnose_radar_lines() {
    use crate::dem::read_geotiff;
    use crate::sar::Slc;
    let (Ok(t), Ok(d), Ok(l)) = (
        std::env::var("UMBRA_DIAG_DEM"),
        std::env::var("UMBRA_DIAG_SLC"),
        std::env::var("UMBRA_DIAG_LINE"),
    ) else {
        return;
    };
    let truth = read_geotiff(std::path::Path::new(&t)).unwrap();
    let rd = |n: u8| {
        Slc::read_from(std::io::BufReader::new(
            std::fs::File::open(std::path::Path::new(&d).join(format!("slc_a{n}_hh.bin"))).unwrap(),
        ))
        .unwrap()
    };
    let (a1, a2) = (rd(1), rd(2));
    let (tg, p) = super::pipeline::process_slcs(&truth, &a1, &a2, &InsarConfig::default()).unwrap();
    let r = &p.radar;
    let k: usize = l.parse().unwrap();
    for kk in k - 2..=k + 2 {
        let row = kk * r.cols;
        let mut s = String::new();
        for m in (20..120).step_by(4) {
            s += &format!(
                "{}:{:.0}/{:.0}/{:.3} ",
                r.labels[row + m],
                r.height_m[row + m],
                r.ground_y_m[row + m] - r.ground_y_m[row + m - 1],
                r.coherence[row + m]
            );
        }
        eprintln!("line {kk}: {s}");
    }
    let w = p.grid.width;
    for rr in k - 3..=k + 3 {
        let (mut e, mut n) = (0.0, 0.0);
        let mut tz = String::new();
        for c in 50..116 {
            let (a, b) = (
                p.dem.heights_m()[rr * w + c],
                tg.window.heights_m()[rr * w + c],
            );
            if a.is_finite() && b.is_finite() {
                e += f64::from(a - b);
                n += 1.0;
            }
            if c % 8 == 0 {
                tz += &format!("{:.1}/{:.1} ", a, b);
            }
        }
        eprintln!("grid row {rr}: mean err {:.2} m; insar/window {tz}", e / n);
    }
}

/// Developer diagnostic: a Gaussian-smoothed copy of an InSAR folder's DEM.
#[test]
#[ignore = "developer diagnostic"]
fn diagnose_smoothed_copy() {
    use crate::dem::{read_geotiff, write_geotiff};
    let (Ok(d), Ok(sig)) = (
        std::env::var("UMBRA_DIAG_DIR"),
        std::env::var("UMBRA_DIAG_SIGMA"),
    ) else {
        return;
    };
    let sigma: f64 = sig.parse().unwrap();
    let dir = std::path::Path::new(&d);
    let ins = read_geotiff(&dir.join("reference-dem.tif")).unwrap();
    let (w, h) = (ins.width(), ins.height());
    let r = (3.0 * sigma).ceil() as i64;
    let z = ins.heights_m();
    let mut out = vec![f32::NAN; w * h];
    for y in 0..h as i64 {
        for x in 0..w as i64 {
            if !z[(y * w as i64 + x) as usize].is_finite() {
                continue;
            }
            let (mut a, mut s) = (0.0, 0.0);
            for dy in -r..=r {
                for dx in -r..=r {
                    let (xx, yy) = (x + dx, y + dy);
                    if xx < 0 || yy < 0 || xx >= w as i64 || yy >= h as i64 {
                        continue;
                    }
                    let v = z[(yy * w as i64 + xx) as usize];
                    if v.is_finite() {
                        let k = (-((dx * dx + dy * dy) as f64) / (2.0 * sigma * sigma)).exp();
                        a += k * f64::from(v);
                        s += k;
                    }
                }
            }
            out[(y * w as i64 + x) as usize] = (a / s) as f32;
        }
    }
    let dem = crate::dem::Dem::new(w, h, out, ins.geo.clone()).unwrap();
    write_geotiff(&dem, &dir.join("diag-smoothed.tif"), None).unwrap();
}

#[test]
fn recentring_moves_plane_heights_back_to_the_window_centres() {
    use super::pipeline::recentre_heights;
    // A plane z = 0.3·line + 0.7·gate (SLC samples) on a 6 × 7 multilook grid, step 4, each
    // height measured at a different centroid offset; one invalid pixel stays as given.
    let (lines, cols, step) = (6usize, 7usize, 4.0);
    let truth = |k: usize, m: usize| 0.3 * k as f64 * step + 0.7 * m as f64 * step;
    let centroid: Vec<(f64, f64)> = (0..lines * cols)
        .map(|i| {
            (
                ((i * 7) % 5) as f64 * 0.4 - 0.8,
                ((i * 3) % 4) as f64 * 0.5 - 0.75,
            )
        })
        .collect();
    let z: Vec<f64> = (0..lines * cols)
        .map(|i| truth(i / cols, i % cols) + 0.3 * centroid[i].0 + 0.7 * centroid[i].1)
        .collect();
    let mut valid = vec![true; lines * cols];
    // Interior, so every valid pixel keeps a neighbour along both axes (a pixel without one gets
    // no correction along that axis).
    valid[24] = false;
    // The gradient comes from the heights themselves, so each pass only shrinks the error
    // (≈ ×0.5 per pass on this adversarial offset pattern); iterated, it
    // converges to the plane.
    let worst = |h: &[f64]| -> f64 {
        (0..lines * cols)
            .filter(|&i| valid[i])
            .map(|i| (h[i] - truth(i / cols, i % cols)).abs())
            .fold(0.0, f64::max)
    };
    let before = worst(&z);
    let one = recentre_heights(&z, &valid, cols, step, &centroid, 1);
    let two = recentre_heights(&z, &valid, cols, step, &centroid, 2);
    let many = recentre_heights(&z, &valid, cols, step, &centroid, 12);
    eprintln!(
        "worst error {before:.4} → {:.4} (1 pass) → {:.4} (2) → {:.6} (12)",
        worst(&one),
        worst(&two),
        worst(&many)
    );
    assert!(worst(&one) < 0.6 * before);
    assert!(worst(&two) < 0.35 * before);
    assert!(worst(&many) < 0.01 * before);
    assert_eq!(two[24], z[24]);
    // Without passes nothing moves.
    assert_eq!(recentre_heights(&z, &valid, cols, step, &centroid, 0), z);
}

#[test]
fn a_second_look_a_whole_cycle_off_is_aligned_before_fusing() {
    use super::pipeline::{cycle_height_m, fuse_looks, mirrored_dem, run_from_dem};
    let t = 35f64.to_radians().tan();
    let dem = scene(200, 5.0, |x, _| -2000.0 + t * (x - 400.0).clamp(0.0, 200.0));
    let cfg = InsarConfig {
        shadow_below_median_db: f64::INFINITY,
        ..InsarConfig::default()
    };
    let east = run_from_dem(&dem, &quiet(), Polarisation::HH, &cfg, false).unwrap();
    let west = run_from_dem(
        &mirrored_dem(&dem).unwrap(),
        &quiet(),
        Polarisation::HH,
        &cfg,
        false,
    )
    .unwrap();
    let mut fused = east.product.clone();
    let f0 = fuse_looks(&mut fused, &west.product).unwrap();
    assert_eq!(f0.west_cycles_shifted, 0, "{f0:?}");
    // The west pass's unwrapping one cycle up (as when its valid mean sits a cycle away).
    let mut slipped = west.product.clone();
    let w = slipped.grid.width;
    let up: Vec<f32> = slipped
        .dem
        .heights_m()
        .iter()
        .enumerate()
        .map(|(i, &h)| (f64::from(h) + cycle_height_m(&west.product, i % w)) as f32)
        .collect();
    slipped.dem = slipped.grid.raster(up).unwrap();
    let mut fused2 = east.product.clone();
    let f1 = fuse_looks(&mut fused2, &slipped).unwrap();
    assert_eq!(f1.west_cycles_shifted, 1, "{f1:?}");
    assert_eq!(fused2.labels, fused.labels);
    assert!(
        (f1.inconsistent - f0.inconsistent).abs() < 1e-12,
        "{f0:?} {f1:?}"
    );
    for (a, b) in fused.dem.heights_m().iter().zip(fused2.dem.heights_m()) {
        assert!(
            a.is_nan() == b.is_nan() && (a.is_nan() || (a - b).abs() < 1e-3),
            "{a} {b}"
        );
    }
}

#[test]
fn looks_that_differ_by_a_cycle_are_not_fused() {
    use super::pipeline::looks_disagree;
    // The 32 m boom's 183 m cycle between two 2 m-bound heights: one look slipped.
    assert!(looks_disagree(-1500.0, -1683.0, 2.0, 2.0));
    // A few metres apart with a few metres of bound: the same ground.
    assert!(!looks_disagree(-1500.0, -1506.0, 2.0, 2.0));
    // Tight bounds count as 0.6 m (7 × 0.85 m = 5.9 m): 5 m apart still agrees, 6 m does not.
    assert!(!looks_disagree(10.0, 15.0, 0.1, 0.1));
    assert!(looks_disagree(10.0, 16.0, 0.1, 0.1));
    // A missing bound never disagrees.
    assert!(!looks_disagree(0.0, 500.0, f32::NAN, 2.0));
}

/// The Shackleton rim (3 km, seed 1) spans eight 183 m cycles of the 32 m boom with a third of
/// the east-looking pass in layover or shadow: the unwrapper's datum rule (the valid pixels'
/// mean nearest the datum) puts that pass a cycle low, its pixels land 375 m off on the ground,
/// and the fused map is half valid and 180 m wrong. The coarse prior DEM (240 m cells) picks
/// the cycles patch by patch and the map comes back (noise-free mission radar, both looks).
#[test]
fn a_coarse_prior_dem_picks_the_cycles_the_datum_rule_gets_wrong() {
    use super::pipeline::{LookDirections, run_from_dem_looks};
    use crate::terrain::{Preset, TerrainParams, Window, generate};
    let p = TerrainParams {
        preset: Preset::Shackleton,
        window: Window::Rim,
        seed: 1,
        size_m: 3000.0,
        pixel_m: 5.0,
    };
    let dem = generate(&p, &indicatif::ProgressBar::hidden()).unwrap().0;
    let sar = SarConfig {
        noise_equivalent_sigma0_db: f64::NEG_INFINITY,
        ..crate::sar::RadarPreset::Mission.config()
    };
    let run = |prior_dem_cell_m: f64| {
        let cfg = InsarConfig {
            prior_dem_cell_m,
            ..InsarConfig::default()
        }
        .with_radar(&sar);
        let r = run_from_dem_looks(
            &dem,
            &sar,
            Polarisation::HH,
            &cfg,
            false,
            LookDirections::Both,
        )
        .unwrap();
        let a = compare(&r.product, &r.truth.grid, None).unwrap();
        eprintln!(
            "prior {prior_dem_cell_m} m: rmse {:.2} m valid {:.4}; unwrap {:?}; looks {:?}",
            a.height_rmse_m, a.valid_fraction, r.product.unwrap, r.product.look_fusion
        );
        (a, r.product.unwrap.prior)
    };
    let (without, c0) = run(0.0);
    assert!(!c0.ran);
    assert!(
        without.height_rmse_m > 100.0 && without.valid_fraction < 0.6,
        "the datum rule alone was expected to slip here: {without:?}"
    );
    let (with, c1) = run(240.0);
    assert!(c1.ran && c1.patches_shifted >= 1, "{c1:?}");
    assert!(c1.median_residual_m.is_some_and(|m| m < 20.0), "{c1:?}");
    assert!(
        with.height_rmse_m < 2.0 && with.valid_fraction > 0.99,
        "rmse {:.2} m valid {:.4}",
        with.height_rmse_m,
        with.valid_fraction
    );
}

/// The parallax of the height error (`looks::parallax_bound_factor`): on a plane falling 15°
/// away from the radar (one look, NESZ −22 dB, so the noise dominates on the darkened slope;
/// 500 m, so the relief stays within one 2π cycle) the chain's error is √(1 + 2kρ + k²a²) ≈
/// 1.30 times the phase's bound, k = tan 15° · cot 26°. The bound carries the factor, so the
/// error over it reads near 1 (measured 1.01, valid 95 %); without the factor the formula puts
/// it near 1.3, outside the band. At −15 dB the slope is too dark to unwrap (valid 30 %).
#[test]
fn the_bound_holds_the_parallax_on_ground_facing_away() {
    let t = 15f64.to_radians().tan();
    let dem = scene(100, 5.0, |x, _| -2000.0 - t * x);
    let sar = SarConfig {
        noise_equivalent_sigma0_db: -22.0,
        ..crate::sar::RadarPreset::Mission.config()
    };
    let r = run_from_dem(&dem, &sar, Polarisation::HH, &InsarConfig::default(), false).unwrap();
    let a = compare(&r.product, &r.truth.grid, None).unwrap();
    let ratio = a.height_rmse_m / a.crlb_height_m;
    eprintln!(
        "15° facing away: rmse {:.3} m bound {:.3} m ({ratio:.2}), valid {:.4}",
        a.height_rmse_m, a.crlb_height_m, a.valid_fraction
    );
    assert!(a.valid_fraction > 0.9, "valid {}", a.valid_fraction);
    // Narrow, so a factor applied to only part of the slope fails it too.
    assert!((0.85..1.12).contains(&ratio), "error over bound {ratio:.2}");
}

/// Four passes of one track: the receiver noise's share of the height error halves, and so
/// does that share of the CRLB, while the surface's share (the noise-free run's: the speckle is
/// the same ground in every pass) stays. At NESZ −15 dB over a 1 km tilted plane (one look) the
/// noise dominates.
#[test]
fn stacked_passes_shrink_the_height_error_as_the_crlb_says() {
    let t = 8f64.to_radians().tan();
    let dem = scene(200, 5.0, |x, y| -2000.0 + t * x + 0.5 * t * y);
    let noisy = SarConfig {
        noise_equivalent_sigma0_db: -15.0,
        ..crate::sar::RadarPreset::Mission.config()
    };
    let quiet = SarConfig {
        noise_equivalent_sigma0_db: f64::NEG_INFINITY,
        ..noisy.clone()
    };
    let run = |sar: &SarConfig, passes: usize| {
        let cfg = InsarConfig {
            passes,
            ..InsarConfig::default()
        };
        let r = run_from_dem(&dem, sar, Polarisation::HH, &cfg, false).unwrap();
        let a = compare(&r.product, &r.truth.grid, None).unwrap();
        eprintln!(
            "{passes} passes, NESZ {}: rmse {:.3} m crlb {:.3} m valid {:.4} looks {:.1}",
            sar.noise_equivalent_sigma0_db,
            a.height_rmse_m,
            a.crlb_height_m,
            a.valid_fraction,
            r.product.effective_looks
        );
        (a, r.product.effective_looks)
    };
    let (floor, _) = run(&quiet, 1);
    let (one, l1) = run(&noisy, 1);
    let (four, l4) = run(&noisy, 4);
    assert!((l4 / l1 - 4.0).abs() < 1e-9, "{l1} {l4}");
    // The bound's thermal part over four passes, its surface part (the noise-free run's) once:
    // the CRLB reads the split from the passes themselves, a little high (the coherence of a
    // finite window is biased up, which shifts variance to the surface part; the 1.0 floor
    // rests on that direction): measured 1.10×.
    let (q, o) = (floor.crlb_height_m, one.crlb_height_m);
    let split = (q * q + (o * o - q * q) / 4.0).sqrt();
    let crlb_ratio = four.crlb_height_m / split;
    assert!(
        (1.0..1.2).contains(&crlb_ratio),
        "four passes' CRLB {:.3} m against {split:.3} m from the split",
        four.crlb_height_m
    );
    let noise = |a: &Accuracy| {
        (a.height_rmse_m.powi(2) - floor.height_rmse_m.powi(2))
            .max(0.0)
            .sqrt()
    };
    let ratio = noise(&four) / noise(&one);
    assert!(
        noise(&one) > 2.0 * floor.height_rmse_m,
        "the noise should dominate one pass"
    );
    assert!(ratio > 0.35 && ratio < 0.7, "noise ratio {ratio}");
    // The bound is the error's own size, not a loose ceiling: before it followed the heights
    // through the DEM filter it claimed twice the noise (0.44×); measured 0.90, 0.81 and 0.76
    // (the geocoding's interpolation, which also averages, is not credited). Before the
    // surface's share stopped averaging over passes, four passes read 0.85 here and 1.44 on
    // the 16 km plains map (1.26 since; one pass 1.13).
    for (a, name) in [
        (&floor, "noise-free"),
        (&one, "one pass"),
        (&four, "four passes"),
    ] {
        let honest = a.height_rmse_m / a.crlb_height_m;
        assert!(
            honest > 0.65 && honest <= 1.05,
            "{name}: error {:.3} m over its CRLB {:.3} m",
            a.height_rmse_m,
            a.crlb_height_m
        );
    }
    assert!(four.valid_fraction >= one.valid_fraction - 1e-9);
    // Out of range: refused before anything is simulated.
    let bad = InsarConfig {
        passes: 0,
        ..InsarConfig::default()
    };
    assert!(run_from_dem(&dem, &noisy, Polarisation::HH, &bad, false).is_err());
}

/// A second, longer baseline lowers the noise of gentle ground by about its length ratio, its
/// bound stays the error's own size, and it takes nothing from a scene it cannot measure
/// better; a long baseline no longer than the radar's is refused.
#[test]
fn a_long_baseline_lowers_the_noise_of_gentle_ground() {
    // Gentle ground with some relief: a 3° tilt and low hills.
    let t = 3f64.to_radians().tan();
    let dem = scene(200, 5.0, |x, y| {
        -2000.0 + t * x + 4.0 * (x / 90.0).sin() * (y / 130.0).cos()
    });
    let noisy = SarConfig {
        noise_equivalent_sigma0_db: -15.0,
        ..crate::sar::RadarPreset::Mission.config()
    };
    let run = |long_baseline_m: f64, long_filter_sigma_px: Option<f64>| {
        let cfg = InsarConfig {
            long_baseline_m,
            long_filter_sigma_px,
            ..InsarConfig::default()
        };
        let r = run_from_dem(&dem, &noisy, Polarisation::HH, &cfg, false).unwrap();
        let a = compare(&r.product, &r.truth.grid, None).unwrap();
        eprintln!(
            "long baseline {long_baseline_m} m: rmse {:.3} m crlb {:.3} m valid {:.4} {:?}",
            a.height_rmse_m, a.crlb_height_m, a.valid_fraction, r.product.baseline_fusion
        );
        (
            a,
            r.product.baseline_fusion,
            r.product.unwrap.ambiguity_height_m,
            r.product.crlb_filter_factor,
        )
    };
    // Both pairs under the same 1 px mean (the default): the baseline's own effect.
    let (short, none, hoa, short_factor) = run(0.0, None);
    let (long, fusion, _, same_factor) = run(4.0 * noisy.baseline_m, None);
    assert!(none.is_empty());
    let f = fusion.first().expect("the long baseline's report");
    assert_eq!(f.long_filter_sigma_px, Some(1.0));
    assert_eq!(same_factor, short_factor);
    // At this noise (10 dB above the mission's) the short bound reaches half the long pair's
    // cycle on a few per cent of cells, which keep their short heights (measured 90 %).
    assert!(f.long_share > 0.8, "{f:?}");
    assert!(
        (f.long_ambiguity_height_m / hoa - 0.25).abs() < 0.01,
        "{f:?}"
    );
    // Four times the baseline: the noise falls by more than half (a quarter in phase terms;
    // the surface's decorrelation grows with the baseline).
    assert!(
        long.height_rmse_m < 0.5 * short.height_rmse_m,
        "{} against {}",
        long.height_rmse_m,
        short.height_rmse_m
    );
    assert!(long.valid_fraction >= short.valid_fraction - 1e-9);
    let honest = long.height_rmse_m / long.crlb_height_m;
    assert!((0.65..=1.1).contains(&honest), "error over CRLB {honest}");
    // The long pair under a narrower mean of its own: its bound grows (less noise averaged),
    // the map's filter factor lies between the two pairs' (weighted by the bounds' power),
    // and the bound still holds the error. On ground this gentle and at this noise (10 dB
    // above the mission's) the narrower mean loses: it flattens little relief and keeps
    // more noise.
    let (narrow, fusion, _, fused_factor) = run(4.0 * noisy.baseline_m, Some(0.5));
    let f = fusion.first().expect("the long baseline's report");
    assert_eq!(f.long_filter_sigma_px, Some(0.5));
    let long_factor = f.long_crlb_filter_factor.expect("the long pair's factor");
    assert!(
        fused_factor > short_factor && fused_factor < long_factor,
        "{fused_factor} between {short_factor} and {long_factor}"
    );
    assert!(narrow.crlb_height_m > long.crlb_height_m);
    assert!(narrow.height_rmse_m > long.height_rmse_m);
    let honest = narrow.height_rmse_m / narrow.crlb_height_m;
    assert!((0.65..=1.1).contains(&honest), "error over CRLB {honest}");
    // Refused before anything is simulated.
    let bad = InsarConfig {
        long_baseline_m: noisy.baseline_m,
        ..InsarConfig::default()
    };
    assert!(run_from_dem(&dem, &noisy, Polarisation::HH, &bad, false).is_err());
    // Its cycles need the unwrapped phase.
    let wrapped = InsarConfig {
        long_baseline_m: 4.0 * noisy.baseline_m,
        unwrap: false,
        ..InsarConfig::default()
    };
    assert!(run_from_dem(&dem, &noisy, Polarisation::HH, &wrapped, false).is_err());
}

#[test]
fn the_frames_share_of_one_look_cells_is_the_worst_windows() {
    use super::pipeline::worst_window_share;
    // 40 × 40 cells, the west half made by one look alone.
    let (w, h) = (40, 40);
    let flag: Vec<bool> = (0..w * h).map(|i| i % w < 20).collect();
    let mut valid = vec![true; w * h];
    // Map-wide half the cells; a 20-cell window inside the west half has nothing else.
    assert!((worst_window_share(&flag, &valid, w, 40.0) - 0.5).abs() < 1e-12);
    assert!((worst_window_share(&flag, &valid, w, 20.0) - 1.0).abs() < 1e-12);
    // A window between the two: 20 of its 30 columns.
    assert!((worst_window_share(&flag, &valid, w, 30.0) - 20.0 / 30.0).abs() < 1e-12);
    // Larger than the grid, or not a size: the whole map's share.
    assert!((worst_window_share(&flag, &valid, w, 100.0) - 0.5).abs() < 1e-12);
    assert!((worst_window_share(&flag, &valid, w, f64::NAN) - 0.5).abs() < 1e-12);
    // A strip 10 cells high: windows as high as the strip, the west half still all one look.
    assert!((worst_window_share(&flag[..400], &valid[..400], w, 20.0) - 1.0).abs() < 1e-12);
    // Mostly holes: a window less than half valid does not speak. Only rows 0–4 of the west
    // half stay valid, so a window needs 7 east columns to be half valid: 65 / 205 at most.
    for (i, v) in valid.iter_mut().enumerate() {
        *v = i % w >= 20 || i / w < 5;
    }
    let s = worst_window_share(&flag, &valid, w, 20.0);
    assert!((s - 65.0 / 205.0).abs() < 1e-12, "{s}");
    // Nothing valid: unknown.
    assert!(worst_window_share(&flag, &[false; 1600], w, 20.0).is_nan());
}

fn look_noise(size: usize, os: f64, alpha: f64) -> super::demfilter::LookNoise {
    super::demfilter::LookNoise {
        size,
        step: 4,
        lag_per_px: [1.0, 1.0],
        oversampling: [os, os],
        alpha,
    }
}

#[test]
fn the_dem_filter_shrinks_the_bound_by_what_the_looks_do_not_share() {
    use super::demfilter::{
        DemFilter, DemFilterKind, dem_filter_noise_factor, dem_filter_noise_factors,
    };
    let gauss = |sigma_px| DemFilter {
        kind: DemFilterKind::Gaussian,
        sigma_px,
    };
    let quad = |sigma_px| DemFilter {
        kind: DemFilterKind::Quadratic,
        sigma_px,
    };
    let chain = look_noise(8, 2.0, 0.54);
    // White noise (Nyquist-sampled rectangular spectrum, windows that do not overlap): the
    // mean keeps sqrt(Σw²)/Σw per axis, 0.282 over both at 1 px.
    let k: Vec<f64> = (-3..=3)
        .map(|d: i32| (-f64::from(d * d) / 2.0).exp())
        .collect();
    let white = k.iter().map(|v| v * v).sum::<f64>() / k.iter().sum::<f64>().powi(2);
    let f = dem_filter_noise_factor(gauss(1.0), look_noise(4, 1.0, 1.0));
    assert!(
        (f - white).abs() < 2e-3 && (white - 0.282).abs() < 1e-3,
        "{f} {white}"
    );
    // The default chain's overlapping looks keep more: 0.553 for the 1 px mean (session 24),
    // about 0.50 for the 2 px quadratic fit, which needs the wider weights to average as
    // much because its kernel has negative lobes.
    let d = dem_filter_noise_factor(gauss(1.0), chain);
    assert!((d - 0.553).abs() < 2e-3, "{d}");
    let q = dem_filter_noise_factor(quad(2.0), chain);
    assert!((q - 0.50).abs() < 0.01, "{q}");
    // No filter, or nonsense lags: the bound as it was.
    assert_eq!(dem_filter_noise_factor(gauss(0.0), chain), 1.0);
    assert_eq!(dem_filter_noise_factor(quad(0.0), chain), 1.0);
    let mut bad = chain;
    bad.lag_per_px[0] = f64::NAN;
    assert_eq!(dem_filter_noise_factor(quad(2.0), bad), 1.0);
    // Per cell: inside, the full factor; at the edge the kernel is cut and keeps more, at a
    // corner more still; a cell alone within its kernel keeps its whole bound.
    let (w, h) = (20, 20);
    let mut valid = vec![true; w * h];
    for r in 12..19 {
        for c in 12..19 {
            valid[r * w + c] = (r, c) == (15, 15);
        }
    }
    let (full, fs) = dem_filter_noise_factors(&valid, w, h, gauss(1.0), chain);
    assert!((full - d).abs() < 1e-12);
    assert!(
        (fs[6 * w + 6] - d).abs() < 1e-12,
        "inside {}",
        fs[6 * w + 6]
    );
    let (edge, corner) = (fs[6 * w], fs[0]);
    assert!(
        edge > d + 0.05 && corner > edge + 0.05 && corner < 1.0,
        "{edge} {corner}"
    );
    assert!((fs[15 * w + 15] - 1.0).abs() < 1e-12, "{}", fs[15 * w + 15]);
    let (_, alone) = dem_filter_noise_factors(&[true], 1, 1, gauss(1.0), chain);
    assert!((alone[0] - 1.0).abs() < 1e-12, "{alone:?}");
    // The quadratic fit: the same shape, never above 1 (a fit that would keep more than 55 %
    // of the white noise falls back to a plane or the mean).
    let (w, h) = (30, 30);
    let mut valid = vec![true; w * h];
    valid[20 * w + 20] = false;
    let (full, fs) = dem_filter_noise_factors(&valid, w, h, quad(2.0), chain);
    assert!((full - q).abs() < 1e-12);
    assert!((fs[8 * w + 8] - q).abs() < 1e-12, "{}", fs[8 * w + 8]);
    assert!(fs[8 * w] > q + 0.05, "edge {}", fs[8 * w]);
    assert!(
        (q - 0.05..1.0).contains(&fs[20 * w + 21]),
        "by a hole {}",
        fs[20 * w + 21]
    );
    assert!(fs.iter().all(|&f| f > 0.0 && f <= 1.0 + 1e-9), "{fs:?}");
    let (_, alone) = dem_filter_noise_factors(&[true], 1, 1, quad(2.0), chain);
    assert!((alone[0] - 1.0).abs() < 1e-12, "{alone:?}");
}

#[test]
fn the_means_bound_is_summed_as_it_always_was() {
    // The default products must not move by a bit: the 1 px mean's per-cell factors, summed
    // here in the order of session 24's code (separable full factor; unnormalised weights with
    // the total divided out last), equal the module's exactly.
    use super::demfilter::{DemFilter, DemFilterKind, dem_filter_noise_factors};
    use super::looks::multilook_noise_correlation;
    let (w, h, r) = (23usize, 17usize, 3usize);
    let valid: Vec<bool> = (0..w * h).map(|i| (i * 7919) % 11 != 3).collect();
    let noise = look_noise(8, 2.0, 0.54);
    let k: Vec<f64> = (0..=2 * r)
        .map(|i| {
            let d = i as f64 - r as f64;
            (-d * d / 2.0).exp()
        })
        .collect();
    let rho: Vec<f64> = (0..=2 * r)
        .map(|d| multilook_noise_correlation(8, 4, d as f64, 2.0, 0.54))
        .collect();
    let total: f64 = k.iter().sum();
    let mut full = 1.0;
    for _ in 0..2 {
        let mut var = 0.0;
        for (i, a) in k.iter().enumerate() {
            for (j, b) in k.iter().enumerate() {
                var += a * b * rho[i.abs_diff(j)];
            }
        }
        full *= f64::max(var, 0.0).sqrt() / total;
    }
    let (f, fs) = dem_filter_noise_factors(
        &valid,
        w,
        h,
        DemFilter {
            kind: DemFilterKind::Gaussian,
            sigma_px: 1.0,
        },
        noise,
    );
    assert_eq!(f.to_bits(), full.to_bits());
    for (i, got) in fs.iter().enumerate() {
        if !valid[i] {
            continue;
        }
        let (y, x) = ((i / w) as i64, (i % w) as i64);
        let mut cells = Vec::new();
        for dy in 0..=2 * r {
            for dx in 0..=2 * r {
                let (yy, xx) = (y + dy as i64 - r as i64, x + dx as i64 - r as i64);
                if (0..h as i64).contains(&yy)
                    && (0..w as i64).contains(&xx)
                    && valid[yy as usize * w + xx as usize]
                {
                    cells.push((dy, dx, k[dy] * k[dx]));
                }
            }
        }
        let whole = cells.len() == (2 * r + 1) * (2 * r + 1);
        let tot: f64 = cells.iter().map(|c| c.2).sum();
        let mut var = 0.0;
        for a in &cells {
            for b in &cells {
                var += a.2 * b.2 * rho[a.0.abs_diff(b.0)] * rho[a.1.abs_diff(b.1)];
            }
        }
        let want = if whole {
            full
        } else {
            f64::max(var, 0.0).sqrt() / tot
        };
        assert_eq!(got.to_bits(), want.to_bits(), "cell {i}: {got} vs {want}");
    }
}

#[test]
fn a_quadratic_fit_too_narrow_to_fit_reports_the_blur_of_its_fallback() {
    use super::demfilter::{DemFilter, DemFilterKind};
    let q = |sigma_px| DemFilter {
        kind: DemFilterKind::Quadratic,
        sigma_px,
    };
    // At 2 px the fit adds no second moment; at 0.5 px it falls back to a plane, which on a
    // whole footprint is the mean, and says so.
    assert_eq!(q(2.0).signal_sigma_m(20.0), 0.0);
    let narrow = q(0.5).signal_sigma_m(20.0);
    assert!(narrow > 5.0 && narrow < 20.0, "{narrow}");
    // σ outside the accepted range: no filter, no blur.
    assert_eq!(q(0.01).signal_sigma_m(20.0), 0.0);
}

#[test]
fn the_quadratic_filter_keeps_curvature_the_mean_flattens() {
    use super::demfilter::{DemFilter, DemFilterKind, filter_dem};
    // A bowl z = 0.01·r² m (cells of 1 px; ∇²z = 0.04 per px²) with a tilt, a hole and edges.
    let (w, h) = (40, 30);
    let surface = |x: f64, y: f64| {
        3.0 + 0.2 * x - 0.1 * y + 0.01 * ((x - 20.0).powi(2) + (y - 15.0).powi(2)) + 0.002 * x * y
    };
    let mut z: Vec<f64> = (0..w * h)
        .map(|i| surface((i % w) as f64, (i / w) as f64))
        .collect();
    for y in 10..13 {
        for x in 25..29 {
            z[y * w + x] = f64::NAN;
        }
    }
    let quad = filter_dem(
        &z,
        w,
        h,
        DemFilter {
            kind: DemFilterKind::Quadratic,
            sigma_px: 2.0,
        },
    );
    let mean = filter_dem(
        &z,
        w,
        h,
        DemFilter {
            kind: DemFilterKind::Gaussian,
            sigma_px: 2.0,
        },
    );
    let mut worst_quad = 0.0f64;
    for i in 0..w * h {
        assert_eq!(
            z[i].is_finite(),
            quad[i].is_finite(),
            "NaN stays NaN, at {i}"
        );
        if z[i].is_finite() {
            worst_quad = worst_quad.max((quad[i] - z[i]).abs());
        }
    }
    // Everywhere a quadratic fits (inside, by the hole, at the edges) it is reproduced; the
    // corner cells that fall back to a plane are off by the curvature over their lopsided
    // footprint.
    assert!(worst_quad < 0.3, "{worst_quad}");
    let mut worst_inner = 0.0f64;
    for y in 3..h - 3 {
        for x in 3..w - 3 {
            if z[y * w + x].is_finite() {
                worst_inner = worst_inner.max((quad[y * w + x] - z[y * w + x]).abs());
            }
        }
    }
    assert!(worst_inner < 1e-6, "{worst_inner}");
    let inside = 15 * w + 10;
    assert!((quad[inside] - z[inside]).abs() < 1e-9);
    assert!(
        (quad[12 * w + 24] - z[12 * w + 24]).abs() < 1e-6,
        "by the hole"
    );
    // The mean raises the bowl by σ²/2 · ∇²z = 2 · 0.04 = 0.08 m.
    let bias = mean[inside] - z[inside];
    assert!((bias - 0.08).abs() < 0.01, "{bias}");
}

#[test]
fn the_filters_bound_matches_filtered_white_noise() {
    use super::demfilter::{DemFilter, DemFilterKind, dem_filter_noise_factor, filter_dem};
    use rand::{RngExt, SeedableRng};
    let (w, h) = (160, 160);
    let mut rng = rand_pcg::Pcg64::seed_from_u64(25);
    // Unit white noise (Box–Muller).
    let z: Vec<f64> = (0..w * h)
        .map(|_| {
            let (u, v): (f64, f64) = (rng.random::<f64>().max(1e-12), rng.random());
            (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
        })
        .collect();
    for kind in [DemFilterKind::Quadratic, DemFilterKind::Gaussian] {
        let filter = DemFilter {
            kind,
            sigma_px: 2.0,
        };
        let f = filter_dem(&z, w, h, filter);
        let inner: Vec<f64> = (0..w * h)
            .filter(|i| (10..h - 10).contains(&(i / w)) && (10..w - 10).contains(&(i % w)))
            .map(|i| f[i])
            .collect();
        let sd = (inner.iter().map(|v| v * v).sum::<f64>() / inner.len() as f64).sqrt();
        let predicted = dem_filter_noise_factor(filter, look_noise(4, 1.0, 1.0));
        assert!(
            (sd / predicted - 1.0).abs() < 0.06,
            "{kind:?}: {sd} vs {predicted}"
        );
    }
}

#[test]
fn the_per_cell_bound_matches_filtered_white_noise_at_edges_and_holes() {
    // Where the footprint is cut (the map's edge, a hole) each cell has its own weights and
    // its own factor; filtered white noise must have that σ there too.
    use super::demfilter::{DemFilter, DemFilterKind, dem_filter_noise_factors, filter_dem};
    use rand::{RngExt, SeedableRng};
    let (w, h) = (30usize, 30usize);
    let hole = |i: usize| (14..17).contains(&(i / w)) && (14..17).contains(&(i % w));
    let valid: Vec<bool> = (0..w * h).map(|i| !hole(i)).collect();
    let edge: Vec<usize> = (6..24).collect();
    let by_hole = [13 * w + 15, 17 * w + 15, 15 * w + 13, 15 * w + 17];
    let mut rng = rand_pcg::Pcg64::seed_from_u64(26);
    for kind in [DemFilterKind::Quadratic, DemFilterKind::Gaussian] {
        let filter = DemFilter {
            kind,
            sigma_px: 2.0,
        };
        let (_, fs) = dem_filter_noise_factors(&valid, w, h, filter, look_noise(4, 1.0, 1.0));
        let (mut edge_ss, mut hole_ss) = (0.0, 0.0);
        let runs = 300;
        for _ in 0..runs {
            let z: Vec<f64> = (0..w * h)
                .map(|i| {
                    if hole(i) {
                        return f64::NAN;
                    }
                    let (u, v): (f64, f64) = (rng.random::<f64>().max(1e-12), rng.random());
                    (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
                })
                .collect();
            let f = filter_dem(&z, w, h, filter);
            edge_ss += edge.iter().map(|&x| f[x] * f[x]).sum::<f64>();
            hole_ss += by_hole.iter().map(|&i| f[i] * f[i]).sum::<f64>();
        }
        let edge_sd = (edge_ss / (runs * edge.len()) as f64).sqrt();
        let hole_sd = (hole_ss / (runs * by_hole.len()) as f64).sqrt();
        // The cells of each set share one factor (the edge row away from corners; the hole's
        // four sides by symmetry).
        assert!(edge.iter().all(|&x| (fs[x] - fs[edge[0]]).abs() < 1e-12));
        assert!(
            by_hole
                .iter()
                .all(|&i| (fs[i] - fs[by_hole[0]]).abs() < 1e-9)
        );
        assert!(
            fs[edge[0]] > fs[15 * w + 5] + 0.01,
            "the edge keeps more noise"
        );
        assert!(
            (edge_sd / fs[edge[0]] - 1.0).abs() < 0.05,
            "{kind:?} edge: {edge_sd} vs {}",
            fs[edge[0]]
        );
        assert!(
            (hole_sd / fs[by_hole[0]] - 1.0).abs() < 0.07,
            "{kind:?} by the hole: {hole_sd} vs {}",
            fs[by_hole[0]]
        );
    }
}

#[test]
fn the_filtered_noise_correlation_sets_the_rehearsals_blur() {
    use super::demfilter::{DemFilter, DemFilterKind, error_blur_m};
    let chain = look_noise(8, 2.0, 0.54);
    // The default 1 px mean: neighbour correlation 0.84 at 20 m, a blur of 23.7 m (the
    // DEM's signal blur, 22.4 m, which the rehearsal keeps for it, gives 0.82).
    let g = error_blur_m(
        DemFilter {
            kind: DemFilterKind::Gaussian,
            sigma_px: 1.0,
        },
        chain,
        20.0,
    );
    assert!((g - 23.7).abs() < 0.3, "{g}");
    // The 2 px quadratic fit keeps more of the looks' correlation: about 0.90, 30 m (the
    // suite's error maps, noise and relief error together, show 0.82–0.84).
    let b = error_blur_m(
        DemFilter {
            kind: DemFilterKind::Quadratic,
            sigma_px: 2.0,
        },
        chain,
        20.0,
    );
    assert!((25.0..35.0).contains(&b), "{b}");
    // No filter over windows that do not overlap: white, no blur.
    let none = error_blur_m(
        DemFilter {
            kind: DemFilterKind::Quadratic,
            sigma_px: 0.0,
        },
        look_noise(4, 1.0, 1.0),
        20.0,
    );
    assert_eq!(none, 0.0);
}

/// The map-feature census against the truth (`products::features_on_truth`): a tile finds every
/// one of its features on the ground it was built from, and few on other ground (the same
/// preset drawn with another seed), so the count says how many of a map's blobs are ground.
#[test]
fn features_on_truth_counts_a_tiles_own_ground_and_little_of_another() {
    use crate::reference::noise_floor::FrameNoise;
    use crate::reference::{
        INSAR_SMOOTHING_M, Smoothing, TILE_FILE, reference_dem, write_reference,
    };
    use crate::terrain::{Preset, TerrainParams, generate};
    let ground = |seed: u64| {
        let mut p = TerrainParams::new(Preset::Shoemaker);
        p.size_m = 2000.0;
        p.seed = seed;
        let (dem, _) = generate(&p, &indicatif::ProgressBar::hidden()).unwrap();
        reference_dem(&dem, 20.0).unwrap()
    };
    let (own, other) = (ground(1), ground(2));
    let surf =
        crate::reference::surf_config_for(&FrameNoise::default_sensor(), 20.0, INSAR_SMOOTHING_M)
            .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let smoothing = Smoothing {
        target_m: INSAR_SMOOTHING_M,
        ..Smoothing::default_for_truth()
    };
    let n = write_reference(&own, dir.path(), &surf, 8192, smoothing)
        .unwrap()
        .features;
    let bytes = std::fs::read(dir.path().join(TILE_FILE)).unwrap();
    let on_own =
        super::products::features_on_truth(&bytes, &own, &surf, INSAR_SMOOTHING_M).unwrap();
    let on_other =
        super::products::features_on_truth(&bytes, &other, &surf, INSAR_SMOOTHING_M).unwrap();
    eprintln!("{n} features: {on_own} on their own ground, {on_other} on another");
    assert!(n >= 20, "too few features to test with: {n}");
    assert_eq!(on_own, n);
    assert!(4 * on_other < n, "{on_other} of {n} on another ground");
    // Garbage in: a clear error, not a count.
    assert!(super::products::features_on_truth(&bytes[..10], &own, &surf, 50.0).is_err());
}

/// Crater-floor relief under noise: the error beyond the bound is the relief the chain's
/// resolution flattens. Against the truth through the look window and the DEM filter, the
/// error is the bound's (noise); against the 20 m truth it is larger.
#[test]
fn the_bound_holds_the_error_at_the_chains_own_resolution() {
    // Gaussian mounds 20 m high, σ 50 m, every 250 m on a 1 km scene: the curvature of the
    // dense floors' small craters.
    let dem = scene(200, 5.0, |x, y| {
        let (u, v) = ((x % 250.0) - 125.0, (y % 250.0) - 125.0);
        -2000.0 + 20.0 * (-(u * u + v * v) / (2.0 * 50.0 * 50.0)).exp()
    });
    let radar = crate::sar::RadarPreset::Mission.config();
    let run = run_from_dem(
        &dem,
        &radar,
        Polarisation::HH,
        &InsarConfig::default(),
        false,
    )
    .unwrap();
    let a = compare(&run.product, &run.truth.grid, Some(&run.truth.window)).unwrap();
    // Measured: RMSE 2.28 m, 2.15 m through the window, 1.81 m with the filter too; bound
    // 1.84 m.
    assert!(a.height_rmse_resolution_matched_m < a.height_rmse_window_matched_m);
    assert!(a.height_rmse_window_matched_m < a.height_rmse_m);
    assert!(
        (0.8..=1.2).contains(&a.rmse_over_crlb_resolution_matched),
        "{}",
        a.rmse_over_crlb_resolution_matched
    );
    assert!(a.rmse_over_crlb > 1.2, "{}", a.rmse_over_crlb);
}

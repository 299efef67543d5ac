//! SURF invariance on synthetic lunar slope images: a 20 m/px reference and 10 m/px frames
//! (scale 0.5, as in the paper) rotated 0–345° in 15° steps, from the seeded analytic crater field.
//!
//! Repeatability: frame keypoints (in the area both images see) with a reference keypoint within
//! 1.5 reference px and a consistent scale, over the smaller of the two keypoint counts there.
//! Precision: among frame features whose descriptor nearest neighbour in the reference passes
//! Lowe's ratio test (0.8), the fraction whose neighbour is the true correspondent.

use nav_core::{DetectorConfig, Feature, Features, SlopeImage, SurfConfig, SurfWorkspace, extract};
use umbra_tests::{CraterField, FramePose, render_slope};

const SEED: u64 = 20_231_107;
const W: usize = 200;
const REF_PX_M: f64 = 20.0;
const FRAME_PX_M: f64 = 10.0;
const BORDER_PX: f64 = 12.0;
const POS_TOL_REF_PX: f64 = 1.5;

fn extract_at<const N: usize>(
    field: &CraterField,
    pose: &FramePose,
    ws: &mut SurfWorkspace<{ W * W }, W>,
) -> Features<N> {
    let px = render_slope(field, pose, W, W);
    let img = SlopeImage::new_checked(&px, W, W, pose.pixel_m as f32).unwrap();
    // The frame is twice as fine as the reference: skip frame detail below the reference's
    // smallest scale (σ ≈ 2.5 reference px = 5 frame px).
    let min_scale_px = if pose.pixel_m < REF_PX_M {
        2.5 * (REF_PX_M / pose.pixel_m) as f32
    } else {
        0.0
    };
    let cfg = SurfConfig {
        detector: DetectorConfig {
            min_scale_px,
            ..DetectorConfig::default()
        },
        upright: false,
    };
    let mut out = Features::<N>::new();
    extract(&img, &cfg, ws.scratch(), &mut out).unwrap();
    out
}

fn ssd(a: &Feature, b: &Feature) -> f32 {
    a.descriptor
        .iter()
        .zip(&b.descriptor)
        .map(|(x, y)| (x - y) * (x - y))
        .sum()
}

struct Figures {
    repeatability: f64,
    precision: f64,
    proposed: usize,
}

fn evaluate(
    reference: &[Feature],
    ref_pose: &FramePose,
    frame: &[Feature],
    frame_pose: &FramePose,
) -> Figures {
    let inside = |x: f64, y: f64| {
        x >= BORDER_PX
            && y >= BORDER_PX
            && x <= W as f64 - 1.0 - BORDER_PX
            && y <= W as f64 - 1.0 - BORDER_PX
    };
    // Frame keypoints mapped into reference pixels, with their scale in reference pixels.
    let mapped: Vec<(f64, f64, f64, bool)> = frame
        .iter()
        .map(|f| {
            let k = f.keypoint;
            let (sx, sy) = frame_pose.to_scene(k.x_px as f64, k.y_px as f64, W, W);
            let (rx, ry) = ref_pose.to_frame(sx, sy, W, W);
            let common = inside(k.x_px as f64, k.y_px as f64) && inside(rx, ry);
            (rx, ry, k.scale_px as f64 * FRAME_PX_M / REF_PX_M, common)
        })
        .collect();
    let ref_common = reference
        .iter()
        .filter(|f| {
            let k = f.keypoint;
            let (sx, sy) = ref_pose.to_scene(k.x_px as f64, k.y_px as f64, W, W);
            let (fx, fy) = frame_pose.to_frame(sx, sy, W, W);
            inside(k.x_px as f64, k.y_px as f64) && inside(fx, fy)
        })
        .count();
    let corresponds = |m: &(f64, f64, f64, bool), r: &Feature| {
        let k = r.keypoint;
        let d = (m.0 - k.x_px as f64).hypot(m.1 - k.y_px as f64);
        let ratio = m.2 / k.scale_px as f64;
        d <= POS_TOL_REF_PX && (1.0 / 1.4..=1.4).contains(&ratio)
    };
    let frame_common = mapped.iter().filter(|m| m.3).count();
    let repeated = mapped
        .iter()
        .filter(|m| m.3 && reference.iter().any(|r| corresponds(m, r)))
        .count();
    let (mut proposed, mut correct) = (0usize, 0usize);
    for (f, m) in frame.iter().zip(&mapped) {
        if !m.3 {
            continue;
        }
        let mut best = (f32::INFINITY, usize::MAX);
        let mut second = f32::INFINITY;
        for (j, r) in reference.iter().enumerate() {
            let d = ssd(f, r);
            if d < best.0 {
                second = best.0;
                best = (d, j);
            } else if d < second {
                second = d;
            }
        }
        if best.1 != usize::MAX && best.0 < 0.64 * second {
            proposed += 1;
            if corresponds(m, &reference[best.1]) {
                correct += 1;
            }
        }
    }
    Figures {
        repeatability: repeated as f64 / frame_common.min(ref_common).max(1) as f64,
        precision: correct as f64 / proposed.max(1) as f64,
        proposed,
    }
}

#[test]
fn repeatability_and_precision_under_rotation_and_scale() {
    let field = CraterField::new(SEED, 6000.0, 900, 30.0, 500.0);
    let mut ws = Box::new(SurfWorkspace::<{ W * W }, W>::new());
    let ref_pose = FramePose {
        x_m: 0.0,
        y_m: 0.0,
        heading_rad: 0.0,
        pixel_m: REF_PX_M,
    };
    let reference = extract_at::<512>(&field, &ref_pose, &mut ws);
    println!(
        "reference: {} features, {} dropped, {:?}",
        reference.len(),
        reference.dropped,
        reference.stats
    );
    let (mut min_rep, mut min_prec, mut sum_rep, mut sum_prec) = (1.0f64, 1.0f64, 0.0, 0.0);
    let mut n = 0;
    for step in 0..24 {
        let deg = step as f64 * 15.0;
        for (x_m, y_m) in [(180.0, -130.0), (-420.0, 350.0)] {
            let pose = FramePose {
                x_m,
                y_m,
                heading_rad: deg.to_radians(),
                pixel_m: FRAME_PX_M,
            };
            let frame = extract_at::<256>(&field, &pose, &mut ws);
            let fig = evaluate(reference.as_slice(), &ref_pose, frame.as_slice(), &pose);
            println!(
                "rotation {deg:5.1}° at ({x_m:6.0}, {y_m:6.0}) m: {:3} features, repeatability {:5.1} %, precision {:5.1} % of {} proposed",
                frame.len(),
                fig.repeatability * 100.0,
                fig.precision * 100.0,
                fig.proposed
            );
            min_rep = min_rep.min(fig.repeatability);
            min_prec = min_prec.min(fig.precision);
            sum_rep += fig.repeatability;
            sum_prec += fig.precision;
            n += 1;
        }
    }
    println!(
        "seed {SEED}: repeatability mean {:.1} % min {:.1} %; precision mean {:.1} % min {:.1} %",
        sum_rep / n as f64 * 100.0,
        min_rep * 100.0,
        sum_prec / n as f64 * 100.0,
        min_prec * 100.0
    );
    // Floors a little under the figures measured with this seed (mean 59.7 % / 82.5 %, worst
    // frame 44.4 % / 58.8 %): a regression in the detector or descriptor drops well below them.
    assert!(sum_rep / n as f64 >= 0.55, "mean repeatability");
    assert!(sum_prec / n as f64 >= 0.78, "mean precision");
    assert!(min_rep >= 0.40, "worst repeatability");
    assert!(min_prec >= 0.50, "worst precision");
}

//! Fast-Hessian accuracy on synthetic Gaussian blobs at known sub-pixel positions and scales.
//!
//! A Gaussian blob of standard deviation σ_b has its scale-normalised determinant-of-Hessian
//! maximum at σ = σ_b, so SURF should report the blob's centre and σ ≈ σ_b. A sign error in the
//! Newton step (x̂ = +H⁻¹∇ instead of −H⁻¹∇) moves points the wrong way by up to 0.5 px and fails this.

use nav_core::frame::{SlopePx, slope_from_deg};
use nav_core::{DetectorConfig, Features, SlopeImage, SurfConfig, SurfWorkspace, extract};

const W: usize = 192;

fn blob_image(blobs: &[(f32, f32, f32, f32)]) -> Vec<SlopePx> {
    let mut px = vec![SlopePx::from_bits(0); W * W];
    for row in 0..W {
        for col in 0..W {
            let mut v = 10.0f32;
            for &(bx, by, sigma, amp) in blobs {
                let (dx, dy) = (col as f32 - bx, row as f32 - by);
                v += amp * (-(dx * dx + dy * dy) / (2.0 * sigma * sigma)).exp();
            }
            px[row * W + col] = slope_from_deg(v);
        }
    }
    px
}

#[test]
fn blobs_are_found_at_their_subpixel_position_and_scale() {
    let mut ws = Box::new(SurfWorkspace::<{ W * W }, W>::new());
    let mut worst_pos = 0.0f32;
    let mut worst_scale = 0.0f32;
    let mut found = 0;
    // Blobs spread over the first two octaves' scale range, at sub-pixel offsets in every quadrant.
    let sigmas = [2.5f32, 3.0, 3.5, 4.5, 5.5, 6.5, 8.0];
    let offsets = [
        (0.0f32, 0.0f32),
        (0.3, -0.2),
        (-0.4, 0.35),
        (0.45, 0.45),
        (-0.25, -0.4),
    ];
    for (k, &sigma) in sigmas.iter().enumerate() {
        for (m, &(ox, oy)) in offsets.iter().enumerate() {
            let (bx, by) = (
                96.0 + ox + (k % 2) as f32 * 0.1,
                96.0 + oy - (m % 2) as f32 * 0.1,
            );
            // Positive and negative blobs (dark and bright) check both Laplacian signs.
            let amp = if (k + m) % 2 == 0 { 25.0 } else { -8.0 };
            let px = blob_image(&[(bx, by, sigma, amp)]);
            let img = SlopeImage::new_checked(&px, W, W, 10.0).unwrap();
            let cfg = SurfConfig {
                detector: DetectorConfig {
                    octaves: 3,
                    layers: 4,
                    threshold: 0.01,
                    min_scale_px: 0.0,
                    max_lazy_responses: u32::MAX,
                },
                upright: false,
            };
            let mut out = Features::<16>::new();
            extract(&img, &cfg, ws.scratch(), &mut out).unwrap();
            let best = out
                .as_slice()
                .iter()
                .map(|f| f.keypoint)
                .min_by(|a, b| {
                    let da = (a.x_px - bx).hypot(a.y_px - by);
                    let db = (b.x_px - bx).hypot(b.y_px - by);
                    da.total_cmp(&db)
                })
                .unwrap_or_else(|| panic!("no keypoint for blob σ={sigma} at ({bx},{by})"));
            let pos_err = (best.x_px - bx).hypot(best.y_px - by);
            let scale_err = (best.scale_px / sigma - 1.0).abs();
            println!(
                "σ_b={sigma:.2} at ({bx:.2},{by:.2}) amp {amp:+}: kp ({:.3},{:.3}) σ={:.3} pos_err={pos_err:.3} px scale_err={:.1}% lap+={}",
                best.x_px,
                best.y_px,
                best.scale_px,
                scale_err * 100.0,
                best.laplacian_positive
            );
            // A dark blob (slope dip, amp < 0) has a positive Laplacian.
            assert_eq!(best.laplacian_positive, amp < 0.0);
            worst_pos = worst_pos.max(pos_err);
            worst_scale = worst_scale.max(scale_err);
            found += 1;
        }
    }
    println!(
        "{found} blobs: worst position error {worst_pos:.3} px, worst scale error {:.1}%",
        worst_scale * 100.0
    );
    assert!(worst_pos <= 0.1, "position error {worst_pos} px");
    assert!(worst_scale <= 0.05, "scale error {worst_scale}");
}

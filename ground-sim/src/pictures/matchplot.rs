//! The paper's Fig. 7 as a picture: frame (left) and reference (right) slope images side by side,
//! matched keypoints joined by lines (inliers green, rejected matches red).

use image::{Rgb, RgbImage};
use imageproc::drawing::{draw_hollow_circle_mut, draw_line_segment_mut};

/// Grey level of a slope value: 0° black, `max_deg` and above white; no data dark blue.
fn grey(v: f32, max_deg: f32) -> Rgb<u8> {
    if v.is_nan() {
        return Rgb([20, 30, 70]);
    }
    let g = (v / max_deg).clamp(0.0, 1.0) * 255.0;
    Rgb([g as u8, g as u8, g as u8])
}

/// Render the match picture. `frame` and `reference` are slope images in degrees (`NaN` = no
/// data); `pairs` are `(frame x, frame y, reference x, reference y, inlier)` in pixels.
pub fn match_picture(
    frame: (&[f32], usize, usize),
    reference: (&[f32], usize, usize),
    pairs: &[(f32, f32, f32, f32, bool)],
) -> RgbImage {
    let (fv, fw, fh) = frame;
    let (rv, rw, rh) = reference;
    let gap = 16u32;
    let (w, h) = (fw as u32 + gap + rw as u32, fh.max(rh) as u32);
    let mut img = RgbImage::from_pixel(w, h, Rgb([255, 255, 255]));
    // A common grey scale: the 99th percentile of both images' slopes.
    let mut all: Vec<f32> = fv
        .iter()
        .chain(rv)
        .copied()
        .filter(|v| v.is_finite())
        .collect();
    let max_deg = if all.is_empty() {
        30.0
    } else {
        let k = (all.len() - 1) * 99 / 100;
        *all.select_nth_unstable_by(k, f32::total_cmp).1
    }
    .max(1.0);
    for (i, &v) in fv.iter().enumerate() {
        img.put_pixel((i % fw) as u32, (i / fw) as u32, grey(v, max_deg));
    }
    let x0 = fw as u32 + gap;
    for (i, &v) in rv.iter().enumerate() {
        img.put_pixel(x0 + (i % rw) as u32, (i / rw) as u32, grey(v, max_deg));
    }
    // Outliers first so inlier lines stay on top.
    for inlier in [false, true] {
        let colour = if inlier {
            Rgb([40, 220, 60])
        } else {
            Rgb([230, 50, 40])
        };
        for &(fx, fy, rx, ry, _) in pairs.iter().filter(|p| p.4 == inlier) {
            let a = (fx, fy);
            let b = (rx + x0 as f32, ry);
            draw_line_segment_mut(&mut img, a, b, colour);
            draw_hollow_circle_mut(&mut img, (fx.round() as i32, fy.round() as i32), 3, colour);
            draw_hollow_circle_mut(
                &mut img,
                (b.0.round() as i32, b.1.round() as i32),
                3,
                colour,
            );
        }
    }
    img
}

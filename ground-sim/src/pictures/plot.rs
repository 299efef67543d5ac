//! Small line plots as PNG (axes, ticks, labels, legend) for trajectories and error histories,
//! drawn with imageproc and the pictures' bitmap font.

use image::{Rgb, RgbImage};
use imageproc::drawing::{draw_filled_circle_mut, draw_line_segment_mut};

use crate::pictures::render::{GLYPH, draw_text, fmt_tick, ticks};

/// Colours for series that stand side by side (a categorical palette), RGB.
pub const PALETTE: [[u8; 3]; 8] = [
    [31, 119, 180],
    [255, 127, 14],
    [44, 160, 44],
    [214, 39, 40],
    [148, 103, 189],
    [140, 86, 75],
    [227, 119, 194],
    [127, 127, 127],
];

/// How a series is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Style {
    /// Connected line.
    Line,
    /// Dots of the given radius, pixels.
    Dots(i32),
}

/// One data series.
#[derive(Debug, Clone)]
pub struct Series {
    /// Legend text.
    pub label: String,
    /// RGB colour.
    pub colour: [u8; 3],
    /// Points `(x, y)` in data units; NaN points break a line.
    pub points: Vec<(f64, f64)>,
    /// Line or dots.
    pub style: Style,
}

/// A line plot.
#[derive(Debug, Clone)]
pub struct Plot {
    /// Picture width, pixels.
    pub width: u32,
    /// Picture height, pixels.
    pub height: u32,
    /// Title above the axes.
    pub title: String,
    /// X axis label.
    pub x_label: String,
    /// Y axis label.
    pub y_label: String,
    /// Series, drawn in order.
    pub series: Vec<Series>,
    /// Same scale on both axes (maps, trajectories).
    pub equal_axes: bool,
}

impl Plot {
    /// Render to an RGB image.
    pub fn render(&self) -> RgbImage {
        let mut img = RgbImage::from_pixel(self.width, self.height, Rgb([255, 255, 255]));
        let (left, right, top, bottom) = (10 * GLYPH, 2 * GLYPH, 3 * GLYPH, 4 * GLYPH);
        let (pw, ph) = (
            self.width.saturating_sub(left + right).max(1),
            self.height.saturating_sub(top + bottom).max(1),
        );
        let finite = self
            .series
            .iter()
            .flat_map(|s| s.points.iter())
            .filter(|p| p.0.is_finite() && p.1.is_finite());
        let (mut x0, mut x1, mut y0, mut y1) = (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        );
        for &(x, y) in finite {
            x0 = x0.min(x);
            x1 = x1.max(x);
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
        if !(x1 > x0) {
            (x0, x1) = (x0.min(0.0) - 1.0, x1.max(0.0) + 1.0);
        }
        if !(y1 > y0) {
            (y0, y1) = (y0.min(0.0) - 1.0, y1.max(0.0) + 1.0);
        }
        let pad = |a: f64, b: f64| 0.04 * (b - a);
        let (px, py) = (pad(x0, x1), pad(y0, y1));
        (x0, x1, y0, y1) = (x0 - px, x1 + px, y0 - py, y1 + py);
        if self.equal_axes {
            // Widen the tighter axis so one data unit is the same number of pixels on both.
            let (sx, sy) = ((x1 - x0) / pw as f64, (y1 - y0) / ph as f64);
            if sx > sy {
                let c = 0.5 * (y0 + y1);
                let half = 0.5 * sx * ph as f64;
                (y0, y1) = (c - half, c + half);
            } else {
                let c = 0.5 * (x0 + x1);
                let half = 0.5 * sy * pw as f64;
                (x0, x1) = (c - half, c + half);
            }
        }
        let to_px = |x: f64, y: f64| {
            (
                left as f32 + ((x - x0) / (x1 - x0) * pw as f64) as f32,
                top as f32 + ((y1 - y) / (y1 - y0) * ph as f64) as f32,
            )
        };
        let grid = Rgb([225, 225, 225]);
        let ink = [30, 30, 30];
        let xt = ticks(x0, x1);
        let yt = ticks(y0, y1);
        let step = |t: &[f64]| if t.len() > 1 { t[1] - t[0] } else { 1.0 };
        for &t in &xt {
            let (x, _) = to_px(t, y0);
            draw_line_segment_mut(&mut img, (x, top as f32), (x, (top + ph) as f32), grid);
            let s = fmt_tick(t, step(&xt));
            draw_text(
                &mut img,
                (x as u32).saturating_sub(s.len() as u32 * GLYPH / 2),
                top + ph + 4,
                &s,
                ink,
            );
        }
        for &t in &yt {
            let (_, y) = to_px(x0, t);
            draw_line_segment_mut(&mut img, (left as f32, y), ((left + pw) as f32, y), grid);
            let s = fmt_tick(t, step(&yt));
            draw_text(
                &mut img,
                left.saturating_sub(s.len() as u32 * GLYPH + 4),
                (y as u32).saturating_sub(GLYPH / 2),
                &s,
                ink,
            );
        }
        let frame = Rgb([60, 60, 60]);
        let (l, t, r, b) = (
            left as f32,
            top as f32,
            (left + pw) as f32,
            (top + ph) as f32,
        );
        for (a, c) in [
            ((l, t), (r, t)),
            ((r, t), (r, b)),
            ((r, b), (l, b)),
            ((l, b), (l, t)),
        ] {
            draw_line_segment_mut(&mut img, a, c, frame);
        }
        for s in &self.series {
            let colour = Rgb(s.colour);
            match s.style {
                Style::Line => {
                    // Two pixels wide, with a dot on every data point, so that curves stay
                    // readable on a printed page and sparse sweeps show where they were
                    // measured.
                    for w in s.points.windows(2) {
                        let (a, c) = (w[0], w[1]);
                        if [a.0, a.1, c.0, c.1].iter().all(|v| v.is_finite()) {
                            let (p, q) = (to_px(a.0, a.1), to_px(c.0, c.1));
                            for (dx, dy) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0)] {
                                draw_line_segment_mut(
                                    &mut img,
                                    (p.0 + dx, p.1 + dy),
                                    (q.0 + dx, q.1 + dy),
                                    colour,
                                );
                            }
                        }
                    }
                    if s.points.len() <= 40 {
                        for &(x, y) in s
                            .points
                            .iter()
                            .filter(|p| p.0.is_finite() && p.1.is_finite())
                        {
                            let (u, v) = to_px(x, y);
                            draw_filled_circle_mut(&mut img, (u as i32, v as i32), 3, colour);
                        }
                    }
                }
                Style::Dots(radius) => {
                    for &(x, y) in s
                        .points
                        .iter()
                        .filter(|p| p.0.is_finite() && p.1.is_finite())
                    {
                        let (u, v) = to_px(x, y);
                        draw_filled_circle_mut(&mut img, (u as i32, v as i32), radius, colour);
                    }
                }
            }
        }
        draw_text(&mut img, left, GLYPH / 2, &self.title, ink);
        draw_text(
            &mut img,
            left + pw / 2 - (self.x_label.len() as u32 * GLYPH) / 2,
            top + ph + 4 + GLYPH + 8,
            &self.x_label,
            ink,
        );
        // The y label sits above the axis, between the title and the plot, clear of the
        // x label.
        draw_text(
            &mut img,
            4,
            top.saturating_sub(GLYPH + 4),
            &self.y_label,
            ink,
        );
        // Legend, top right inside the axes.
        let mut ly = top + 6;
        // Series without a label (e.g. the dots over a line) stay out of the legend.
        for s in self.series.iter().filter(|s| !s.label.is_empty()) {
            let lx = left + pw - (s.label.len() as u32 + 3) * GLYPH - 6;
            draw_line_segment_mut(
                &mut img,
                (lx as f32, (ly + GLYPH / 2) as f32),
                ((lx + 2 * GLYPH - 4) as f32, (ly + GLYPH / 2) as f32),
                Rgb(s.colour),
            );
            draw_text(&mut img, lx + 2 * GLYPH, ly, &s.label, s.colour);
            ly += GLYPH + 4;
        }
        img
    }
}

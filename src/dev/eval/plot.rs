//! Minimal PNG plots for the evaluation reports, drawn directly with the `image` crate.
//!
//! Why not a plotting crate: `plotters` needs a font stack (fontconfig/freetype or an embedded
//! font) for any axis text, and the default build must stay free of system libraries; these plots
//! carry no text at all and `summary.md` states the axes, ranges and grid spacing instead.

use image::{Rgb, RgbImage};

const WHITE: Rgb<u8> = Rgb([255, 255, 255]);
const GRID: Rgb<u8> = Rgb([225, 225, 225]);
const AXIS: Rgb<u8> = Rgb([120, 120, 120]);
/// Colour of the identity line / the zero-error line.
pub const REFERENCE: Rgb<u8> = Rgb([220, 40, 40]);
/// Colour of data points and bars.
pub const DATA: Rgb<u8> = Rgb([30, 90, 200]);

/// A plot area mapping data coordinates `[x0, x1] x [y0, y1]` to a square-ish pixel canvas.
#[derive(Debug, Clone)]
pub struct Canvas {
    /// The picture.
    pub img: RgbImage,
    x0: f64,
    x1: f64,
    y0: f64,
    y1: f64,
    margin: u32,
}

impl Canvas {
    /// A `w` x `h` white canvas showing `x0..x1` horizontally and `y0..y1` vertically (up).
    pub fn new(w: u32, h: u32, (x0, x1): (f64, f64), (y0, y1): (f64, f64)) -> Self {
        Self {
            img: RgbImage::from_pixel(w.max(16), h.max(16), WHITE),
            x0,
            x1,
            y0,
            y1,
            margin: 8,
        }
    }

    /// Pixel position of data point `(x, y)` (may lie outside the image).
    fn to_px(&self, x: f64, y: f64) -> (f64, f64) {
        let (w, h) = (self.img.width() as f64, self.img.height() as f64);
        let m = self.margin as f64;
        let px = m + (x - self.x0) / (self.x1 - self.x0) * (w - 2.0 * m - 1.0);
        let py = h - 1.0 - m - (y - self.y0) / (self.y1 - self.y0) * (h - 2.0 * m - 1.0);
        (px, py)
    }

    fn put(&mut self, x: i64, y: i64, c: Rgb<u8>) {
        if x >= 0 && y >= 0 && (x as u32) < self.img.width() && (y as u32) < self.img.height() {
            self.img.put_pixel(x as u32, y as u32, c);
        }
    }

    /// A straight line between two data points (sampled densely; plots are small).
    pub fn line(&mut self, a: (f64, f64), b: (f64, f64), c: Rgb<u8>) {
        let (ax, ay) = self.to_px(a.0, a.1);
        let (bx, by) = self.to_px(b.0, b.1);
        let n = ((bx - ax).abs().max((by - ay).abs()).ceil() as usize).clamp(1, 100_000);
        for i in 0..=n {
            let t = i as f64 / n as f64;
            self.put(
                (ax + t * (bx - ax)).round() as i64,
                (ay + t * (by - ay)).round() as i64,
                c,
            );
        }
    }

    /// Grid lines every `step` in both directions and the axes through 0 (when in range).
    pub fn grid(&mut self, step: f64) {
        let (x0, x1, y0, y1) = (self.x0, self.x1, self.y0, self.y1);
        if step > 0.0 {
            let mut v = (x0 / step).ceil() * step;
            while v <= x1 + 1e-12 {
                self.line((v, y0), (v, y1), GRID);
                v += step;
            }
            let mut v = (y0 / step).ceil() * step;
            while v <= y1 + 1e-12 {
                self.line((x0, v), (x1, v), GRID);
                v += step;
            }
        }
        if x0 <= 0.0 && x1 >= 0.0 {
            self.line((0.0, y0), (0.0, y1), AXIS);
        }
        if y0 <= 0.0 && y1 >= 0.0 {
            self.line((x0, 0.0), (x1, 0.0), AXIS);
        }
    }

    /// A small filled square marker at a data point.
    pub fn dot(&mut self, x: f64, y: f64, c: Rgb<u8>) {
        let (px, py) = self.to_px(x, y);
        let (px, py) = (px.round() as i64, py.round() as i64);
        for dy in -1..=1 {
            for dx in -1..=1 {
                self.put(px + dx, py + dy, c);
            }
        }
    }

    /// A filled bar from `y = 0` up to `height` over `[xa, xb]`.
    pub fn bar(&mut self, xa: f64, xb: f64, height: f64, c: Rgb<u8>) {
        let (pa, p0) = self.to_px(xa, 0.0);
        let (pb, ph) = self.to_px(xb, height);
        let (left, right) = (pa.min(pb).round() as i64, pa.max(pb).round() as i64);
        let (top, bottom) = (p0.min(ph).round() as i64, p0.max(ph).round() as i64);
        for y in top..=bottom {
            for x in left..right.max(left + 1) {
                self.put(x, y, c);
            }
        }
    }
}

/// Estimated against true `k`: one dot per estimate (true k jittered a little so the columns
/// show their spread), the identity line in red, grid every 0.1, both axes `-range..range`.
pub fn scatter_estimates(points: &[(f64, f64)], range: f64) -> RgbImage {
    let mut c = Canvas::new(480, 480, (-range, range), (-range, range));
    c.grid(0.1);
    c.line((-range, -range), (range, range), REFERENCE);
    for (i, &(t, e)) in points.iter().enumerate() {
        // Deterministic jitter of +-0.012 in true k, so overlapping dots spread into a column.
        let jitter = ((i * 7919) % 25) as f64 / 1000.0 - 0.012;
        c.dot(t + jitter, e.clamp(-range, range), DATA);
    }
    c.img
}

/// Histograms of `errors` (estimate minus true k), one panel per group stacked top to bottom,
/// each over `-range..range` in `bins` bins, heights as the share of the group's samples
/// (full panel height = `max_share`); red line at zero error, grid every 0.05.
pub fn error_histograms(groups: &[Vec<f64>], range: f64, bins: usize, max_share: f64) -> RgbImage {
    let (w, ph) = (480u32, 90u32);
    let n = groups.len().max(1) as u32;
    let mut out = RgbImage::from_pixel(w, ph * n, WHITE);
    let bins = bins.max(1);
    for (g, errors) in groups.iter().enumerate() {
        let mut c = Canvas::new(w, ph, (-range, range), (0.0, max_share));
        c.grid(0.05);
        let width = 2.0 * range / bins as f64;
        let mut counts = vec![0usize; bins];
        for &e in errors.iter().filter(|e| e.is_finite()) {
            let b = ((e.clamp(-range, range) + range) / width).floor() as usize;
            counts[b.min(bins - 1)] += 1;
        }
        let total = errors.len().max(1) as f64;
        for (b, &cnt) in counts.iter().enumerate() {
            let xa = -range + b as f64 * width;
            c.bar(xa, xa + width, (cnt as f64 / total).min(max_share), DATA);
        }
        c.line((0.0, 0.0), (0.0, max_share), REFERENCE);
        // A dark separator line at the bottom of each panel.
        for x in 0..w {
            c.img.put_pixel(x, ph - 1, AXIS);
        }
        image::imageops::replace(&mut out, &c.img, 0, (g as u32 * ph) as i64);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identity_line_crosses_the_centre() {
        let img = scatter_estimates(&[], 0.5);
        // The red identity line passes through the middle of the canvas.
        let mid = img.width() / 2;
        let hit = (mid - 2..=mid + 2)
            .any(|y| (mid - 2..=mid + 2).any(|x| *img.get_pixel(x, y) == REFERENCE));
        assert!(hit);
    }

    #[test]
    fn histogram_has_one_panel_per_group() {
        let img = error_histograms(&[vec![0.0, 0.01], vec![-0.1]], 0.2, 40, 0.5);
        assert_eq!(img.height(), 180);
        assert!(img.pixels().any(|p| *p == DATA));
    }
}

//! What a panning rolling-shutter camera adds to a still beyond one shear (`eval shear
//! --camera`, issue 61): a pan whose speed changes during the readout (the rows' offsets bend,
//! so the shear depends on the row), a vertical drift (the rows spread apart), motion blur
//! along the rows, sensor noise and JPEG.
//!
//! Time is in frame intervals; row `y'` of the frame is read at `s = rho (y' - c) / H` from
//! the middle row `c = H / 2`. The content moves right at `v(s) = v0 (1 + a s)` px per frame
//! (`v0 = k H / rho`, so the middle row's shear is the nominal `k`), so row `y'` is displaced by
//! `d(y') = v0 (s + a s^2 / 2)` and the local shear there is `d'(y') = k (1 + a s)`. A vertical
//! drift scales rows about `c`; each row is blurred by a box of `|v(s)| e` px (`e`: the
//! exposure); Gaussian noise and a JPEG round trip follow. The frame keeps only the columns
//! every row covers, as a camera's frame has no empty corner.

use image::{codecs::jpeg::JpegEncoder, DynamicImage, ImageFormat, RgbImage};

use crate::error::{Error, Result};
use crate::geometry::Point;
use crate::rng::SplitMix64;

/// The camera's settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraLike {
    /// The readout's share of the frame interval, `rho`.
    pub readout_fraction: f64,
    /// The pan's relative change of speed per frame interval, `a` (0.5: half as fast again one
    /// frame interval later).
    pub acceleration: f64,
    /// The exposure in frame intervals (0.12: 1/250 s at 30 frames/s).
    pub exposure: f64,
    /// The rows' vertical scale from a vertical drift during the readout (1.02: 2% apart).
    pub vertical_scale: f64,
    /// Standard deviation of the sensor noise, grey levels.
    pub noise: f64,
    /// JPEG quality of the delivered frame (0: no JPEG).
    pub jpeg_quality: u8,
}

impl Default for CameraLike {
    fn default() -> Self {
        Self {
            readout_fraction: 0.8,
            acceleration: 0.5,
            exposure: 0.12,
            vertical_scale: 1.02,
            noise: 2.0,
            jpeg_quality: 85,
        }
    }
}

/// Where a photo's points land in the frame [`CameraLike::render`] makes of it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraFrame {
    k: f64,
    rho: f64,
    acceleration: f64,
    scale: f64,
    exposure: f64,
    height: f64,
    /// The photo's column shown by the frame's column 0 on the middle row.
    x0: f64,
    /// The frame's width, pixels.
    pub width: u32,
}

impl CameraFrame {
    fn time(&self, y: f64) -> f64 {
        self.rho * (y - self.height / 2.0) / self.height
    }

    fn speed(&self) -> f64 {
        self.k * self.height / self.rho
    }

    /// The displacement of frame row `y` relative to the middle row, pixels.
    pub fn offset(&self, y: f64) -> f64 {
        let s = self.time(y);
        self.speed() * (s + self.acceleration * s * s / 2.0)
    }

    /// The shear at frame row `y`: the slope of the rows' offsets there.
    pub fn local_k(&self, y: f64) -> f64 {
        self.k * (1.0 + self.acceleration * self.time(y))
    }

    /// The motion blur of frame row `y`, pixels.
    pub fn blur(&self, y: f64) -> f64 {
        (self.speed() * (1.0 + self.acceleration * self.time(y)) * self.exposure).abs()
    }

    /// The frame point showing photo point `p`.
    pub fn apply(&self, p: Point) -> Point {
        let c = self.height / 2.0;
        let y = c + self.scale * (p.y - c);
        Point::new(p.x + self.offset(y) - self.x0, y)
    }

    /// The photo point frame point `q` shows.
    pub fn invert(&self, q: Point) -> Point {
        let c = self.height / 2.0;
        Point::new(q.x + self.x0 - self.offset(q.y), c + (q.y - c) / self.scale)
    }
}

impl CameraLike {
    /// Checks the settings: a readout fraction in (0, 1.2], finite acceleration, exposure in
    /// [0, 1], vertical scale in [0.5, 2], noise >= 0, JPEG quality at most 100.
    pub fn validate(&self) -> Result<()> {
        let ok = self.readout_fraction > 0.0
            && self.readout_fraction <= 1.2
            && self.acceleration.is_finite()
            && (0.0..=1.0).contains(&self.exposure)
            && (0.5..=2.0).contains(&self.vertical_scale)
            && self.noise >= 0.0
            && self.noise.is_finite()
            && self.jpeg_quality <= 100;
        if ok {
            Ok(())
        } else {
            Err(Error::InvalidArgument(format!(
                "camera-like settings out of range: {self:?}"
            )))
        }
    }

    /// The frame's geometry for a `width` x `height` photo at nominal shear `k`, or `None`
    /// when no column is covered by every row.
    pub fn frame(&self, k: f64, width: u32, height: u32) -> Option<CameraFrame> {
        let mut f = CameraFrame {
            k,
            rho: self.readout_fraction,
            acceleration: self.acceleration,
            scale: self.vertical_scale,
            exposure: self.exposure,
            height: f64::from(height),
            x0: 0.0,
            width: 0,
        };
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for y in 0..height {
            let d = f.offset(f64::from(y));
            lo = lo.min(d);
            hi = hi.max(d);
        }
        // Frame column x shows photo column x + x0 - d(y): inside [0, W - 1] on every row.
        f.x0 = hi.ceil();
        let last = (f64::from(width) - 1.0 + lo).floor();
        if !(k.is_finite() && last >= f.x0) {
            return None;
        }
        f.width = (last - f.x0) as u32 + 1;
        Some(f)
    }

    /// The frame this camera makes of `img` at nominal shear `k` (noise drawn from `seed`),
    /// and where the photo's points land in it.
    pub fn render(&self, img: &DynamicImage, k: f64, seed: u64) -> Result<(RgbImage, CameraFrame)> {
        self.validate()?;
        let (w, h) = (img.width(), img.height());
        let frame = self.frame(k, w, h).ok_or_else(|| {
            Error::InvalidArgument(format!(
                "no column of a {w}x{h} photo stays in view at k = {k}"
            ))
        })?;
        let src = img.to_rgb32f();
        let (ws, fw) = (w as usize, frame.width as usize);
        let mut rng = SplitMix64::new(seed);
        let mut out = RgbImage::new(frame.width, h);
        let mut row = vec![0f32; ws * 3];
        let mut shifted = vec![0f32; fw * 3];
        let mut blurred = vec![0f32; fw * 3];
        for y in 0..h {
            let yf = f64::from(y);
            // The photo's row, between two rows when the drift spreads them.
            let sy = frame
                .invert(Point::new(0.0, yf))
                .y
                .clamp(0.0, f64::from(h - 1));
            let (y0, t) = (sy.floor() as u32, (sy - sy.floor()) as f32);
            let y1 = (y0 + 1).min(h - 1);
            for x in 0..w {
                let (a, b) = (src.get_pixel(x, y0).0, src.get_pixel(x, y1).0);
                for c in 0..3 {
                    row[x as usize * 3 + c] = a[c] * (1.0 - t) + b[c] * t;
                }
            }
            let shift = frame.x0 - frame.offset(yf);
            for x in 0..fw {
                let sx = (x as f64 + shift).clamp(0.0, (ws - 1) as f64);
                let (x0, t) = (sx.floor() as usize, (sx - sx.floor()) as f32);
                let x1 = (x0 + 1).min(ws - 1);
                for c in 0..3 {
                    shifted[x * 3 + c] = row[x0 * 3 + c] * (1.0 - t) + row[x1 * 3 + c] * t;
                }
            }
            box_blur(&shifted, frame.blur(yf), &mut blurred);
            for x in 0..fw {
                let mut px = [0u8; 3];
                for (c, v) in px.iter_mut().enumerate() {
                    let noisy =
                        f64::from(blurred[x * 3 + c]) * 255.0 + self.noise * gaussian(&mut rng);
                    *v = noisy.round().clamp(0.0, 255.0) as u8;
                }
                out.put_pixel(x as u32, y, image::Rgb(px));
            }
        }
        if self.jpeg_quality > 0 {
            out = jpeg_round_trip(&out, self.jpeg_quality)?;
        }
        Ok((out, frame))
    }
}

/// An RGB row (interleaved) blurred into `out` (as long) by a box `length` px long centred on
/// each pixel, the box's two end taps weighted by the fraction they cover; edges replicated.
/// Running sums keep it one pass whatever the length.
fn box_blur(row: &[f32], length: f64, out: &mut [f32]) {
    let n = row.len() / 3;
    if length <= 1.0 || n == 0 {
        out.copy_from_slice(row);
        return;
    }
    let half = length / 2.0;
    let whole = (half - 0.5).floor().max(0.0) as usize;
    let edge = ((half - 0.5) - whole as f64) as f32;
    let at = |i: isize, c: usize| row[(i.clamp(0, n as isize - 1) as usize) * 3 + c];
    for c in 0..3 {
        let mut sum: f32 = (-(whole as isize)..=whole as isize).map(|i| at(i, c)).sum();
        for x in 0..n as isize {
            if x > 0 {
                sum += at(x + whole as isize, c) - at(x - 1 - whole as isize, c);
            }
            let ends = at(x - whole as isize - 1, c) + at(x + whole as isize + 1, c);
            out[x as usize * 3 + c] = (sum + edge * ends) / (2.0 * whole as f32 + 1.0 + 2.0 * edge);
        }
    }
}

/// A standard normal draw (Box-Muller).
fn gaussian(rng: &mut SplitMix64) -> f64 {
    let u = 1.0 - rng.next_f64();
    let v = rng.next_f64();
    (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
}

fn jpeg_round_trip(img: &RgbImage, quality: u8) -> Result<RgbImage> {
    let mut bytes = Vec::new();
    img.write_with_encoder(JpegEncoder::new_with_quality(&mut bytes, quality.max(1)))
        .map_err(|e| Error::InvalidArgument(format!("JPEG encoding failed: {e}")))?;
    Ok(
        image::load_from_memory_with_format(&bytes, ImageFormat::Jpeg)
            .map_err(|e| Error::InvalidArgument(format!("JPEG decoding failed: {e}")))?
            .to_rgb8(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plain() -> CameraLike {
        CameraLike {
            acceleration: 0.0,
            exposure: 0.0,
            vertical_scale: 1.0,
            noise: 0.0,
            jpeg_quality: 0,
            ..CameraLike::default()
        }
    }

    /// Without acceleration the offsets are the documented shear about the middle row, and
    /// the frame keeps the columns every row covers (`W - |k| H` wide, rounded in).
    #[test]
    fn a_steady_pan_is_a_shear_about_the_middle_row() {
        let f = plain().frame(0.4, 100, 50).expect("frame");
        assert!((f.offset(25.0)).abs() < 1e-12);
        assert!((f.offset(45.0) - 8.0).abs() < 1e-9);
        assert!((f.local_k(0.0) - 0.4).abs() < 1e-12);
        assert_eq!(f.width, 80); // offsets from -10 to +9.6 over rows 0..49
        let p = Point::new(50.0, 45.0);
        let q = f.apply(p);
        assert!((q.x - (50.0 + 8.0 - 10.0)).abs() < 1e-9 && (q.y - 45.0).abs() < 1e-12);
        let back = f.invert(q);
        assert!((back.x - p.x).abs() < 1e-9 && (back.y - p.y).abs() < 1e-9);
    }

    /// A speeding pan bends the offsets: the local shear grows down the frame as `k (1 + a s)`
    /// and matches the offsets' numerical slope; the drift scales rows about the middle.
    #[test]
    fn a_speeding_pan_shears_lower_rows_more() {
        let cam = CameraLike {
            vertical_scale: 1.1,
            ..plain()
        };
        let cam = CameraLike {
            acceleration: 0.5,
            ..cam
        };
        let f = cam.frame(0.3, 400, 200).expect("frame");
        let (top, bottom) = (f.local_k(0.0), f.local_k(199.0));
        assert!((top - 0.3 * (1.0 - 0.5 * 0.4)).abs() < 1e-9, "{top}");
        assert!(bottom > 0.3 && bottom < 0.3 * 1.2 + 1e-9, "{bottom}");
        let slope = (f.offset(150.5) - f.offset(149.5)) / 1.0;
        assert!((slope - f.local_k(150.0)).abs() < 1e-6);
        let q = f.apply(Point::new(10.0, 150.0));
        assert!((q.y - (100.0 + 1.1 * 50.0)).abs() < 1e-9);
        let back = f.invert(q);
        assert!((back.x - 10.0).abs() < 1e-9 && (back.y - 150.0).abs() < 1e-9);
    }

    /// The rendered frame shows the photo where `apply` says: a bright dot moves to its
    /// predicted place (no blur, no noise), and a sheared past its width photo is refused.
    #[test]
    fn render_puts_points_where_apply_says() {
        let mut img = RgbImage::new(120, 60);
        img.put_pixel(70, 50, image::Rgb([255, 255, 255]));
        let cam = CameraLike {
            acceleration: 0.5,
            ..plain()
        };
        let (out, f) = cam
            .render(&DynamicImage::ImageRgb8(img), 0.3, 1)
            .expect("render");
        assert_eq!(out.width(), f.width);
        let q = f.apply(Point::new(70.0, 50.0));
        let (mut best, mut at) = (0u8, (0, 0));
        for (x, y, p) in out.enumerate_pixels() {
            if p.0[0] > best {
                (best, at) = (p.0[0], (x, y));
            }
        }
        assert!((f64::from(at.0) - q.x).abs() <= 1.0 && (f64::from(at.1) - q.y).abs() <= 0.5);
        assert!(cam
            .render(&DynamicImage::new_rgb8(10, 100), 0.5, 1)
            .is_err());
    }

    /// The box keeps a row's mean and smears an edge over its length; noise has the set spread.
    #[test]
    fn blur_and_noise_have_their_sizes() {
        let row: Vec<f32> = (0..40)
            .flat_map(|x| [if x < 20 { 0.0 } else { 1.0 }; 3])
            .collect();
        let mut out = vec![0f32; row.len()];
        box_blur(&row, 10.0, &mut out);
        let ramp = (0..40)
            .filter(|&x| out[x * 3] > 0.01 && out[x * 3] < 0.99)
            .count();
        assert!((9..=11).contains(&ramp), "{ramp}");
        assert!((out[20 * 3] - 0.55).abs() < 0.06, "{}", out[60]);
        let mut rng = SplitMix64::new(7);
        let draws: Vec<f64> = (0..20000).map(|_| gaussian(&mut rng)).collect();
        let var = draws.iter().map(|d| d * d).sum::<f64>() / draws.len() as f64;
        assert!((var - 1.0).abs() < 0.05, "{var}");
        assert!(CameraLike {
            readout_fraction: 0.0,
            ..CameraLike::default()
        }
        .validate()
        .is_err());
    }
}

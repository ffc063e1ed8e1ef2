//! The square crop the landmark network sees: a face resampled through an affine frame that
//! may remove a shear and a roll, so that the network is shown a nearly upright, unsheared face
//! once the first estimate is known.
//!
//! A crop pixel `p` (pixel centres at integers, the crop's centre at `((N - 1) / 2, (N - 1) / 2)`)
//! shows the image point `centre + scale * S(k) R(roll) (p - crop centre)`, where
//! `S(k) = [[1, k], [0, 1]]` is this crate's shear ([`crate::geometry::Shear`]) and `R` turns
//! clockwise on screen (x right, y down) for a positive roll, as
//! [`crate::locate::filters::NormalizedFace::rotated`] does. A face sheared by `k` and tilted by `roll`
//! in the image therefore appears upright and unsheared in a crop made with that `k` and `roll`.

use image::GrayImage;

use crate::geometry::{Point, Rect};
use crate::resample::{bilinear_clamped, resample};

/// The affine map from crop pixels to image pixels (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CropFrame {
    /// The image point the crop's centre shows.
    pub(crate) centre: Point,
    /// Image pixels per crop pixel.
    pub(crate) scale: f64,
    /// The shear the crop removes (pivot: the crop's centre).
    pub(crate) k: f64,
    /// The roll the crop removes, radians (positive: the head turned clockwise on screen).
    pub(crate) roll: f64,
    /// Side of the crop, pixels.
    pub(crate) size: usize,
}

impl CropFrame {
    /// The linear part `scale * S(k) R(roll)`, row-major.
    fn linear(&self) -> [f64; 4] {
        let (s, c) = self.roll.sin_cos();
        let m = self.scale;
        [m * (c + self.k * s), m * (-s + self.k * c), m * s, m * c]
    }

    /// The crop's own centre, in crop pixels.
    pub(crate) fn crop_centre(&self) -> f64 {
        (self.size as f64 - 1.0) / 2.0
    }

    /// The image point a crop point shows.
    pub fn to_image(&self, p: Point) -> Point {
        let [a, b, c, d] = self.linear();
        let o = self.crop_centre();
        let (u, v) = (p.x - o, p.y - o);
        Point::new(self.centre.x + a * u + b * v, self.centre.y + c * u + d * v)
    }

    /// The crop point that shows an image point.
    pub fn from_image(&self, q: Point) -> Point {
        let [a, b, c, d] = self.linear();
        let det = a * d - b * c;
        let (x, y) = (q.x - self.centre.x, q.y - self.centre.y);
        let o = self.crop_centre();
        Point::new(o + (d * x - b * y) / det, o + (-c * x + a * y) / det)
    }

    /// The image-axis-aligned box holding every pixel the crop shows.
    pub(crate) fn footprint(&self) -> Rect {
        let n = self.size as f64 - 1.0;
        let corners =
            [(0.0, 0.0), (n, 0.0), (0.0, n), (n, n)].map(|(u, v)| self.to_image(Point::new(u, v)));
        let fold = |f: fn(f64, f64) -> f64, init: f64, pick: fn(&Point) -> f64| {
            corners.iter().map(pick).fold(init, f)
        };
        let (x0, x1) = (
            fold(f64::min, f64::INFINITY, |p| p.x),
            fold(f64::max, f64::NEG_INFINITY, |p| p.x),
        );
        let (y0, y1) = (
            fold(f64::min, f64::INFINITY, |p| p.y),
            fold(f64::max, f64::NEG_INFINITY, |p| p.y),
        );
        Rect::new(x0, y0, x1 - x0, y1 - y0)
    }

    /// Whether every number of the frame is finite and its scale positive (a frame built from a
    /// degenerate box or a runaway estimate is not rendered).
    pub(crate) fn is_valid(&self) -> bool {
        [self.centre.x, self.centre.y, self.scale, self.k, self.roll]
            .iter()
            .all(|v| v.is_finite())
            && self.scale > 0.0
            && self.size > 0
    }

    /// Renders the crop from `gray`: grey levels 0-255 as `f32`, row-major, `size * size`.
    ///
    /// Each crop pixel is the mean of `m x m` bilinear reads spread over it (`m` the scale
    /// rounded up, at most `MAX_SUPERSAMPLING`), so the anti-aliasing blur is a box of one crop
    /// pixel in the crop's own frame: the same for a sheared face as for an upright one. (A
    /// blur in the image's axes, such as resampling the image first and reading it along the
    /// sheared rows, is itself sheared in the crop's frame, and a network trained on upright
    /// photos learns that slant as part of the face's shear: with such crops the estimate
    /// followed a synthetic shear about 1.5% short.) Faces larger than `MAX_SUPERSAMPLING`
    /// image pixels per crop pixel are first reduced by a whole factor (a blur in the image's
    /// axes, but of at most about a fifth of a crop pixel). Outside the image the
    /// edge is replicated. `None` for an invalid frame or a footprint too large to be a face
    /// (more than 16 times the image's size in either direction).
    pub fn render(&self, gray: &GrayImage) -> Option<Vec<f32>> {
        self.render_with(gray, MAX_SUPERSAMPLING)
    }

    /// [`Self::render`] with at most `max_supersampling` reads per crop pixel and axis instead
    /// of [`MAX_SUPERSAMPLING`] (at least 1): faster for large faces, whose image is then
    /// reduced by a larger whole factor first, a blur in the image's axes of up to about
    /// `1 / max_supersampling` of a crop pixel.
    pub(crate) fn render_with(
        &self,
        gray: &GrayImage,
        max_supersampling: usize,
    ) -> Option<Vec<f32>> {
        let Sampling {
            source,
            width: sw,
            height: sh,
            origin: (x0, y0),
            block,
            reads: m,
            steps: [ax, ay, bx, by],
        } = self.sampling(gray, max_supersampling)?;
        let inv = 1.0 / (m * m) as f32;
        let offsets: Vec<f64> = (0..m).map(|i| (i as f64 + 0.5) / m as f64 - 0.5).collect();
        let row_start = |j: usize| {
            let first = self.to_image(Point::new(0.0, j as f64));
            ((first.x - x0) / block, (first.y - y0) / block)
        };
        // The source holds the footprint with a margin of two samples, so every read of a
        // valid frame lies inside it and the reads need no clamping; checked on the corner
        // reads (the read points are affine in the crop pixel and the offsets), with a margin
        // for rounding. The clamped read stays for anything else.
        let n = self.size - 1;
        let (lo, hi) = (offsets[0], offsets[m - 1]);
        let inside = [0, n].iter().all(|&j| {
            let (sx, sy) = row_start(j);
            [0, n].iter().all(|&i| {
                let (px, py) = (sx + ax * i as f64, sy + ay * i as f64);
                [lo, hi].iter().all(|&v| {
                    [lo, hi].iter().all(|&u| {
                        let (x, y) = (px + ax * u + bx * v, py + ay * u + by * v);
                        x >= 1e-3 && y >= 1e-3 && x <= sw as f64 - 1.001 && y <= sh as f64 - 1.001
                    })
                })
            })
        });
        let mut out = vec![0f32; self.size * self.size];
        if inside {
            supersample_inside(
                &mut out,
                self.size,
                &offsets,
                [ax, ay, bx, by],
                row_start,
                (&source, sw),
            );
        } else {
            supersample(
                &mut out,
                self.size,
                &offsets,
                [ax, ay, bx, by],
                row_start,
                |x, y| bilinear_clamped(&source, sw, sh, x, y),
            );
        }
        out.iter_mut().for_each(|o| *o *= inv);
        Some(out)
    }

    /// What [`Self::render_with`] reads: the footprint resampled at one sample per `block`
    /// image pixels, with a margin of two samples, and how the crop's pixels step through it.
    /// `None` for a frame that is not rendered.
    fn sampling(&self, gray: &GrayImage, max_supersampling: usize) -> Option<Sampling> {
        let max_supersampling = max_supersampling.max(1);
        if !self.is_valid() || gray.width() == 0 || gray.height() == 0 {
            return None;
        }
        let area = self.footprint();
        let (iw, ih) = (f64::from(gray.width()), f64::from(gray.height()));
        if area.width > 16.0 * iw + 16.0 * self.size as f64
            || area.height > 16.0 * ih + 16.0 * self.size as f64
        {
            return None;
        }
        // Image pixels reduced into one source sample before supersampling (1: none).
        let block = (self.scale / max_supersampling as f64).ceil().max(1.0);
        // Source sample 0 sits on a whole image pixel, so that with `block` 1 the source is
        // the image's own pixels, not an interpolation of them.
        let (x0, y0) = (
            (area.x / block).floor() * block - 2.0 * block,
            (area.y / block).floor() * block - 2.0 * block,
        );
        let width = ((area.width + 4.0 * block) / block).ceil() as usize + 1;
        let height = ((area.height + 4.0 * block) / block).ceil() as usize + 1;
        // The footprint at one sample per `block` image pixels: reduced with `resample`'s
        // area-weighted triangle (block > 1), or the image's own pixels (block = 1).
        let source = resample(gray, x0, y0, block, width, height);
        let reads = ((self.scale / block).ceil() as usize).clamp(1, max_supersampling);
        let [a, b, c, d] = self.linear();
        Some(Sampling {
            source,
            width,
            height,
            origin: (x0, y0),
            block,
            reads,
            steps: [a / block, c / block, b / block, d / block],
        })
    }
}

/// The source raster a crop is rendered from ([`CropFrame::sampling`]).
struct Sampling {
    /// The footprint and its margin, one sample per `block` image pixels, row-major.
    source: Vec<f32>,
    /// Samples per row.
    width: usize,
    /// Rows.
    height: usize,
    /// The image point of sample `(0, 0)`.
    origin: (f64, f64),
    /// Image pixels per source sample.
    block: f64,
    /// Reads per crop pixel and axis.
    reads: usize,
    /// One crop pixel's steps along its row and its column, in source samples: `[ax, ay, bx, by]`.
    steps: [f64; 4],
}

/// Sums, into each pixel of the `size x size` crop `out`, the reads `read(x, y)` at the
/// `offsets x offsets` points spread over it: pixel `(i, j)`'s read point for offsets `(u, v)`
/// is `row_start(j) + i * (ax, ay) + u * (ax, ay) + v * (bx, by)`, in source samples.
///
/// One offset pair at a time along a whole row (the loop a compiler can keep in registers),
/// but in the same order per pixel and with the same arithmetic as summing pixel by pixel, so
/// the sums are bit-identical to that plainer loop.
fn supersample(
    out: &mut [f32],
    size: usize,
    offsets: &[f64],
    [ax, ay, bx, by]: [f64; 4],
    row_start: impl Fn(usize) -> (f64, f64),
    read: impl Fn(f64, f64) -> f32,
) {
    for (j, row) in out.chunks_exact_mut(size).enumerate() {
        let (sx, sy) = row_start(j);
        for &v in offsets {
            for &u in offsets {
                for (i, o) in row.iter_mut().enumerate() {
                    let i = i as f64;
                    let (px, py) = (sx + ax * i, sy + ay * i);
                    *o += read(px + ax * u + bx * v, py + ay * u + by * v);
                }
            }
        }
    }
}

/// [`supersample`] with bilinear reads of `source` (samples, samples per row) that need no
/// clamping, every read point known to lie inside it, in two sweeps per row and offset pair: first every
/// read point's corner sample and fractions ([`corner_and_fractions`]), arithmetic with no
/// memory reads that the compiler vectorises, then the reads themselves ([`bilinear_at`]).
/// Interleaved, the address arithmetic was most of the render's time; this is the same
/// arithmetic in the same order, so the same bits.
///
/// Compiled also for AVX2 and chosen at run time when the processor has it (the default
/// target, x86-64's baseline, has only 128-bit SSE2): the same operations per value, so the
/// same bits, in wider vectors.
#[multiversion::multiversion(targets("x86_64+avx2"))]
fn supersample_inside(
    out: &mut [f32],
    size: usize,
    offsets: &[f64],
    [ax, ay, bx, by]: [f64; 4],
    row_start: impl Fn(usize) -> (f64, f64),
    (source, width): (&[f32], usize),
) {
    let mut corner = vec![0usize; size];
    let mut fraction_x = vec![0f32; size];
    let mut fraction_y = vec![0f32; size];
    for (j, row) in out.chunks_exact_mut(size).enumerate() {
        let (sx, sy) = row_start(j);
        for &v in offsets {
            for &u in offsets {
                for (i, ((c, fx), fy)) in corner
                    .iter_mut()
                    .zip(fraction_x.iter_mut())
                    .zip(fraction_y.iter_mut())
                    .enumerate()
                {
                    // `i` through `i32`, which converts to `f64` in one instruction (a crop
                    // is far smaller than `i32::MAX`); the same value as `i as f64`.
                    let i = f64::from(i as i32);
                    let (px, py) = (sx + ax * i, sy + ay * i);
                    let (x, y) = (px + ax * u + bx * v, py + ay * u + by * v);
                    debug_assert!(x >= 0.0 && y >= 0.0 && x < width as f64, "({x}, {y})");
                    // SAFETY: the caller checked that every read point lies inside the source,
                    // so `x` and `y` are finite, non-negative and below its width and height.
                    (*c, *fx, *fy) = unsafe { corner_and_fractions(width, x, y) };
                }
                for (o, ((&c, &fx), &fy)) in row
                    .iter_mut()
                    .zip(corner.iter().zip(&fraction_x).zip(&fraction_y))
                {
                    *o += bilinear_at(source, width, c, fx, fy);
                }
            }
        }
    }
}

/// The index of the sample at the top left of `(x, y)` in a raster `width` samples wide, and
/// the point's fractions right and down of it.
///
/// # Safety
/// `x` and `y` must be finite, non-negative and below `i32::MAX`: they are truncated without
/// the saturating checks of `as`, which keep the loop in [`supersample_inside`] from being
/// vectorised.
#[inline(always)]
unsafe fn corner_and_fractions(width: usize, x: f64, y: f64) -> (usize, f32, f32) {
    // Non-negative, so truncation is the floor. Through `i32`: converting between `f64` and
    // `usize` takes several instructions each way on x86-64, and `i32` one.
    // SAFETY: the caller guarantees that both values fit an `i32`.
    let (xi, yi): (i32, i32) = unsafe { (x.to_int_unchecked(), y.to_int_unchecked()) };
    let (fx, fy) = ((x - f64::from(xi)) as f32, (y - f64::from(yi)) as f32);
    (yi as usize * width + xi as usize, fx, fy)
}

/// The bilinear interpolation of the four samples from `corner` (see [`corner_and_fractions`])
/// of a raster `width` samples wide, `fx` right and `fy` down.
#[inline(always)]
fn bilinear_at(src: &[f32], width: usize, corner: usize, fx: f32, fy: f32) -> f32 {
    // One slice for the four samples, so that a single bounds check covers them.
    let q = &src[corner..][..width + 2];
    let top = q[0] + (q[1] - q[0]) * fx;
    let bottom = q[width] + (q[width + 1] - q[width]) * fx;
    top + (bottom - top) * fy
}

/// [`bilinear_clamped`] for a point known to lie in `[0, w - 1) x [0, h - 1)`: the same value
/// without the clamps (what [`supersample_inside`] computes in two steps; kept as the
/// reference the tests hold it to).
#[cfg(test)]
fn bilinear_inside(src: &[f32], w: usize, x: f64, y: f64) -> f32 {
    assert!(x >= 0.0 && y >= 0.0 && x < w as f64 && y < (src.len() / w) as f64);
    // SAFETY: just asserted.
    let (corner, fx, fy) = unsafe { corner_and_fractions(w, x, y) };
    bilinear_at(src, w, corner, fx, fy)
}

/// The most reads per crop pixel and axis in [`CropFrame::render`] (25 in all for a face
/// shrunk 5 times or more).
pub(crate) const MAX_SUPERSAMPLING: usize = 5;

/// The shear seen in a crop made with `roll` from a face sheared by `residual` more than the
/// crop removes: the shear factor of the upper-triangular part of `R(-roll) S(residual)` (its
/// RQ decomposition), which is `residual` itself when `roll` is 0. This is what the network's
/// shear output is trained to read; [`residual_from_crop_shear`] inverts it.
#[cfg(any(test, feature = "dev"))]
pub(crate) fn crop_shear(residual: f64, roll: f64) -> f64 {
    let (s, c) = roll.sin_cos();
    // R(-roll) S(d) = [[c, c d + s], [-s, c - s d]]; the shear of its RQ decomposition is
    // (row1 . row2) / |row2|^2.
    let d = residual;
    let (r1, r2) = ((c, c * d + s), (-s, c - s * d));
    (r1.0 * r2.0 + r1.1 * r2.1) / (r2.0 * r2.0 + r2.1 * r2.1)
}

/// The residual shear `d` (image frame) for which [`crop_shear`]`(d, roll)` equals `kappa`, the
/// root nearest `kappa` (the branch through `d = kappa` at roll 0); `None` when there is none.
pub(crate) fn residual_from_crop_shear(kappa: f64, roll: f64) -> Option<f64> {
    if roll == 0.0 {
        return Some(kappa);
    }
    let (s, c) = roll.sin_cos();
    // kappa (s^2 + (c - s d)^2) = d (c^2 - s^2) - s c d^2, a quadratic in d:
    // d^2 (kappa s^2 + s c) + d (-2 kappa s c - (c^2 - s^2)) + kappa (s^2 + c^2) = 0.
    let qa = kappa * s * s + s * c;
    let qb = -2.0 * kappa * s * c - (c * c - s * s);
    let qc = kappa;
    if qa.abs() < 1e-12 {
        return (qb != 0.0).then(|| -qc / qb);
    }
    let disc = qb * qb - 4.0 * qa * qc;
    if disc < 0.0 {
        return None;
    }
    let q = -0.5 * (qb + qb.signum() * disc.sqrt());
    let roots = [q / qa, if q != 0.0 { qc / q } else { f64::INFINITY }];
    roots
        .into_iter()
        .filter(|r| r.is_finite())
        .min_by(|a, b| (a - kappa).abs().total_cmp(&(b - kappa).abs()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(k: f64, roll_degrees: f64, scale: f64) -> CropFrame {
        CropFrame {
            centre: Point::new(70.0, 60.0),
            scale,
            k,
            roll: roll_degrees.to_radians(),
            size: 32,
        }
    }

    #[test]
    fn image_and_crop_points_round_trip() {
        for f in [
            frame(0.0, 0.0, 1.0),
            frame(0.3, 12.0, 2.5),
            frame(-0.45, -20.0, 0.7),
        ] {
            for p in [
                Point::new(0.0, 0.0),
                Point::new(31.0, 5.5),
                Point::new(-3.0, 40.0),
            ] {
                let back = f.from_image(f.to_image(p));
                assert!(p.distance(back) < 1e-9, "{f:?} {p:?} {back:?}");
            }
            // The crop's centre shows the frame's centre.
            let c = f.crop_centre();
            assert!(f.to_image(Point::new(c, c)).distance(f.centre) < 1e-12);
        }
    }

    #[test]
    fn a_sheared_and_turned_frame_maps_rows_as_the_shear_and_roll_do() {
        // No roll: one crop row down moves the image point by (k, 1) * scale.
        let f = frame(0.25, 0.0, 2.0);
        let (a, b) = (
            f.to_image(Point::new(3.0, 4.0)),
            f.to_image(Point::new(3.0, 5.0)),
        );
        assert!((b.x - a.x - 0.5).abs() < 1e-12 && (b.y - a.y - 2.0).abs() < 1e-12);
        // No shear: a crop row is the image turned clockwise by the roll.
        let f = frame(0.0, 30.0, 1.0);
        let (a, b) = (
            f.to_image(Point::new(3.0, 4.0)),
            f.to_image(Point::new(4.0, 4.0)),
        );
        let angle = (b.y - a.y).atan2(b.x - a.x).to_degrees();
        assert!((angle - 30.0).abs() < 1e-9, "{angle}");
    }

    #[test]
    fn rendering_reads_the_image_at_the_mapped_points() {
        // A linear ramp is reproduced exactly by bilinear reads at unit scale.
        let ramp = |x: f64, y: f64| 0.5 * x + 0.25 * y;
        let img = GrayImage::from_fn(200, 200, |x, y| {
            image::Luma([ramp(f64::from(x), f64::from(y)) as u8])
        });
        let f = CropFrame {
            centre: Point::new(100.0, 90.0),
            scale: 1.0,
            k: 0.2,
            roll: 0.15,
            size: 24,
        };
        let crop = f.render(&img).expect("valid frame");
        for (n, &got) in crop.iter().enumerate() {
            let p = f.to_image(Point::new((n % 24) as f64, (n / 24) as f64));
            assert!(
                (f64::from(got) - ramp(p.x, p.y)).abs() < 1.0,
                "pixel {n}: {got} against {}",
                ramp(p.x, p.y)
            );
        }
    }

    #[test]
    fn shrinking_crops_average_instead_of_aliasing() {
        // A one-pixel checkerboard shrunk 4x comes out flat grey.
        let img = GrayImage::from_fn(256, 256, |x, y| {
            image::Luma([if (x + y) % 2 == 0 { 0 } else { 200 }])
        });
        let f = CropFrame {
            centre: Point::new(128.0, 128.0),
            scale: 4.0,
            k: 0.1,
            roll: 0.0,
            size: 16,
        };
        for v in f.render(&img).expect("valid frame") {
            assert!((v - 100.0).abs() < 10.0, "{v}");
        }
    }

    #[test]
    fn a_crop_that_removes_the_shear_shows_the_unsheared_image() {
        // A smooth pattern with detail near the crop's resolution, and the same pattern sheared
        // by k about row `pivot` (what a rolling shutter records).
        let pattern = |x: f64, y: f64| {
            100.0 + 50.0 * (x / 3.1).sin() * (y / 4.3).cos() + 40.0 * ((x + 2.0 * y) / 7.0).sin()
        };
        let (k, pivot) = (0.4, 150.0);
        let image = |shear: f64| {
            GrayImage::from_fn(400, 300, |x, y| {
                let (x, y) = (f64::from(x), f64::from(y));
                image::Luma([pattern(x - shear * (y - pivot), y).round() as u8])
            })
        };
        let (upright, sheared) = (image(0.0), image(k));
        let at = Point::new(200.0, 130.0);
        let plain = CropFrame {
            centre: at,
            scale: 2.5,
            k: 0.0,
            roll: 0.0,
            size: 48,
        };
        let unsheared = CropFrame {
            centre: Point::new(at.x + k * (at.y - pivot), at.y),
            k,
            ..plain
        };
        let a = plain.render(&upright).expect("valid frame");
        let b = unsheared.render(&sheared).expect("valid frame");
        let mean_difference =
            a.iter().zip(&b).map(|(p, q)| (p - q).abs()).sum::<f32>() / a.len() as f32;
        // Measured: 0.16 grey levels (the source rounded to whole levels, bilinear reads on
        // different image pixels). A crop that did not remove the shear differs by tens of
        // levels on this pattern, whose contrast over one crop pixel is about 40.
        assert!(mean_difference < 0.5, "mean difference {mean_difference}");
    }

    #[test]
    fn fewer_reads_per_pixel_blur_a_large_face_a_little_more() {
        // A fine checkerboard (2 px squares) shrunk 6 times: averaged away to mid-grey with
        // either budget, since both reduce by whole blocks and average within the crop pixel.
        let img = GrayImage::from_fn(600, 600, |x, y| {
            image::Luma([if (x / 2 + y / 2) % 2 == 0 { 0 } else { 255 }])
        });
        let f = CropFrame {
            centre: Point::new(300.0, 300.0),
            scale: 6.0,
            k: 0.2,
            roll: 0.0,
            size: 32,
        };
        let full = f.render(&img).expect("valid frame");
        assert_eq!(f.render_with(&img, MAX_SUPERSAMPLING), Some(full.clone()));
        let fast = f.render_with(&img, 2).expect("valid frame");
        assert_ne!(fast, full, "a different sampling");
        for v in full.iter().chain(&fast) {
            assert!((v - 127.5).abs() < 20.0, "aliasing: {v}");
        }
        // Zero reads is taken as one.
        assert_eq!(f.render_with(&img, 0), f.render_with(&img, 1));
    }

    /// The renderer as first written: pixel by pixel, every read clamped.
    fn render_pixel_by_pixel(
        f: &CropFrame,
        gray: &GrayImage,
        max_supersampling: usize,
    ) -> Vec<f32> {
        let s = f.sampling(gray, max_supersampling).expect("valid frame");
        let (source, sw, sh, m) = (&s.source, s.width, s.height, s.reads);
        let ((x0, y0), block, [ax, ay, bx, by]) = (s.origin, s.block, s.steps);
        let offsets: Vec<f64> = (0..m).map(|i| (i as f64 + 0.5) / m as f64 - 0.5).collect();
        let mut out = vec![0f32; f.size * f.size];
        for (j, row) in out.chunks_exact_mut(f.size).enumerate() {
            let first = f.to_image(Point::new(0.0, j as f64));
            let (sx, sy) = ((first.x - x0) / block, (first.y - y0) / block);
            for (i, o) in row.iter_mut().enumerate() {
                let (px, py) = (sx + ax * i as f64, sy + ay * i as f64);
                let mut total = 0.0f32;
                for &v in &offsets {
                    for &u in &offsets {
                        let (x, y) = (px + ax * u + bx * v, py + ay * u + by * v);
                        total += bilinear_clamped(source, sw, sh, x, y);
                    }
                }
                *o = total * (1.0 / (m * m) as f32);
            }
        }
        out
    }

    #[test]
    fn rendering_row_by_row_gives_the_same_bits_as_pixel_by_pixel() {
        // A textured image, and frames inside it, across its edges and past its corner, at
        // every supersampling from 1 to 5 reads per axis and with the image first reduced.
        let img = GrayImage::from_fn(240, 180, |x, y| {
            image::Luma([(((x * 7 + y * 13) % 251) ^ ((x * y) % 17)) as u8])
        });
        let mut frames = 0;
        for (cx, cy) in [(120.0, 90.0), (3.5, 170.2), (250.0, -20.0)] {
            for scale in [0.8, 1.0, 1.7, 2.06, 3.44, 4.9, 7.3] {
                for (k, roll) in [(0.0, 0.0), (0.4, 0.0), (-0.33, 0.3), (0.14, -0.7)] {
                    let f = CropFrame {
                        centre: Point::new(cx, cy),
                        scale,
                        k,
                        roll,
                        size: 24,
                    };
                    for budget in [5, 2] {
                        let fast = f.render_with(&img, budget).expect("valid frame");
                        let plain = render_pixel_by_pixel(&f, &img, budget);
                        let same = crate::testing::same_bits(&fast, &plain);
                        assert!(same, "{f:?} with {budget} reads per axis");
                        frames += 1;
                    }
                }
            }
        }
        assert_eq!(frames, 168);
    }

    #[test]
    fn the_unclamped_read_equals_the_clamped_one_inside() {
        let (w, h) = (9, 7);
        let src: Vec<f32> = (0..w * h).map(|i| ((i * 37) % 23) as f32 * 1.5).collect();
        for (x, y) in [
            (0.0, 0.0),
            (7.999, 5.999),
            (3.25, 2.5),
            (0.001, 4.0),
            (6.5, 0.75),
        ] {
            assert_eq!(
                bilinear_inside(&src, w, x, y).to_bits(),
                bilinear_clamped(&src, w, h, x, y).to_bits(),
                "({x}, {y})"
            );
        }
    }

    #[test]
    fn degenerate_frames_are_not_rendered() {
        let img = GrayImage::new(10, 10);
        let mut f = frame(0.0, 0.0, 1.0);
        f.scale = f64::NAN;
        assert!(f.render(&img).is_none());
        f.scale = 0.0;
        assert!(f.render(&img).is_none());
        f.scale = 1e6;
        assert!(f.render(&img).is_none());
    }

    #[test]
    fn crop_shear_is_the_residual_without_roll_and_inverts_with_it() {
        for d in [-0.5, -0.2, 0.0, 0.1, 0.4] {
            assert!((crop_shear(d, 0.0) - d).abs() < 1e-12);
            for roll in [-0.4f64, -0.1, 0.2, 0.35] {
                let kappa = crop_shear(d, roll);
                let back = residual_from_crop_shear(kappa, roll).expect("invertible");
                assert!((back - d).abs() < 1e-9, "d {d} roll {roll}: {back}");
            }
        }
        // The crop's shear of a turned, sheared face is what the crop frame shows: the eye
        // line stays level under a pure shear, so with roll it is the RQ shear factor.
        let (d, roll) = (0.3f64, 0.2f64);
        let kappa = crop_shear(d, roll);
        assert!(kappa > 0.2 && kappa < 0.4, "{kappa}");
    }
}

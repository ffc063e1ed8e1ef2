//! Rotated views of a greyscale image, for looking for rolled faces.
//!
//! The Viola-Jones cascade finds upright faces only (it tolerates about 10-15 degrees of roll),
//! so a face whose head is tilted further is searched for in the image rotated the other way.
//! This is a detection aid, not a correction: the estimate is always made in the input's own
//! pixels. Hand-written (a short bilinear loop) because `image::imageops` rotates by multiples
//! of 90 degrees only.

use image::GrayImage;
use rayon::prelude::*;

use crate::{Error, Point, Result};

/// How a rotated view relates to its input: a view point `v` shows the input point
/// `c_in + R(-angle) (v - c_view)`, where `R(a)` turns by `a` (x right, y down: positive angles
/// turn clockwise on screen).
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub struct Rotation {
    /// The angle the input was turned by to make the view, radians.
    pub(crate) angle: f64,
    /// The input point at the centre of the rotation.
    pub(crate) input_centre: Point,
    /// Where that point lies in the view.
    pub(crate) view_centre: Point,
}

impl Rotation {
    /// The view point showing input point `p`.
    pub fn to_view(&self, p: Point) -> Point {
        let (s, c) = self.angle.sin_cos();
        let (dx, dy) = (p.x - self.input_centre.x, p.y - self.input_centre.y);
        Point::new(
            self.view_centre.x + c * dx - s * dy,
            self.view_centre.y + s * dx + c * dy,
        )
    }

    /// The input point shown at view point `v`.
    pub fn to_input(&self, v: Point) -> Point {
        let (s, c) = self.angle.sin_cos();
        let (dx, dy) = (v.x - self.view_centre.x, v.y - self.view_centre.y);
        Point::new(
            self.input_centre.x + c * dx + s * dy,
            self.input_centre.y - s * dx + c * dy,
        )
    }
}

/// The whole of `gray` turned by `angle` radians about its centre, on a canvas just large enough
/// to hold it (bilinear; pixels from outside the input are 0), and the [`Rotation`] that maps
/// points between the two.
///
/// # Errors
/// [`Error::InvalidArgument`] when the angle is not finite or the canvas would exceed
/// `super::MAX_OUTPUT_PIXELS`.
pub fn rotate_gray(gray: &GrayImage, angle: f64) -> Result<(GrayImage, Rotation)> {
    if !angle.is_finite() {
        return Err(Error::InvalidArgument(format!(
            "rotation {angle} is not finite"
        )));
    }
    let (w, h) = (f64::from(gray.width()), f64::from(gray.height()));
    let (s, c) = angle.sin_cos();
    // The rounding guard keeps exact quarter turns from gaining a column to cos(pi/2) ~ 6e-17.
    let out_w = (w * c.abs() + h * s.abs() - 1e-9).ceil().max(1.0);
    let out_h = (w * s.abs() + h * c.abs() - 1e-9).ceil().max(1.0);
    if out_w * out_h > super::MAX_OUTPUT_PIXELS as f64 {
        return Err(Error::InvalidArgument(format!(
            "a {out_w}x{out_h} rotated canvas is too large"
        )));
    }
    let rotation = Rotation {
        angle,
        input_centre: Point::new((w - 1.0) / 2.0, (h - 1.0) / 2.0),
        view_centre: Point::new((out_w - 1.0) / 2.0, (out_h - 1.0) / 2.0),
    };
    let (out_w, out_h) = (out_w as u32, out_h as u32);
    let (iw, ih) = (gray.width() as usize, gray.height() as usize);
    let src = gray.as_raw();
    let mut out = vec![0u8; out_w as usize * out_h as usize];
    out.par_chunks_exact_mut(out_w as usize)
        .enumerate()
        .for_each(|(y, row)| {
            // Along a view row the input point moves by (cos, -sin) per pixel.
            let start = rotation.to_input(Point::new(0.0, y as f64));
            for (x, o) in row.iter_mut().enumerate() {
                let px = start.x + c * x as f64;
                let py = start.y - s * x as f64;
                *o = bilinear(src, iw, ih, px, py);
            }
        });
    let view = GrayImage::from_raw(out_w, out_h, out)
        .ok_or_else(|| Error::InvalidArgument("rotated canvas size mismatch".into()))?;
    Ok((view, rotation))
}

/// Bilinear sample of a `w x h` grey raster at `(x, y)`; 0 outside, fading over the last pixel.
fn bilinear(src: &[u8], w: usize, h: usize, x: f64, y: f64) -> u8 {
    if !(x > -1.0 && y > -1.0 && x < w as f64 && y < h as f64) {
        return 0;
    }
    let (x0, y0) = (floor(x), floor(y));
    let (fx, fy) = (x - x0, y - y0);
    let at = |xi: f64, yi: f64| -> f64 {
        if xi < 0.0 || yi < 0.0 || xi >= w as f64 || yi >= h as f64 {
            0.0
        } else {
            f64::from(src[yi as usize * w + xi as usize])
        }
    };
    let top = at(x0, y0) * (1.0 - fx) + at(x0 + 1.0, y0) * fx;
    let bottom = at(x0, y0 + 1.0) * (1.0 - fx) + at(x0 + 1.0, y0 + 1.0) * fx;
    // A blend of grey levels with weights in [0, 1]: never negative.
    round_non_negative(top * (1.0 - fy) + bottom * fy).min(255.0) as u8
}

/// `v.floor()` for `|v| < 2^52`. `f64::floor` and `f64::round` are calls into libm on the
/// baseline x86-64 target (no rounding instruction), and three per pixel were a fifth of the
/// rotation's time; truncation is one instruction.
fn floor(v: f64) -> f64 {
    let t = v as i64 as f64;
    if t > v {
        t - 1.0
    } else {
        t
    }
}

/// `v.round()` (halves away from zero) for `0 <= v < 2^52`: `v - trunc(v)` is exact there.
fn round_non_negative(v: f64) -> f64 {
    let t = v as i64 as f64;
    if v - t >= 0.5 {
        t + 1.0
    } else {
        t
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floor_and_round_match_the_standard_library() {
        let cases = [
            -0.999_999,
            -0.5,
            -0.0,
            0.0,
            0.25,
            0.5,
            0.499_999_999_999_999_94,
            1.0,
            1.5,
            2.5,
            254.5,
            254.499_999_999,
            255.0,
            1_919.999_999_999_9,
            4.0e15,
        ];
        for v in cases {
            assert_eq!(floor(v), v.floor(), "floor {v}");
            if v >= 0.0 {
                assert_eq!(round_non_negative(v), v.round(), "round {v}");
            }
        }
        let mut x = 0.123_f64;
        for _ in 0..10_000 {
            x = (x * 7.31 + 0.137) % 300.0 - 1.0;
            assert_eq!(floor(x), x.floor(), "floor {x}");
            let v = x.abs();
            assert_eq!(round_non_negative(v), v.round(), "round {v}");
        }
    }

    #[test]
    fn points_round_trip_and_the_centre_stays() {
        let img = GrayImage::new(40, 30);
        let (view, r) = rotate_gray(&img, 0.3).unwrap();
        let p = Point::new(7.5, 21.25);
        let q = r.to_input(r.to_view(p));
        assert!(p.distance(q) < 1e-9);
        let c = r.to_view(r.input_centre);
        assert!(c.distance(r.view_centre) < 1e-9);
        // The canvas holds the whole turned image: every input corner lands inside it.
        for (x, y) in [(0.0, 0.0), (39.0, 0.0), (0.0, 29.0), (39.0, 29.0)] {
            let v = r.to_view(Point::new(x, y));
            assert!(v.x >= -0.5 && v.y >= -0.5, "{v:?}");
            assert!(v.x <= f64::from(view.width()) - 0.5, "{v:?}");
            assert!(v.y <= f64::from(view.height()) - 0.5, "{v:?}");
        }
    }

    #[test]
    fn zero_angle_is_the_identity() {
        let img = GrayImage::from_fn(13, 9, |x, y| image::Luma([(x * 17 + y * 5) as u8]));
        let (view, _) = rotate_gray(&img, 0.0).unwrap();
        assert_eq!(view.dimensions(), img.dimensions());
        assert_eq!(view.as_raw(), img.as_raw());
    }

    #[test]
    fn a_bright_dot_moves_where_to_view_says() {
        // A 3x3 bright square; after turning by 25 degrees the view's brightest pixel is within
        // a pixel of where `to_view` puts the square's centre.
        let img = GrayImage::from_fn(60, 50, |x, y| {
            image::Luma([if (14..=16).contains(&x) && (9..=11).contains(&y) {
                255
            } else {
                0
            }])
        });
        let (view, r) = rotate_gray(&img, 25f64.to_radians()).unwrap();
        let expected = r.to_view(Point::new(15.0, 10.0));
        let (mut best, mut at) = (0u8, (0u32, 0u32));
        for (x, y, p) in view.enumerate_pixels() {
            if p[0] > best {
                (best, at) = (p[0], (x, y));
            }
        }
        assert_eq!(best, 255);
        let found = Point::new(f64::from(at.0), f64::from(at.1));
        assert!(found.distance(expected) <= 1.0, "{found:?} vs {expected:?}");
    }

    #[test]
    fn a_quarter_turn_moves_the_top_row_to_the_right_column() {
        // Positive angles turn clockwise on screen (y down): the top row becomes the right
        // column, read top to bottom.
        let img = GrayImage::from_fn(5, 3, |x, y| {
            image::Luma([if y == 0 { 10 + x as u8 } else { 0 }])
        });
        let (view, _) = rotate_gray(&img, std::f64::consts::FRAC_PI_2).unwrap();
        assert_eq!(view.dimensions(), (3, 5));
        for y in 0..5 {
            assert_eq!(view.get_pixel(2, y)[0], 10 + y as u8);
        }
    }

    #[test]
    fn non_finite_angles_are_refused() {
        let img = GrayImage::new(4, 4);
        assert!(rotate_gray(&img, f64::NAN).is_err());
        assert!(rotate_gray(&img, f64::INFINITY).is_err());
    }
}

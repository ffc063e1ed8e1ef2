//! A picture that shows what was detected: face boxes, eyes, nostrils and the estimated vertical
//! axis of each face, drawn over an RGB copy of the image, and the scene's segments that voted
//! for its shear.
//!
//! The three drawing primitives (thick line, filled disc, rectangle outline) are written here
//! rather than taken from `imageproc`: that crate would pull a large dependency tree (and its own
//! `image` version constraints) into the library for a few dozen lines of code. All of them clip
//! to the image, so marks partly or entirely outside it (or with non-finite coordinates) are
//! simply cut off, never a panic.

use crate::{Point, Rect, SceneShear};
use image::{DynamicImage, Rgb, RgbImage};

/// Everything drawn for one face.
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub struct FaceMarks {
    /// The detected face box.
    pub face_box: Rect,
    /// The subject's right eye (on the left of the picture).
    pub right_eye: Point,
    /// The subject's left eye.
    pub left_eye: Point,
    /// The subject's right nostril.
    pub right_nostril: Point,
    /// The subject's left nostril.
    pub left_nostril: Point,
    /// The mouth centre, when located.
    pub mouth: Option<Point>,
    /// The estimated shear, if any; it sets the direction of the drawn face axis.
    pub k: Option<f64>,
}

/// Colour of the face box (sky blue).
pub(crate) const BOX_COLOR: Rgb<u8> = Rgb([0, 170, 255]);
/// Colour of the eye marks (green).
pub(crate) const EYE_COLOR: Rgb<u8> = Rgb([0, 230, 0]);
/// Colour of the nostril marks (orange).
pub(crate) const NOSTRIL_COLOR: Rgb<u8> = Rgb([255, 120, 0]);
/// Colour of the mouth mark (violet).
pub(crate) const MOUTH_COLOR: Rgb<u8> = Rgb([170, 80, 255]);
/// Colour of the eye-to-nostril lines (yellow).
pub(crate) const LINK_COLOR: Rgb<u8> = Rgb([255, 230, 0]);
/// Colour of the face's vertical axis under the estimated shear (magenta).
pub(crate) const AXIS_COLOR: Rgb<u8> = Rgb([255, 0, 200]);
/// Colour of the scene's segments that voted for the shear (cyan).
pub(crate) const SCENE_COLOR: Rgb<u8> = Rgb([0, 255, 255]);
/// Outline drawn around each point so it stays visible on any background (black).
const OUTLINE_COLOR: Rgb<u8> = Rgb([0, 0, 0]);

/// Line width in pixels for an image: about 1/400 of its smaller side, at least 1, so marks stay
/// visible on 50-megapixel photos without swamping small frames.
pub(crate) fn line_width(width: u32, height: u32) -> f64 {
    (f64::from(width.min(height)) / 400.0).round().max(1.0)
}

/// An RGB copy of `img` with, per face: the box, the two eyes (green) and nostrils (orange) as
/// discs with a black outline, the mouth (violet) when located, the eye→nostril lines on each side (yellow), and — when `k` is
/// known — the face's vertical axis under the estimated shear (magenta): the line through the
/// midpoint of the eyes in direction `(k, 1)`, spanning the box's rows.
pub fn draw_annotations(img: &DynamicImage, faces: &[FaceMarks]) -> RgbImage {
    let mut out = img.to_rgb8();
    let lw = line_width(out.width(), out.height());
    let radius = 2.5 * lw + 1.0;
    for face in faces {
        draw_rect_outline(&mut out, face.face_box, lw, BOX_COLOR);
        draw_line(&mut out, face.right_eye, face.right_nostril, lw, LINK_COLOR);
        draw_line(&mut out, face.left_eye, face.left_nostril, lw, LINK_COLOR);
        if let Some(k) = face.k {
            let mid = face.right_eye.midpoint(face.left_eye);
            let b = face.face_box;
            let at = |y: f64| Point::new(mid.x + k * (y - mid.y), y);
            draw_line(&mut out, at(b.y), at(b.y + b.height), lw, AXIS_COLOR);
        }
        for (p, color) in [
            (face.right_eye, EYE_COLOR),
            (face.left_eye, EYE_COLOR),
            (face.right_nostril, NOSTRIL_COLOR),
            (face.left_nostril, NOSTRIL_COLOR),
        ]
        .into_iter()
        .chain(face.mouth.map(|m| (m, MOUTH_COLOR)))
        {
            draw_disc(&mut out, p, radius + lw, OUTLINE_COLOR);
            draw_disc(&mut out, p, radius, color);
        }
    }
    out
}

/// Draws the scene's segments that voted for its shear ([`SceneShear::voters`]) over
/// `picture` (cyan, the line width of [`draw_annotations`]), clipped like the face marks.
pub fn draw_scene_segments(picture: &mut RgbImage, scene: &SceneShear) {
    let lw = line_width(picture.width(), picture.height());
    for s in &scene.voters {
        draw_line(picture, s.from, s.to, lw, SCENE_COLOR);
    }
}

/// The pixel index range `[lo, hi)` of the interval `[a, b]` clipped to `0..len`, or `None` when
/// it misses (also for NaN).
fn clip_range(a: f64, b: f64, len: u32) -> Option<(u32, u32)> {
    let lo = a.ceil().max(0.0);
    let hi = (b.floor() + 1.0).min(f64::from(len));
    // NaN compares false, so non-finite input falls out here.
    if lo < hi {
        Some((lo as u32, hi as u32))
    } else {
        None
    }
}

/// Fill the disc of `radius` around `c`, clipped.
fn draw_disc(img: &mut RgbImage, c: Point, radius: f64, color: Rgb<u8>) {
    let (w, h) = img.dimensions();
    let Some((x0, x1)) = clip_range(c.x - radius, c.x + radius, w) else {
        return;
    };
    let Some((y0, y1)) = clip_range(c.y - radius, c.y + radius, h) else {
        return;
    };
    let r2 = radius * radius;
    for y in y0..y1 {
        for x in x0..x1 {
            let (dx, dy) = (f64::from(x) - c.x, f64::from(y) - c.y);
            if dx * dx + dy * dy <= r2 {
                img.put_pixel(x, y, color);
            }
        }
    }
}

/// A segment of the given width (pixels within `width / 2` of it, square-ish caps from the
/// distance test), clipped. The segment is first clipped to the image (grown by the half-width)
/// so a line with far-away end points only costs the pixels it actually covers.
fn draw_line(img: &mut RgbImage, a: Point, b: Point, width: f64, color: Rgb<u8>) {
    let (w, h) = img.dimensions();
    let half = width / 2.0;
    let bounds = Rect::new(
        -half - 1.0,
        -half - 1.0,
        f64::from(w) + width + 2.0,
        f64::from(h) + width + 2.0,
    );
    let Some((a, b)) = clip_segment(a, b, bounds) else {
        return;
    };
    let Some((x0, x1)) = clip_range(a.x.min(b.x) - half, a.x.max(b.x) + half, w) else {
        return;
    };
    let Some((y0, y1)) = clip_range(a.y.min(b.y) - half, a.y.max(b.y) + half, h) else {
        return;
    };
    let (dx, dy) = (b.x - a.x, b.y - a.y);
    let len2 = dx * dx + dy * dy;
    let half2 = half.max(0.5) * half.max(0.5);
    for y in y0..y1 {
        for x in x0..x1 {
            let (px, py) = (f64::from(x) - a.x, f64::from(y) - a.y);
            let t = if len2 > 0.0 {
                ((px * dx + py * dy) / len2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let (ex, ey) = (px - t * dx, py - t * dy);
            if ex * ex + ey * ey <= half2 {
                img.put_pixel(x, y, color);
            }
        }
    }
}

/// Liang-Barsky clipping of segment `a`-`b` to `r`; `None` if it misses (or is not finite).
fn clip_segment(a: Point, b: Point, r: Rect) -> Option<(Point, Point)> {
    if ![a.x, a.y, b.x, b.y].iter().all(|v| v.is_finite()) {
        return None;
    }
    let (dx, dy) = (b.x - a.x, b.y - a.y);
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for (p, q) in [
        (-dx, a.x - r.x),
        (dx, r.x + r.width - a.x),
        (-dy, a.y - r.y),
        (dy, r.y + r.height - a.y),
    ] {
        if p == 0.0 {
            if q < 0.0 {
                return None;
            }
        } else {
            let t = q / p;
            if p < 0.0 {
                t0 = t0.max(t);
            } else {
                t1 = t1.min(t);
            }
        }
    }
    (t0 <= t1).then(|| {
        (
            Point::new(a.x + t0 * dx, a.y + t0 * dy),
            Point::new(a.x + t1 * dx, a.y + t1 * dy),
        )
    })
}

/// The outline of `r`, `width` pixels thick, centred on the box edges, clipped.
fn draw_rect_outline(img: &mut RgbImage, r: Rect, width: f64, color: Rgb<u8>) {
    let (x0, y0, x1, y1) = (r.x, r.y, r.x + r.width, r.y + r.height);
    for (a, b) in [
        ((x0, y0), (x1, y0)),
        ((x1, y0), (x1, y1)),
        ((x1, y1), (x0, y1)),
        ((x0, y1), (x0, y0)),
    ] {
        draw_line(
            img,
            Point::new(a.0, a.1),
            Point::new(b.0, b.1),
            width,
            color,
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::{GrayImage, Luma, Rgba, RgbaImage};

    fn marks() -> FaceMarks {
        FaceMarks {
            face_box: Rect::new(100.0, 80.0, 200.0, 240.0),
            right_eye: Point::new(160.0, 160.0),
            left_eye: Point::new(240.0, 160.0),
            right_nostril: Point::new(185.0, 240.0),
            left_nostril: Point::new(215.0, 240.0),
            mouth: Some(Point::new(212.0, 290.0)),
            k: Some(0.2),
        }
    }

    #[test]
    fn marks_land_on_the_expected_pixels() {
        let img = DynamicImage::ImageLuma8(GrayImage::from_pixel(400, 400, Luma([128])));
        let out = draw_annotations(&img, &[marks()]);
        assert_eq!(out.dimensions(), (400, 400));
        let grey = Rgb([128, 128, 128]);
        // Box edges (line width 1 at this size).
        assert_eq!(*out.get_pixel(150, 80), BOX_COLOR);
        assert_eq!(*out.get_pixel(100, 200), BOX_COLOR);
        assert_eq!(*out.get_pixel(300, 300), BOX_COLOR);
        // Points.
        assert_eq!(*out.get_pixel(160, 160), EYE_COLOR);
        assert_eq!(*out.get_pixel(240, 160), EYE_COLOR);
        assert_eq!(*out.get_pixel(185, 240), NOSTRIL_COLOR);
        assert_eq!(*out.get_pixel(215, 240), NOSTRIL_COLOR);
        assert_eq!(*out.get_pixel(212, 290), MOUTH_COLOR);
        // Eye-nostril link, halfway (172.5, 200) -> pixel (172 or 173, 200).
        assert!([172, 173]
            .iter()
            .any(|&x| *out.get_pixel(x, 200) == LINK_COLOR));
        // Axis through (200, 160) in direction (0.2, 1): at y = 300 it is at x = 228.
        assert_eq!(*out.get_pixel(228, 300), AXIS_COLOR);
        assert_eq!(*out.get_pixel(188, 100), AXIS_COLOR); // 200 + 0.2 * (100 - 160)
                                                          // Far from every mark: unchanged.
        assert_eq!(*out.get_pixel(20, 20), grey);
        assert_eq!(*out.get_pixel(380, 390), grey);
        assert_eq!(*out.get_pixel(130, 290), grey);
    }

    #[test]
    fn no_axis_without_k_and_width_scales() {
        let img = DynamicImage::ImageRgba8(RgbaImage::from_pixel(400, 400, Rgba([0, 0, 0, 0])));
        let out = draw_annotations(&img, &[FaceMarks { k: None, ..marks() }]);
        assert!(out.pixels().all(|p| *p != AXIS_COLOR));
        assert_eq!(line_width(400, 400), 1.0);
        assert_eq!(line_width(8000, 6000), 15.0);
        // Thick lines on a big image: a pixel 5 px inside the box edge is still box-coloured.
        let big = DynamicImage::ImageLuma8(GrayImage::new(4000, 4000));
        let m = FaceMarks {
            face_box: Rect::new(1000.0, 1000.0, 2000.0, 2000.0),
            ..marks()
        };
        let out = draw_annotations(&big, &[m]);
        assert_eq!(*out.get_pixel(2000, 1004), BOX_COLOR);
        assert_eq!(*out.get_pixel(2000, 1010), Rgb([0, 0, 0]));
    }

    #[test]
    fn drawing_outside_the_image_does_not_panic() {
        let img = DynamicImage::ImageLuma8(GrayImage::from_pixel(50, 40, Luma([7])));
        let far = Point::new(-1e9, 5e12);
        let faces = [
            FaceMarks {
                face_box: Rect::new(-500.0, -500.0, 100.0, 100.0),
                right_eye: far,
                left_eye: Point::new(1e6, -1e6),
                right_nostril: Point::new(f64::NAN, 3.0),
                left_nostril: Point::new(f64::INFINITY, f64::NEG_INFINITY),
                mouth: Some(Point::new(f64::NAN, f64::NAN)),
                k: Some(f64::NAN),
            },
            FaceMarks {
                face_box: Rect::new(f64::NAN, 0.0, f64::INFINITY, 1e300),
                k: Some(1e300),
                ..marks()
            },
        ];
        let out = draw_annotations(&img, &faces);
        assert_eq!(out.dimensions(), (50, 40));
        assert_eq!(*out.get_pixel(25, 20), Rgb([7, 7, 7]));
        // An empty image.
        let empty = DynamicImage::ImageLuma8(GrayImage::new(0, 0));
        assert_eq!(draw_annotations(&empty, &[marks()]).dimensions(), (0, 0));
    }

    #[test]
    fn scene_segments_are_drawn_where_they_are() {
        let scene = SceneShear {
            k: 0.1,
            uncertainty: 0.01,
            segments: 1,
            lines: 1,
            length: 0.5,
            roll_degrees: None,
            convergence: 0.0,
            voters: vec![crate::SceneSegment {
                from: Point::new(50.0, 20.0),
                to: Point::new(60.0, 120.0),
            }],
        };
        let mut out = RgbImage::from_pixel(200, 200, Rgb([9, 9, 9]));
        draw_scene_segments(&mut out, &scene);
        assert_eq!(*out.get_pixel(55, 70), SCENE_COLOR);
        assert_eq!(*out.get_pixel(150, 70), Rgb([9, 9, 9]));
    }

    #[test]
    fn segment_clipping() {
        let r = Rect::new(0.0, 0.0, 10.0, 10.0);
        let (a, b) = clip_segment(Point::new(-5.0, 5.0), Point::new(15.0, 5.0), r).unwrap();
        assert_eq!((a, b), (Point::new(0.0, 5.0), Point::new(10.0, 5.0)));
        assert!(clip_segment(Point::new(-5.0, -5.0), Point::new(-1.0, 20.0), r).is_none());
    }
}

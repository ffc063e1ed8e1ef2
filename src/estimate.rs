//! The shear estimate of the paper's equation 5: `k = x-displacement / y-difference` between an
//! eye point and the nose point below it, on each side of the face, averaged over both sides.
//!
//! A horizontal shear `x' = x + k (y - c)` moves a point by `k` pixels per row, so two points that
//! lie on one vertical line in the undistorted face end up `k * dy` apart horizontally, whatever
//! the pivot `c`. The points are taken in the input image's own pixels; a uniform rescale of the
//! image scales `dx` and `dy` alike and leaves `k` unchanged.

use crate::geometry::Point;

/// The shortest eye-to-nose height (pixels) for which a side's estimate is used: below it a
/// one-pixel error alone would move `k` by more than 0.2.
pub const MIN_VERTICAL_SPAN: f64 = 5.0;

/// `k` from one side of the face: the horizontal displacement of `lower` relative to `upper`
/// divided by their vertical difference. `None` when `lower` is not at least
/// [`MIN_VERTICAL_SPAN`] pixels below `upper`.
pub fn shear_from_pair(upper: Point, lower: Point) -> Option<f64> {
    let dy = lower.y - upper.y;
    (dy >= MIN_VERTICAL_SPAN && dy.is_finite() && (lower.x - upper.x).is_finite())
        .then(|| (lower.x - upper.x) / dy)
}

/// Equation 5 on both sides of the face, averaged: the subject's right side
/// (`right_eye` over `right_nose`) and left side. A side whose geometry is unusable
/// (see [`shear_from_pair`]) is left out; `None` when neither side is usable.
pub fn shear_from_sides(
    right_eye: Point,
    right_nose: Point,
    left_eye: Point,
    left_nose: Point,
) -> Option<f64> {
    match (
        shear_from_pair(right_eye, right_nose),
        shear_from_pair(left_eye, left_nose),
    ) {
        (Some(a), Some(b)) => Some((a + b) / 2.0),
        (Some(a), None) | (None, Some(a)) => Some(a),
        (None, None) => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Shear;

    #[test]
    fn recovers_the_shear_of_a_sheared_face() {
        let (re, rn, le, ln) = (
            Point::new(80.0, 100.0),
            Point::new(82.0, 140.0),
            Point::new(140.0, 101.0),
            Point::new(137.0, 139.0),
        );
        let k0 = shear_from_sides(re, rn, le, ln).expect("usable");
        for k in [-0.4, -0.2, 0.2, 0.4] {
            let s = Shear::new(k, 250.0);
            let est = shear_from_sides(s.apply(re), s.apply(rn), s.apply(le), s.apply(ln))
                .expect("usable");
            assert!((est - k0 - k).abs() < 1e-12, "k {k}: {est}");
        }
    }

    #[test]
    fn symmetric_offsets_cancel_and_scale_does_not_matter() {
        let pts = [
            Point::new(80.0, 100.0),
            Point::new(90.0, 140.0),
            Point::new(140.0, 100.0),
            Point::new(130.0, 140.0),
        ];
        assert!(
            shear_from_sides(pts[0], pts[1], pts[2], pts[3])
                .expect("usable")
                .abs()
                < 1e-12
        );
        let s = |p: Point| Point::new(p.x * 3.7 + 11.0, p.y * 3.7 - 5.0);
        let a = shear_from_sides(pts[0], Point::new(95.0, 140.0), pts[2], pts[3]).expect("usable");
        let b = shear_from_sides(s(pts[0]), s(Point::new(95.0, 140.0)), s(pts[2]), s(pts[3]))
            .expect("usable");
        assert!((a - b).abs() < 1e-12 && (a - 0.0625).abs() < 1e-12);
    }

    #[test]
    fn mirror_gives_minus_k() {
        let pts = [
            Point::new(80.0, 100.0),
            Point::new(92.0, 140.0),
            Point::new(140.0, 100.0),
            Point::new(149.0, 141.0),
        ];
        let k = shear_from_sides(pts[0], pts[1], pts[2], pts[3]).expect("usable");
        let m = |p: Point| Point::new(300.0 - p.x, p.y);
        // Mirroring swaps the subject's sides too.
        let km = shear_from_sides(m(pts[2]), m(pts[3]), m(pts[0]), m(pts[1])).expect("usable");
        assert!((k + km).abs() < 1e-12);
    }

    #[test]
    fn degenerate_sides_are_left_out() {
        let up = Point::new(0.0, 10.0);
        assert_eq!(shear_from_pair(up, Point::new(3.0, 12.0)), None);
        assert_eq!(shear_from_pair(up, Point::new(3.0, 5.0)), None);
        assert_eq!(shear_from_pair(up, Point::new(f64::NAN, 50.0)), None);
        let k = shear_from_sides(up, Point::new(4.0, 50.0), up, Point::new(0.0, 11.0));
        assert_eq!(k, Some(0.1));
        assert_eq!(shear_from_sides(up, up, up, up), None);
    }
}

//! The shear estimate: the paper's equation 5, and the exact shear-and-roll model this project
//! uses by default.
//!
//! **Equation 5** (`k = x-displacement / y-difference` between an eye point and the nose point
//! below it, on each side of the face, averaged): a horizontal shear `x' = x + k (y - c)` moves a
//! point by `k` pixels per row, so two points that lie on one vertical line in the undistorted
//! face end up `k * dy` apart horizontally, whatever the pivot `c`. It assumes the head is upright:
//! a head rolled by `θ` reads as a shear of about `tan θ` (web faces roll by 3.6° in the median,
//! 0.06 of apparent shear).
//!
//! **Shear and roll** (`shear_and_roll`): the face seen in the image is `S(k) R(θ)` applied to an
//! upright face, with `S(k)` the horizontal shear and `R(θ)` the head's roll. In the upright face
//! the eye line `E` (right eye to left eye) and the face's axis `V` (eye midpoint down to a point
//! on the midline: the nostrils' midpoint, the mouth) are perpendicular. `S(k)^-1 = S(-k)` maps the
//! observed vectors back to a rotated upright face, where rotation keeps them perpendicular:
//!
//! ```text
//! (Ex - k Ey)(Vx - k Vy) + Ey Vy = 0
//! <=>  Ey Vy k^2 - (Ex Vy + Ey Vx) k + (Ex Vx + Ey Vy) = 0
//! ```
//!
//! With no roll (`Ey = 0`) this is equation 5, `k = Vx / Vy`; otherwise the root that tends to it
//! is taken, and the roll is `θ = atan2(Ey, Ex - k Ey)`. Rotating by the eye-line angle first and
//! then applying equation 5 is only right without shear: the shear itself tilts the eye line
//! (by `k Ey`), which that shortcut would read as roll. On the 928 Caltech development faces with
//! eyes at least 40 px apart, the hand-annotated points give a median apparent shear of 0.080
//! with equation 5 (eye midpoint over the annotated nose), 0.059 with this model.
//!
//! **Yaw** (`yaw_corrected`): a head turned sideways moves each point by its depth times
//! `sin(yaw)`; the eyes and the mouth lie nearly in one plane, the nose stands out of it. Both axes
//! then read `k` plus a yaw term proportional to their depth, `a` for the nose and `b < a` for the
//! mouth, and the extrapolation `k_mouth + β (k_mouth - k_nose)` with `β = b / (a - b)` removes
//! it. The nose point is the lower nose as the nose filter finds it (the nostrils when it was
//! not searched). On located points a smaller `β` than the annotations' does better, because the
//! extrapolation also amplifies the nose point's own error; see `YAW_EXTRAPOLATION` for how
//! `β` was measured.
//!
//! The points are taken in the input image's own pixels; a uniform rescale of the image scales
//! every vector alike and leaves `k` and the roll unchanged.

use crate::geometry::Point;

/// The shortest eye-to-nose height (pixels) for which a side's estimate is used: below it a
/// one-pixel error alone would move `k` by more than 0.2.
pub(crate) const MIN_VERTICAL_SPAN: f64 = 5.0;

/// `k` from one side of the face: the horizontal displacement of `lower` relative to `upper`
/// divided by their vertical difference. `None` when `lower` is not at least
/// [`MIN_VERTICAL_SPAN`] pixels below `upper`.
pub(crate) fn shear_from_pair(upper: Point, lower: Point) -> Option<f64> {
    let dy = lower.y - upper.y;
    (dy >= MIN_VERTICAL_SPAN && dy.is_finite() && (lower.x - upper.x).is_finite())
        .then(|| (lower.x - upper.x) / dy)
}

/// Equation 5 on both sides of the face, averaged: the subject's right side
/// (`right_eye` over `right_nose`) and left side. A side whose geometry is unusable
/// (see [`shear_from_pair`]) is left out; `None` when neither side is usable.
pub(crate) fn shear_from_sides(
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

/// The largest roll (radians, 57°) the shear-and-roll model reports. The frontal cascade fires
/// up to about 35° of roll in the image as it is (the de-sheared views add a little); turned
/// views (`--roll-hypotheses`) find heads tilted further, whose features are then searched
/// upright, so a roll up to this is real; beyond it the points are taken to be wrong.
///
/// Past about 30° of roll with a shear, the points no longer pin down one answer: two
/// (shear, roll) pairs make the eye line and the face's axis perpendicular, and the root
/// nearest equation 5's answer (the one [`shear_and_roll`] takes) can be the wrong one (on a
/// grid of |k| <= 0.8 and rolls up to 55°, 68 of 391 posed faces, all with |roll| >= 30°).
pub(crate) const MAX_ROLL: f64 = 1.0;

/// How far the mouth's shear is extrapolated away from the nose tip's to cancel yaw:
/// `k = k_mouth + YAW_EXTRAPOLATION (k_mouth - k_nose_tip)`. On hand-annotated points 0.5 cancels
/// yaw best; located points amplify the nose point's error by the same factor, so the value is
/// chosen on located points of faces no accuracy table measures (`scripts/yaw_factor.py` on
/// the `--faces unseen` runs of the three filter types, steps of 0.1: 0.1 is best).
pub(crate) const YAW_EXTRAPOLATION: f64 = 0.1;

/// [`YAW_EXTRAPOLATION`] for the nostrils' axis, used when the nose filter's point is missing
/// (features located in a view the caller gave). The nostrils sit nearer the face's plane than
/// the nose tip and are located less surely: chosen as above, the mouth's own axis (0) is best.
pub(crate) const YAW_EXTRAPOLATION_NOSTRILS: f64 = 0.0;

/// The shear and roll of a face (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct ShearRoll {
    /// The horizontal shear `k`.
    pub(crate) k: f64,
    /// The head's roll in the de-sheared face, radians, positive when the left eye (image right)
    /// is lower than the right eye (image y grows downwards).
    pub(crate) roll: f64,
}

/// Solves `S(k) R(θ)` from the eye line `eye_line` (subject's right eye to left eye, image
/// pixels) and the face axis `axis` (eye midpoint to a point below it on the face's midline).
///
/// `None` when the axis does not point downwards by at least [`MIN_VERTICAL_SPAN`] pixels, the
/// eye line is shorter than that, a value is not finite, or the roll would exceed [`MAX_ROLL`].
/// When noise leaves the quadratic without a real root, its vertex (the `k` that comes closest to
/// making the two vectors perpendicular) is used.
pub(crate) fn shear_and_roll(eye_line: Point, axis: Point) -> Option<ShearRoll> {
    let (ex, ey, vx, vy) = (eye_line.x, eye_line.y, axis.x, axis.y);
    if ![ex, ey, vx, vy].iter().all(|v| v.is_finite())
        || vy < MIN_VERTICAL_SPAN
        || ex < MIN_VERTICAL_SPAN
    {
        return None;
    }
    let no_roll = vx / vy;
    let a = ey * vy;
    let b = -(ex * vy + ey * vx);
    let c = ex * vx + ey * vy;
    let k = if a.abs() < 1e-12 * (b.abs() + c.abs()).max(1e-300) {
        -c / b
    } else {
        let disc = b * b - 4.0 * a * c;
        if disc < 0.0 {
            -b / (2.0 * a)
        } else {
            // The numerically stable pair of roots; the one nearer the no-roll answer is the
            // branch that becomes equation 5 as the roll goes to zero.
            let q = -0.5 * (b + b.signum() * disc.sqrt());
            let (r1, r2) = (q / a, if q != 0.0 { c / q } else { f64::INFINITY });
            if (r1 - no_roll).abs() <= (r2 - no_roll).abs() {
                r1
            } else {
                r2
            }
        }
    };
    let roll = ey.atan2(ex - k * ey);
    (k.is_finite() && roll.abs() <= MAX_ROLL).then_some(ShearRoll { k, roll })
}

/// The vertical shear `c` (`y' = y + c x`, a picture read out column by column) and the head's
/// roll that a reading `(k, roll)` of [`shear_and_roll`] describes, `None` when there is none.
///
/// Through the row model an upright face sheared vertically is `S(k) R(θ)` of a slightly
/// stretched face: `V(c) R(φ) = S(k) R(θ) D` with `D` diagonal (at `φ` = 0, `k = tan θ` and
/// `c = sin θ cos θ`, so `D = diag(cos θ, 1 / cos θ)`, within faces' own variety). `D` keeps the
/// upright face's eye line and axis perpendicular, so `V(-c) S(k) R(θ)` has perpendicular
/// columns, a quadratic in `c`; `φ` is the angle of the first column, and of the two roots the
/// one with the more upright head is taken (the other turns it further, as the two rolls
/// `θ` with one `sin 2θ` do). Exact on points that fit either model; the row reading itself is
/// off by a tenth of `c` at `c` = 0.3.
pub(crate) fn vertical_from_row_reading(k: f64, roll: f64) -> Option<ShearRoll> {
    let (s, co) = roll.sin_cos();
    let (m11, m12, m21, m22) = (co + k * s, k * co - s, s, co);
    // Columns of V(-c) M: (m11, m21 - c m11) and (m12, m22 - c m12); their dot product is 0.
    let a = m11 * m12;
    let b = -(m11 * m22 + m12 * m21);
    let q = m11 * m12 + m21 * m22;
    let with_roll = |c: f64| ShearRoll {
        k: c,
        roll: (m21 - c * m11).atan2(m11),
    };
    let found = if a.abs() < 1e-12 {
        with_roll(-q / b)
    } else {
        let disc = b * b - 4.0 * a * q;
        if disc < 0.0 {
            return None;
        }
        let r = disc.sqrt();
        let [p, n] = [(-b + r) / (2.0 * a), (-b - r) / (2.0 * a)].map(with_roll);
        if p.roll.abs() <= n.roll.abs() {
            p
        } else {
            n
        }
    };
    (found.k.is_finite() && found.roll.is_finite()).then_some(found)
}

/// The yaw-corrected shear from a nose axis's and the mouth axis's estimates, extrapolating by
/// `beta` ([`YAW_EXTRAPOLATION`] for the nose tip, [`YAW_EXTRAPOLATION_NOSTRILS`] for the
/// nostrils).
pub(crate) fn yaw_corrected(k_nose: f64, k_mouth: f64, beta: f64) -> f64 {
    k_mouth + beta * (k_mouth - k_nose)
}

/// Which formula turns located points into `k` (the eval compares them).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ShearModel {
    /// The paper's equation 5: each eye point over the nose point below it, both sides averaged.
    Equation5,
    /// `shear_and_roll` on the eye line and the nose axis (eye midpoint to nostril midpoint).
    ShearRoll,
    /// `shear_and_roll` on the nose-tip axis (the nose filter's point; the nostrils' midpoint
    /// when it was not searched) and on the mouth axis, combined by `yaw_corrected` (a nose
    /// axis alone when there is no mouth point).
    #[default]
    ShearRollYaw,
}

/// The located points a shear estimate is made from, image pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct FeatureGeometry {
    /// Subject's right eye centre (image left).
    pub(crate) right_eye: Point,
    /// Subject's left eye centre (image right).
    pub(crate) left_eye: Point,
    /// Equation 5's points, subject's right side: the eye point and the nose point below it.
    pub(crate) right_pair: (Point, Point),
    /// Equation 5's points, subject's left side.
    pub(crate) left_pair: (Point, Point),
    /// The nostrils' midpoint.
    pub(crate) nose: Point,
    /// The mouth centre, if located.
    pub(crate) mouth: Option<Point>,
    /// The lower nose as the nose filter found it, if it was searched.
    pub(crate) nose_tip: Option<Point>,
}

/// A face's estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct FaceEstimate {
    /// The shear.
    pub(crate) k: f64,
    /// The roll (radians, see [`ShearRoll::roll`]) under that shear; 0 for
    /// [`ShearModel::Equation5`], which has no roll.
    pub(crate) roll: f64,
    /// The nose axis's own shear-and-roll estimate, if usable.
    pub(crate) k_nose: Option<f64>,
    /// The mouth axis's own shear-and-roll estimate, if usable.
    pub(crate) k_mouth: Option<f64>,
    /// The nose-tip axis's own shear-and-roll estimate, if usable.
    pub(crate) k_nose_tip: Option<f64>,
}

/// Estimates the shear of one face with `model`; `None` when the points do not allow it.
pub(crate) fn estimate_face(points: &FeatureGeometry, model: ShearModel) -> Option<FaceEstimate> {
    let eye_line = Point::new(
        points.left_eye.x - points.right_eye.x,
        points.left_eye.y - points.right_eye.y,
    );
    let mid = points.right_eye.midpoint(points.left_eye);
    let axis = |p: Point| Point::new(p.x - mid.x, p.y - mid.y);
    let nose = shear_and_roll(eye_line, axis(points.nose));
    let mouth = points.mouth.and_then(|m| shear_and_roll(eye_line, axis(m)));
    let nose_tip = points
        .nose_tip
        .and_then(|t| shear_and_roll(eye_line, axis(t)));
    let roll_at = |k: f64| eye_line.y.atan2(eye_line.x - k * eye_line.y);
    let (k, roll) = match model {
        ShearModel::Equation5 => (
            shear_from_sides(
                points.right_pair.0,
                points.right_pair.1,
                points.left_pair.0,
                points.left_pair.1,
            )?,
            0.0,
        ),
        ShearModel::ShearRoll => {
            let n = nose?;
            (n.k, n.roll)
        }
        ShearModel::ShearRollYaw => {
            let k = match (nose_tip, nose, mouth) {
                (Some(t), _, Some(m)) => yaw_corrected(t.k, m.k, YAW_EXTRAPOLATION),
                (None, Some(n), Some(m)) => yaw_corrected(n.k, m.k, YAW_EXTRAPOLATION_NOSTRILS),
                (_, _, Some(m)) => m.k,
                (_, Some(n), None) => n.k,
                (Some(t), None, None) => t.k,
                (None, None, None) => return None,
            };
            (k, roll_at(k))
        }
    };
    Some(FaceEstimate {
        k,
        roll,
        k_nose: nose.map(|n| n.k),
        k_mouth: mouth.map(|m| m.k),
        k_nose_tip: nose_tip.map(|t| t.k),
    })
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_vertical_shear_is_recovered_from_the_row_reading() {
        // An upright face's eyes and nose (eye distance 20, nose 12 below), under V(c) R(phi),
        // within the shears and rolls the row model has an exact reading for.
        for c in [-0.4f64, -0.3, -0.1, 0.0, 0.15, 0.3, 0.4] {
            for phi in [-0.3f64, -0.05, 0.0, 0.1, 0.3] {
                if c.abs() + phi.abs() > 0.5 {
                    continue;
                }
                let (s, co) = phi.sin_cos();
                let map = |x: f64, y: f64| {
                    let (rx, ry) = (co * x - s * y, s * x + co * y);
                    super::Point::new(rx, ry + c * rx)
                };
                let (re, le, nose) = (map(-10.0, 0.0), map(10.0, 0.0), map(0.0, 12.0));
                let mid = re.midpoint(le);
                let row = super::shear_and_roll(
                    super::Point::new(le.x - re.x, le.y - re.y),
                    super::Point::new(nose.x - mid.x, nose.y - mid.y),
                )
                .expect("a row reading");
                let v = super::vertical_from_row_reading(row.k, row.roll).expect("converts");
                assert!(
                    (v.k - c).abs() < 1e-9,
                    "c {c} phi {phi}: {v:?} from {row:?}"
                );
                assert!((v.roll - phi).abs() < 1e-9, "c {c} phi {phi}: {v:?}");
                if c != 0.0 && phi == 0.0 {
                    // The row model alone reads tan(theta), sin 2 theta = 2c: off beyond 0.01.
                    assert!((row.k - c).abs() > 0.001, "{c}: {row:?}");
                }
            }
        }
    }

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

    /// An upright face with its axis points, rolled by `roll` and sheared by `k` about `pivot`.
    fn posed(k: f64, roll: f64, pivot: f64) -> (Point, Point) {
        let (s, c) = roll.sin_cos();
        let rot = |p: Point| Point::new(c * p.x - s * p.y, s * p.x + c * p.y);
        let shear = Shear::new(k, pivot);
        let place = |p: Point| shear.apply(Point::new(200.0 + p.x, 150.0 + p.y));
        let (re, le, mouth) = (
            place(rot(Point::new(-30.0, 0.0))),
            place(rot(Point::new(30.0, 0.0))),
            place(rot(Point::new(0.0, 66.0))),
        );
        let mid = re.midpoint(le);
        (
            Point::new(le.x - re.x, le.y - re.y),
            Point::new(mouth.x - mid.x, mouth.y - mid.y),
        )
    }

    #[test]
    fn shear_and_roll_recovers_both_exactly() {
        for k in [-0.5, -0.2, 0.0, 0.14, 0.4] {
            for deg in [-25.0f64, -8.0, 0.0, 3.0, 20.0] {
                let (e, v) = posed(k, deg.to_radians(), 77.0);
                let got = shear_and_roll(e, v).expect("solvable");
                assert!((got.k - k).abs() < 1e-9, "k {k} roll {deg}: {got:?}");
                assert!(
                    (got.roll - deg.to_radians()).abs() < 1e-9,
                    "k {k} roll {deg}: {got:?}"
                );
            }
        }
    }

    #[test]
    fn without_roll_it_is_equation_five() {
        let got = shear_and_roll(Point::new(60.0, 0.0), Point::new(13.0, 52.0)).expect("usable");
        assert!((got.k - 0.25).abs() < 1e-12 && got.roll.abs() < 1e-12);
    }

    #[test]
    fn naive_rotation_first_is_biased_and_the_model_is_not() {
        // k = -0.4 with a 10 degree roll: rotating by the eye line's angle, then equation 5,
        // reads -0.349 (worked out by hand from the same construction).
        let (e, v) = posed(-0.4, 10f64.to_radians(), 0.0);
        let angle = e.y.atan2(e.x);
        let (s, c) = (-angle).sin_cos();
        let naive = (c * v.x - s * v.y) / (s * v.x + c * v.y);
        assert!((naive + 0.3485).abs() < 1e-3, "naive {naive}");
        assert!((shear_and_roll(e, v).expect("usable").k + 0.4).abs() < 1e-9);
    }

    #[test]
    fn unusable_geometry_gives_none() {
        assert_eq!(
            shear_and_roll(Point::new(60.0, 0.0), Point::new(3.0, 2.0)),
            None
        );
        assert_eq!(
            shear_and_roll(Point::new(60.0, 0.0), Point::new(3.0, -40.0)),
            None
        );
        assert_eq!(
            shear_and_roll(Point::new(-60.0, 0.0), Point::new(3.0, 40.0)),
            None
        );
        assert_eq!(
            shear_and_roll(Point::new(f64::NAN, 0.0), Point::new(3.0, 40.0)),
            None
        );
        // 45 degrees of roll is within MAX_ROLL (57 degrees) and solved exactly; whatever is
        // returned for points posed far past it has a roll within the bound.
        let (e, v) = posed(0.0, 45f64.to_radians(), 0.0);
        let solved = shear_and_roll(e, v).expect("45 degrees is within MAX_ROLL");
        assert!((solved.roll - 45f64.to_radians()).abs() < 1e-9);
        assert!(solved.k.abs() < 1e-9);
        for degrees in [70.0f64, 80.0, -75.0] {
            let (e, v) = posed(0.0, degrees.to_radians(), 0.0);
            if let Some(r) = shear_and_roll(e, v) {
                assert!(r.roll.abs() <= MAX_ROLL, "{degrees}: {r:?}");
            }
        }
    }

    #[test]
    fn yaw_extrapolation_cancels_a_depth_proportional_term() {
        // Yaw adds a * t to the nose's reading and b * t to the mouth's, b / (a - b) = beta.
        for beta in [YAW_EXTRAPOLATION, YAW_EXTRAPOLATION_NOSTRILS] {
            let (a, b) = (1.0 + beta, beta);
            for t in [-0.1, 0.0, 0.07] {
                let k = yaw_corrected(0.3 + a * t, 0.3 + b * t, beta);
                assert!((k - 0.3).abs() < 1e-12, "beta {beta}, t {t}: {k}");
            }
        }
    }

    #[test]
    fn the_nose_tip_axis_is_preferred_and_the_nostrils_stand_in_for_it() {
        // Upright, unsheared eyes; each axis reads its own shear (x offset / height).
        let geometry = |tip: Option<Point>| FeatureGeometry {
            right_eye: Point::new(70.0, 100.0),
            left_eye: Point::new(130.0, 100.0),
            right_pair: (Point::new(83.0, 100.0), Point::new(83.0, 140.0)),
            left_pair: (Point::new(117.0, 100.0), Point::new(117.0, 140.0)),
            nose: Point::new(100.0 + 0.2 * 40.0, 140.0),
            mouth: Some(Point::new(100.0 + 0.1 * 60.0, 160.0)),
            nose_tip: tip,
        };
        let with_tip = estimate_face(
            &geometry(Some(Point::new(100.0 + 0.3 * 40.0, 140.0))),
            ShearModel::ShearRollYaw,
        )
        .expect("usable");
        assert!((with_tip.k - (0.1 + YAW_EXTRAPOLATION * (0.1 - 0.3))).abs() < 1e-9);
        assert_eq!(with_tip.k_nose_tip.map(|k| (k * 1e9).round()), Some(0.3e9));
        let without = estimate_face(&geometry(None), ShearModel::ShearRollYaw).expect("usable");
        assert!((without.k - (0.1 + YAW_EXTRAPOLATION_NOSTRILS * (0.1 - 0.2))).abs() < 1e-9);
        assert_eq!(without.k_nose_tip, None);
    }

    #[test]
    fn models_agree_on_an_upright_frontal_face_and_differ_under_roll() {
        let face = |k: f64, roll_deg: f64| {
            let (s, c) = roll_deg.to_radians().sin_cos();
            let shear = Shear::new(k, 0.0);
            let at = |x: f64, y: f64| {
                shear.apply(Point::new(100.0 + c * x - s * y, 80.0 + s * x + c * y))
            };
            FeatureGeometry {
                right_eye: at(-30.0, 0.0),
                left_eye: at(30.0, 0.0),
                right_pair: (at(-17.0, 0.0), at(-17.0, 42.0)),
                left_pair: (at(17.0, 0.0), at(17.0, 42.0)),
                nose: at(0.0, 42.0),
                mouth: Some(at(0.0, 66.0)),
                nose_tip: Some(at(0.0, 40.0)),
            }
        };
        for model in [
            ShearModel::Equation5,
            ShearModel::ShearRoll,
            ShearModel::ShearRollYaw,
        ] {
            let e = estimate_face(&face(0.3, 0.0), model).expect("usable");
            assert!((e.k - 0.3).abs() < 1e-9, "{model:?}: {e:?}");
        }
        let rolled = face(0.3, 12.0);
        let eq5 = estimate_face(&rolled, ShearModel::Equation5).expect("usable");
        assert!(
            (eq5.k - 0.3).abs() > 0.1,
            "equation 5 reads roll as shear: {eq5:?}"
        );
        for model in [ShearModel::ShearRoll, ShearModel::ShearRollYaw] {
            let e = estimate_face(&rolled, model).expect("usable");
            assert!((e.k - 0.3).abs() < 1e-9, "{model:?}: {e:?}");
            assert!(
                (e.roll - 12f64.to_radians()).abs() < 1e-9,
                "{model:?}: {e:?}"
            );
        }
        let mut no_mouth = rolled;
        no_mouth.mouth = None;
        let e = estimate_face(&no_mouth, ShearModel::ShearRollYaw).expect("nose alone");
        assert!((e.k - 0.3).abs() < 1e-9 && e.k_mouth.is_none());
    }
}

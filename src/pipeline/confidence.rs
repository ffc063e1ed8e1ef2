//! How far each face's estimate can be trusted: logistic models of the chance that it is within
//! 0.10 of the true shear, fitted by `scripts/fit_confidence.py` (docs/how-it-works.md).

use crate::detect::boxes::EYE_DISTANCE_PER_BOX_WIDTH;
use crate::estimate::FaceEstimate;
use crate::filters::FilterType;
use crate::fitted;
use crate::geometry::{Point, Rect};
use crate::locate::filters::FacePoints;
use crate::locate::network::LocatedFace;

/// A logistic confidence model: weights of `confidence`'s features, in their order, and the
/// intercept. Fitted by `scripts/fit_confidence.py`, which generates them into `src/fitted.rs`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConfidenceModel {
    /// One weight per feature.
    pub weights: [f64; 7],
    /// The intercept.
    pub intercept: f64,
}

impl ConfidenceModel {
    /// The logistic model's probability for `features` (0 when not finite).
    pub fn probability(&self, features: &[f64; 7]) -> f64 {
        let z = self.intercept
            + features
                .iter()
                .zip(self.weights)
                .map(|(x, w)| x * w)
                .sum::<f64>();
        let p = 1.0 / (1.0 + (-z).exp());
        if p.is_finite() {
            p
        } else {
            0.0
        }
    }

    /// The model fitted for filters of type `kind`: the peak-to-sidelobe ratios of the three
    /// filter types live on different scales, so each has its own fit (see `confidence`; the
    /// values are generated into `src/fitted.rs`, which names the commands each was fitted by).
    pub fn for_filters(kind: FilterType) -> Self {
        match kind {
            FilterType::Umace => Self {
                weights: fitted::CONFIDENCE_UMACE_WEIGHTS,
                intercept: fitted::CONFIDENCE_UMACE_INTERCEPT,
            },
            FilterType::Asef => Self {
                weights: fitted::CONFIDENCE_ASEF_WEIGHTS,
                intercept: fitted::CONFIDENCE_ASEF_INTERCEPT,
            },
            FilterType::Mosse => Self {
                weights: fitted::CONFIDENCE_MOSSE_WEIGHTS,
                intercept: fitted::CONFIDENCE_MOSSE_INTERCEPT,
            },
        }
    }

    /// The model fitted for the landmark network (see `network_confidence`).
    ///
    /// Fitted by `scripts/fit_confidence.py --model network` on the estimates of the 817
    /// development faces that no accuracy table measures and the network was never trained on
    /// (`eval shear --faces unseen`, eyes 12-40 px apart, at k = 0, +-0.20 and +-0.40), and
    /// checked on the 928 faces the tables measure (`src/fitted.rs` names the commands). The
    /// network is rarely more than 0.10 off on a face, so the model mostly ranks; the face
    /// score, the other factor, is what refuses non-faces.
    pub const NETWORK: Self = Self {
        weights: fitted::CONFIDENCE_NETWORK_WEIGHTS,
        intercept: fitted::CONFIDENCE_NETWORK_INTERCEPT,
    };
}

/// A face's confidence, 0 to 1: a logistic model of the chance that its estimate is within 0.10
/// of the true shear, from how clearly each feature stood out and whether the face's geometry is
/// consistent:
///
/// 1. `ln` of the weaker eye peak's peak-to-sidelobe ratio (PSRs below 0.1 count as 0.1);
/// 2. `ln` of the weaker nostril peak's PSR;
/// 3. `ln` of the mouth peak's PSR (0.1 without a mouth filter);
/// 4. `ln` of the nose filter's PSR (0.1 when it did not run);
/// 5. how far the nose tip's and the mouth's own estimates disagree, `|k_nose_tip - k_mouth|`
///    (0.5 when either is missing);
/// 6. the roll, `|degrees| / 10` (frontal faces in photos rarely roll much);
/// 7. how far the located eye distance over the box width is from the detector's 0.381, times 10.
///
/// Each filter type's model ([`ConfidenceModel::for_filters`]) was fitted by logistic regression
/// (`scripts/fit_confidence.py`, which documents the commands) on that filter type's estimates
/// of the development faces that no accuracy table measures and the landmark network was never
/// trained on (`eval shear --faces unseen`), and checked on the faces the tables measure
/// (`src/fitted.rs` gives each fit's figures).
pub(crate) fn confidence(
    points: &FacePoints,
    estimate: &FaceEstimate,
    face_box: Rect,
    model: &ConfidenceModel,
) -> f64 {
    let ln = |v: f64| v.max(0.1).ln();
    let eyes = points.psr[0].min(points.psr[1]);
    let nostrils = points.psr[2].min(points.psr[3]);
    let disagreement = match (estimate.k_nose_tip, estimate.k_mouth) {
        (Some(n), Some(m)) => (n - m).abs(),
        _ => 0.5,
    };
    let ratio = points.right_eye.distance(points.left_eye) / face_box.width.max(1.0);
    let features = [
        ln(eyes),
        ln(nostrils),
        ln(points.mouth_psr),
        ln(points.nose_tip_psr),
        disagreement,
        estimate.roll.to_degrees().abs() / 10.0,
        (ratio - EYE_DISTANCE_PER_BOX_WIDTH).abs() * 10.0,
    ];
    model.probability(&features)
}

/// A landmark-network face's confidence, 0 to 1: its face score (the chance that it is a face at
/// all) times a logistic model of the chance that, being a face, its estimate is within 0.10 of
/// the true shear, from
///
/// 1. the wider of the two eye heatmaps' spreads (eye distances);
/// 2. the nose heatmap's spread;
/// 3. the mouth heatmap's spread;
/// 4. how far the network's own reading and the points' shear disagree,
///    `|k_network - k_points|` (0.5 without `k_points`);
/// 5. how far the nose axis and the mouth axis disagree (0.5 when either is missing);
/// 6. the roll, `|degrees| / 10`;
/// 7. how far the located eye distance over the detector's box width is from 0.381, times 10
///    (a box that does not fit the eyes found: a false detection, or eyes found elsewhere).
pub(crate) fn network_confidence(
    found: &LocatedFace,
    face_box: Rect,
    model: &ConfidenceModel,
) -> f64 {
    let ratio = found.right_eye.distance(found.left_eye) / face_box.width.max(1.0);
    let features = [
        found.spread[0].max(found.spread[1]),
        found.spread[2],
        found.spread[3],
        found.k_points.map_or(0.5, |p| (found.k_network - p).abs()),
        match (found.k_nose, found.k_mouth) {
            (Some(n), Some(m)) => (n - m).abs(),
            _ => 0.5,
        },
        found.roll.to_degrees().abs() / 10.0,
        (ratio - EYE_DISTANCE_PER_BOX_WIDTH).abs() * 10.0,
    ];
    let c = found.face * model.probability(&features);
    if c.is_finite() {
        c
    } else {
        0.0
    }
}

/// Why the ruled checks of [`plausibility`] doubt a face.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Doubt {
    /// The face box lies largely outside the image, or a located point does.
    OutsideImage,
    /// The located points are not laid out as a face's.
    NotFaceLike,
    /// A head tipped far back or forward (the nose's drop outside [`TRUSTED_NOSE_DROP`]), or
    /// foreshortened and rolled ([`FORESHORTENED_ROLL_LIMIT`]), where the shear read from it is
    /// unreliable.
    UnreliablePose,
}

/// Largest share of a face box that may lie outside the image with no doubt: faces cut by the
/// border keep their box partly outside, and beyond half of it the face is mostly not seen.
/// Between this and [`BOX_OUTSIDE_REFUSED`] the confidence falls linearly to 0. Measured on the
/// development eval (docs/accuracy.md#gross-errors): no face found there has more than 0.16 of
/// its box outside.
pub const BOX_OUTSIDE_DOUBTED: f64 = 0.25;

/// Share of a face box outside the image from which the face is refused (see
/// [`BOX_OUTSIDE_DOUBTED`]).
pub const BOX_OUTSIDE_REFUSED: f64 = 0.5;

/// How far (pixels) a located eye, nose or mouth may lie outside the image: a point that is not
/// in the picture was guessed, not seen.
pub const POINT_OUTSIDE_MARGIN: f64 = 1.0;

/// The range of the located eye distance over the face box width: the detector's boxes put
/// 0.381 (docs/how-it-works.md); the development faces range from about 0.25 to 0.55, and a
/// walk of crops that ended on something far smaller or larger than the box it started from
/// found no face of that box. Development faces: 0.20-0.63.
pub const EYE_BOX_RATIO_RANGE: (f64, f64) = (0.15, 0.75);

/// The range of the nose point's drop below the eye line, in eye distances, in the face's own
/// frame (shear and roll undone): development faces measure 0.44-1.12 (median 0.77,
/// docs/accuracy.md#gross-errors), with a margin for faces looking up or down.
pub const NOSE_DROP_RANGE: (f64, f64) = (0.3, 1.3);

/// The range of the mouth's drop below the eye line, in eye distances (development faces
/// 0.66-1.56, median 1.10; see [`NOSE_DROP_RANGE`]).
pub const MOUTH_DROP_RANGE: (f64, f64) = (0.5, 1.75);

/// Widest the landmark network's nose and mouth heatmaps may both spread (eye distances, the
/// narrower of the two): beyond it the network found neither a nose nor a mouth to read the
/// shear from. Of the readings of the development faces that no accuracy table measures
/// (`eval shear --faces unseen`), 0.5% spread both wider (median 0.20); on photos whose faces
/// are painted over, the "faces" the network still scores as faces (hair and an outline around
/// a flat patch) spread them over 0.3 to 0.9 (docs/accuracy.md, false faces).
pub const MAX_NOSE_MOUTH_SPREAD: f64 = 0.28;

/// Largest sideways offset of the nose or the mouth from the eyes' midpoint, in eye distances,
/// in the face's own frame (development faces: at most 0.48, from turned heads).
pub const MAX_SIDEWAYS: f64 = 0.6;

/// The nose's usual drop below the eye line, in eye distances: the development faces' median.
pub const TYPICAL_NOSE_DROP: f64 = 0.77;

/// The range of the nose's drop below the eye line (eye distances, in the face's own frame) over
/// which its shear is trusted: the shear is read over the drop of the nose and mouth below the
/// eyes, so a head tipped far back (a short drop) magnifies every misplaced point, and a drop
/// far longer than faces have means a head bowed over or eyes located on the brows. Chosen with
/// the development eval and checked on the landmark network's own training photos (faces 25-40
/// px, none measured): in each it refuses one face read more than 0.15 off (at one shear and
/// at six), and 0.1% of the estimates within 0.10 (docs/accuracy.md#gross-errors).
pub const TRUSTED_NOSE_DROP: (f64, f64) = (0.45, 1.15);

/// Largest foreshortening-times-roll a face may show, `(TYPICAL_NOSE_DROP - nose drop) x |roll
/// in degrees|`: a head tipped back or forward draws its nose up towards the eyes, and when it
/// is also rolled the network misreads the foreshortening as shear, confidently. On the
/// development eval at all nine shears the accepted estimates more than 0.15 off from such a
/// head score 2.3-2.6, and 0.3% of those within 0.10 score 2.2 or more
/// (docs/accuracy.md#gross-errors).
pub const FORESHORTENED_ROLL_LIMIT: f64 = 2.2;

/// Where a face's nose and mouth lie from its eyes' midpoint in the face's own frame (the
/// measured shear and roll undone), in eye distances as the image shows them: `x` to the
/// image's right, `y` down.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FaceLayout {
    /// The nose point.
    pub nose: Point,
    /// The mouth centre.
    pub mouth: Point,
}

/// The layout of located points under shear `k` and roll `roll` (radians): the image of an
/// upright face is `S(k) R(roll)` of it, so the face's frame is `R(-roll) S(-k)` of the image
/// about the eyes' midpoint. `None` when the eyes coincide or a value is not finite.
pub fn face_layout(
    right_eye: Point,
    left_eye: Point,
    nose: Point,
    mouth: Point,
    k: f64,
    roll: f64,
) -> Option<FaceLayout> {
    let d = right_eye.distance(left_eye);
    if !(d > 0.0 && d.is_finite() && k.is_finite() && roll.is_finite()) {
        return None;
    }
    let mid = right_eye.midpoint(left_eye);
    let (s, c) = roll.sin_cos();
    // In eye distances as the image shows them (a rolled face's shear changes its eye distance
    // by a few per cent: the ranges were measured this way).
    let frame = |p: Point| {
        let (x, y) = (p.x - mid.x, p.y - mid.y);
        let x = x - k * y;
        // R(-roll): the roll turns the subject's left eye (image right) down.
        Point::new((c * x + s * y) / d, (-s * x + c * y) / d)
    };
    let layout = FaceLayout {
        nose: frame(nose),
        mouth: frame(mouth),
    };
    [layout.nose.x, layout.nose.y, layout.mouth.x, layout.mouth.y]
        .iter()
        .all(|v| v.is_finite())
        .then_some(layout)
}

/// The share of `b` outside a `width` x `height` image (0 inside, 1 wholly outside or empty).
pub fn box_outside_share(b: Rect, width: u32, height: u32) -> f64 {
    let image = Rect::new(0.0, 0.0, f64::from(width), f64::from(height));
    let area = b.area();
    if !(area > 0.0 && area.is_finite()) {
        return 1.0;
    }
    let inside = b.intersection(&image).map_or(0.0, |i| i.area());
    (1.0 - inside / area).clamp(0.0, 1.0)
}

/// What the ruled checks make of one face's located points.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plausibility {
    /// The factor (0 to 1) the learned confidence is multiplied by.
    pub factor: f64,
    /// Why the factor is below 1, if it is.
    pub doubt: Option<Doubt>,
}

/// The located points of one face.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocatedPoints {
    /// The detector's box.
    pub face_box: Rect,
    /// Subject's right eye (image left).
    pub right_eye: Point,
    /// Subject's left eye (image right).
    pub left_eye: Point,
    /// The nose point, if located.
    pub nose: Option<Point>,
    /// The mouth centre, if located.
    pub mouth: Option<Point>,
    /// The measured shear.
    pub k: f64,
    /// The measured roll, radians.
    pub roll: f64,
    /// The narrower of the landmark network's nose and mouth heatmap spreads, eye distances
    /// (`None` for the filters, which have no heatmaps).
    pub nose_mouth_spread: Option<f64>,
}

/// Ruled checks of what the learned confidence cannot see, as a factor on it: the logistic
/// models were fitted on real faces inside the picture, so they say nothing about a box hanging
/// off the image or points laid out like no face. Each check is a range measured on the
/// development faces (see the constants); outside it the face is refused (factor 0), except for
/// the box's share outside the image, which lowers the factor linearly between
/// [`BOX_OUTSIDE_DOUBTED`] and [`BOX_OUTSIDE_REFUSED`].
pub fn plausibility(p: &LocatedPoints, width: u32, height: u32) -> Plausibility {
    let refused = |doubt| Plausibility {
        factor: 0.0,
        doubt: Some(doubt),
    };
    let (w, h) = (f64::from(width), f64::from(height));
    let m = POINT_OUTSIDE_MARGIN;
    let inside = |q: Point| q.x >= -m && q.y >= -m && q.x <= w + m && q.y <= h + m;
    let points = [Some(p.right_eye), Some(p.left_eye), p.nose, p.mouth];
    if points.iter().flatten().any(|&q| !inside(q)) {
        return refused(Doubt::OutsideImage);
    }
    let ratio = p.right_eye.distance(p.left_eye) / p.face_box.width;
    if !(EYE_BOX_RATIO_RANGE.0..=EYE_BOX_RATIO_RANGE.1).contains(&ratio)
        || p.nose_mouth_spread
            .is_some_and(|s| s > MAX_NOSE_MOUTH_SPREAD)
    {
        return refused(Doubt::NotFaceLike);
    }
    if let (Some(nose), Some(mouth)) = (p.nose, p.mouth) {
        let Some(l) = face_layout(p.right_eye, p.left_eye, nose, mouth, p.k, p.roll) else {
            return refused(Doubt::NotFaceLike);
        };
        let face_like = (NOSE_DROP_RANGE.0..=NOSE_DROP_RANGE.1).contains(&l.nose.y)
            && (MOUTH_DROP_RANGE.0..=MOUTH_DROP_RANGE.1).contains(&l.mouth.y)
            && l.mouth.y > l.nose.y
            && l.nose.x.abs() <= MAX_SIDEWAYS
            && l.mouth.x.abs() <= MAX_SIDEWAYS;
        if !face_like {
            return refused(Doubt::NotFaceLike);
        }
        let foreshortened = (TYPICAL_NOSE_DROP - l.nose.y).max(0.0) * p.roll.to_degrees().abs();
        let trusted_drop = (TRUSTED_NOSE_DROP.0..=TRUSTED_NOSE_DROP.1).contains(&l.nose.y);
        if foreshortened >= FORESHORTENED_ROLL_LIMIT || !trusted_drop {
            return refused(Doubt::UnreliablePose);
        }
    }
    let outside = box_outside_share(p.face_box, width, height);
    let factor = ((BOX_OUTSIDE_REFUSED - outside) / (BOX_OUTSIDE_REFUSED - BOX_OUTSIDE_DOUBTED))
        .clamp(0.0, 1.0);
    Plausibility {
        factor,
        doubt: (factor < 1.0).then_some(Doubt::OutsideImage),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::estimate::FaceEstimate;
    use crate::geometry::Point;

    #[test]
    fn confidence_rises_with_clear_peaks_and_falls_with_disagreement_for_every_filter_type() {
        let p = |x: f64, y: f64| Point::new(x, y);
        let points = |mouth_psr: f64| FacePoints {
            right_eye: p(81.0, 100.0),
            left_eye: p(138.0, 100.0),
            right_nostril: p(100.0, 140.0),
            left_nostril: p(119.0, 140.0),
            right_eye_point: p(94.0, 100.0),
            left_eye_point: p(125.0, 100.0),
            right_nose_point: p(94.0, 140.0),
            left_nose_point: p(125.0, 140.0),
            psr: [8.0, 8.0, 4.0, 4.0],
            mouth: Some(p(110.0, 163.0)),
            mouth_psr,
            nose_tip: Some(p(110.0, 143.0)),
            nose_tip_psr: 5.0,
            view_k: 0.0,
        };
        let estimate = |disagreement: f64| FaceEstimate {
            k: 0.0,
            roll: 0.0,
            k_nose: Some(0.0),
            k_mouth: Some(0.0),
            k_nose_tip: Some(disagreement),
        };
        // A box the detector would draw for eyes 57 px apart.
        let face_box = Rect::new(60.0, 60.0, 57.0 / EYE_DISTANCE_PER_BOX_WIDTH, 150.0);
        for kind in FilterType::ALL {
            let model = ConfidenceModel::for_filters(kind);
            let c = |mouth_psr, disagreement| {
                confidence(
                    &points(mouth_psr),
                    &estimate(disagreement),
                    face_box,
                    &model,
                )
            };
            let (clear, faint, split) = (c(6.0, 0.0), c(2.0, 0.0), c(6.0, 0.3));
            for v in [clear, faint, split] {
                assert!(v > 0.0 && v < 1.0, "{kind:?}: {v}");
            }
            assert!(clear > faint, "{kind:?}: mouth PSR {clear} vs {faint}");
            assert!(clear > split, "{kind:?}: disagreement {clear} vs {split}");
        }
    }

    /// An upright face with eyes 40 px apart about (100, 100), nose 0.7 and mouth 1.15 eye
    /// distances below, sheared by `k` and rolled by `roll` about the eyes' midpoint.
    fn posed(k: f64, roll: f64) -> LocatedPoints {
        let mid = Point::new(100.0, 100.0);
        let (s, c) = f64::sin_cos(roll);
        let pose = |x: f64, y: f64| {
            let (x, y) = (c * x - s * y, s * x + c * y);
            Point::new(mid.x + x + k * y, mid.y + y)
        };
        LocatedPoints {
            face_box: Rect::new(48.0, 70.0, 105.0, 105.0),
            right_eye: pose(-20.0, 0.0),
            left_eye: pose(20.0, 0.0),
            nose: Some(pose(0.0, 28.0)),
            mouth: Some(pose(0.0, 46.0)),
            k,
            roll,
            nose_mouth_spread: Some(0.21),
        }
    }

    #[test]
    fn the_layout_is_read_in_the_faces_own_frame() {
        for (k, roll) in [(0.0, 0.0), (0.4, 0.0), (-0.3, 0.3), (0.2, -0.5)] {
            let p = posed(k, roll);
            let l = face_layout(
                p.right_eye,
                p.left_eye,
                p.nose.unwrap_or_default(),
                p.mouth.unwrap_or_default(),
                k,
                roll,
            )
            .expect("layout");
            // Scaled by the eye distance the image shows: 40 px unless shear meets roll.
            let scale = 40.0 / p.right_eye.distance(p.left_eye);
            assert!(
                l.nose.x.abs() < 1e-9 && (l.nose.y - 0.7 * scale).abs() < 1e-9,
                "{l:?}"
            );
            let mouth = 1.15 * scale;
            assert!(
                l.mouth.x.abs() < 1e-9 && (l.mouth.y - mouth).abs() < 1e-9,
                "{l:?}"
            );
            assert!((scale - 1.0).abs() < 0.1 && (k * roll != 0.0 || scale == 1.0));
        }
    }

    #[test]
    fn ruled_checks_refuse_what_the_learned_confidence_cannot_see() {
        let ok = posed(0.3, 0.2);
        assert_eq!(
            plausibility(&ok, 300, 300),
            Plausibility {
                factor: 1.0,
                doubt: None
            }
        );
        // An eye outside the picture was guessed, not seen.
        let out = plausibility(&ok, 115, 300);
        assert_eq!((out.factor, out.doubt), (0.0, Some(Doubt::OutsideImage)));
        // The box partly outside: from a quarter of it, less and less trusted, nothing from half.
        let shifted = |x: f64| LocatedPoints {
            face_box: Rect::new(x, 70.0, 105.0, 105.0),
            ..ok
        };
        assert_eq!(plausibility(&shifted(-20.0), 300, 300).factor, 1.0);
        let third = plausibility(&shifted(-105.0 / 3.0), 300, 300);
        assert!(third.factor > 0.0 && third.factor < 1.0, "{third:?}");
        assert_eq!(third.doubt, Some(Doubt::OutsideImage));
        assert_eq!(plausibility(&shifted(-53.0), 300, 300).factor, 0.0);
        // Points laid out like no face: the nose above the eyes, the mouth far to one side,
        // eyes a tenth of the box apart.
        let nose_up = LocatedPoints {
            nose: Some(Point::new(100.0, 90.0)),
            ..posed(0.0, 0.0)
        };
        let mouth_aside = LocatedPoints {
            mouth: Some(Point::new(140.0, 146.0)),
            ..posed(0.0, 0.0)
        };
        let small_eyes = LocatedPoints {
            face_box: Rect::new(0.0, 0.0, 400.0, 400.0),
            ..posed(0.0, 0.0)
        };
        // The network could not find a nose or mouth: its heatmap spread wide.
        let no_mouth_seen = LocatedPoints {
            nose_mouth_spread: Some(MAX_NOSE_MOUTH_SPREAD + 0.01),
            ..posed(0.0, 0.0)
        };
        for p in [nose_up, mouth_aside, small_eyes, no_mouth_seen] {
            let v = plausibility(&p, 500, 500);
            assert_eq!(
                (v.factor, v.doubt),
                (0.0, Some(Doubt::NotFaceLike)),
                "{p:?}"
            );
        }
        assert_eq!(
            box_outside_share(Rect::new(-10.0, 0.0, 20.0, 10.0), 50, 50),
            0.5
        );
        assert_eq!(
            box_outside_share(Rect::new(0.0, 0.0, 0.0, 10.0), 50, 50),
            1.0
        );
    }

    /// A head tipped far back or forward, or tipped a little and rolled, gives a shear reading
    /// that cannot be trusted ([`TRUSTED_NOSE_DROP`], [`FORESHORTENED_ROLL_LIMIT`]).
    #[test]
    fn tipped_heads_are_refused_as_unreliable_poses() {
        // Eyes 40 px apart: the nose `drop` eye distances below them, the mouth 0.4 below it.
        let tipped = |drop: f64, roll_degrees: f64| {
            let p = posed(0.1, roll_degrees.to_radians());
            let (s, c) = roll_degrees.to_radians().sin_cos();
            let at = |y: f64| Point::new(100.0 - s * y + 0.1 * c * y, 100.0 + c * y);
            LocatedPoints {
                nose: Some(at(drop * 40.0)),
                mouth: Some(at((drop + 0.4) * 40.0)),
                ..p
            }
        };
        let doubt = |drop, roll| plausibility(&tipped(drop, roll), 300, 300).doubt;
        let unreliable = Some(Doubt::UnreliablePose);
        for (drop, roll) in [(0.5, 0.0), (0.77, 30.0), (1.1, 5.0), (0.6, 10.0)] {
            assert_eq!(doubt(drop, roll), None, "drop {drop}, roll {roll}");
        }
        for (drop, roll) in [(0.42, 0.0), (1.2, 0.0), (0.6, 15.0), (0.55, -11.0)] {
            assert_eq!(doubt(drop, roll), unreliable, "drop {drop}, roll {roll}");
        }
    }
}

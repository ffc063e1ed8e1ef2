//! How far each face's estimate can be trusted: logistic models of the chance that it is within
//! 0.10 of the true shear, fitted by `scripts/fit_confidence.py` (docs/how-it-works.md).

use crate::detect::boxes::EYE_DISTANCE_PER_BOX_WIDTH;
use crate::estimate::FaceEstimate;
use crate::filters::FilterType;
use crate::fitted;
use crate::geometry::Rect;
use crate::locate::filters::FacePoints;
use crate::locate::network::LocatedFace;

/// A logistic confidence model: weights of [`confidence`]'s features, in their order, and the
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
    /// filter types live on different scales, so each has its own fit (see [`confidence`]; the
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

    /// The model fitted for the landmark network (see [`network_confidence`]).
    ///
    /// Fitted by `scripts/fit_confidence.py --model network` on the estimates of the first 300
    /// faces at k = 0 and +-0.40, and checked on the other 628 faces (`src/fitted.rs` names the
    /// commands). The network is rarely more than 0.10 off on a face, so the fit has few bad
    /// estimates to learn from and its weights are loose (the nose and mouth axes'
    /// disagreement even gets a positive weight); the face score, the other factor, is what
    /// refuses non-faces.
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
/// (`scripts/fit_confidence.py`, which documents the commands) on the estimates of 300 of the 928
/// Caltech development faces with eyes at least 40 px apart, at k = 0 and +-0.40, with the
/// default pipeline and those filters, and checked on the estimates of the other 628 faces,
/// which were not used to fit it (the first 300 by image path for every type). The mouth's PSR
/// and the nose/mouth disagreement weigh most. With MOSSE filters (the default), on its 1782
/// check estimates, the default threshold of 0.25 keeps 83% of them with 69% within 0.10 (all:
/// 61%); 0.3 keeps 79% with 71%, 0.5 keeps 63% with 78%. With UMACE, 0.25 keeps 84% of 1777
/// with 66% within 0.10 (all: 59%). (A refused face is retried in de-sheared views, so in the
/// whole pipeline fewer faces end up refused than these shares suggest.)
pub fn confidence(
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
pub fn network_confidence(found: &LocatedFace, face_box: Rect, model: &ConfidenceModel) -> f64 {
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
}

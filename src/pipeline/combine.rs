//! Faces found more than once reduced to one, and the image's shear from its faces.

use super::report::FaceReport;
use crate::geometry::Rect;
use crate::stats::weighted_median;

/// Whether `b` holds both eyes that `report` located.
pub(crate) fn holds_eyes(b: &Rect, report: &FaceReport) -> bool {
    b.contains(report.right_eye) && b.contains(report.left_eye)
}

/// How close (in eye distances, the smaller face's) the eye midpoints of two estimates must be
/// for them to be one face found twice: two people's eye midpoints are two or more eye distances
/// apart even in a crowd.
pub(crate) const SAME_FACE_EYE_DISTANCES: f64 = 0.5;

/// Whether two estimates located the same face: their eye midpoints within
/// [`SAME_FACE_EYE_DISTANCES`]. Their boxes can still differ much: a turned view's box around
/// a whole head, say, from which the features were followed to the face that another box holds
/// tightly.
fn same_face(a: &FaceReport, b: &FaceReport) -> bool {
    let eye_distance = a
        .right_eye
        .distance(a.left_eye)
        .min(b.right_eye.distance(b.left_eye));
    let apart = a
        .right_eye
        .midpoint(a.left_eye)
        .distance(b.right_eye.midpoint(b.left_eye));
    apart < SAME_FACE_EYE_DISTANCES * eye_distance
}

/// Of faces whose boxes overlap (IoU 0.3 or more), whose estimates located the same face
/// ([`same_face`]), or of which one's box holds both eyes located in another kept before it, the
/// one with the most confident estimate (a face without an estimate last), preferring one whose
/// box holds both eyes it located: a box the features were followed out of (from a false alarm
/// beside the face, say) does not show where the face is. A box holding both eyes of a face
/// already kept is that face seen again, often from a view that takes in the whole head, whose
/// walk of crops may have stopped on something else (eyes of two faces, say) before reaching
/// it; two people's faces cannot both fit in one face box.
pub(crate) fn most_confident_of_overlapping(
    mut all: Vec<(Rect, Option<FaceReport>)>,
) -> Vec<(Rect, Option<FaceReport>)> {
    let confidence = |r: &Option<FaceReport>| r.as_ref().map_or(-1.0, |r| r.confidence);
    let holds_its_eyes =
        |(b, r): &(Rect, Option<FaceReport>)| r.as_ref().is_some_and(|r| holds_eyes(b, r));
    all.sort_by(|a, b| {
        holds_its_eyes(b)
            .cmp(&holds_its_eyes(a))
            .then(confidence(&b.1).total_cmp(&confidence(&a.1)))
    });
    let mut kept: Vec<(Rect, Option<FaceReport>)> = Vec::new();
    for f in all {
        let duplicate = |k: &(Rect, Option<FaceReport>)| {
            k.0.iou(&f.0) >= 0.3
                || matches!((&k.1, &f.1), (Some(a), Some(b)) if same_face(a, b))
                || matches!(&k.1, Some(a) if holds_eyes(&f.0, a))
        };
        if !kept.iter().any(duplicate) {
            kept.push(f);
        }
    }
    kept
}

/// [`combined_shear`] of the faces in `found` that gave an estimate.
pub(crate) fn measured_shear(found: &[(Rect, Option<FaceReport>)]) -> Option<f64> {
    let reports: Vec<FaceReport> = found.iter().filter_map(|(_, r)| *r).collect();
    combined_shear(&reports)
}

/// The image's shear from its faces' accepted estimates: their confidence-weighted median,
/// robust to a minority of faces whose features were mislocated and led by the faces the
/// estimator trusts most. Faces with refused estimates do not count; `None` when no face has an
/// accepted estimate.
pub fn combined_shear(faces: &[FaceReport]) -> Option<f64> {
    weighted_median(
        faces
            .iter()
            .filter_map(|f| Some((f.k?, f.confidence.max(1e-6)))),
    )
}

//! Faces found more than once reduced to one, and the image's shear from its faces.

use super::report::{FaceReport, FoundBox, Refusal, ShearSource};
use crate::config::Ruler;
use crate::geometry::Rect;
use crate::scene::SceneShear;
use crate::stats::weighted_median;

/// Whether `b` holds both eyes that `report` located.
pub(crate) fn holds_eyes(b: &Rect, report: &FaceReport) -> bool {
    b.contains(report.right_eye) && b.contains(report.left_eye)
}

/// How close (in eye distances, the smaller face's) the eye midpoints of two estimates must be
/// for them to be one face found twice: two people's eye midpoints are two or more eye distances
/// apart even in a crowd.
pub(crate) const SAME_FACE_EYE_DISTANCES: f64 = 0.5;

/// The smaller of two estimates' eye distances: the unit their eyes are compared in.
pub(crate) fn smaller_eye_distance(a: &FaceReport, b: &FaceReport) -> f64 {
    a.right_eye
        .distance(a.left_eye)
        .min(b.right_eye.distance(b.left_eye))
}

/// Whether two estimates located the same face: their eye midpoints within
/// [`SAME_FACE_EYE_DISTANCES`]. Their boxes can still differ much: a turned view's box around
/// a whole head, say, from which the features were followed to the face that another box holds
/// tightly.
fn same_face(a: &FaceReport, b: &FaceReport) -> bool {
    let eye_distance = smaller_eye_distance(a, b);
    let apart = a
        .right_eye
        .midpoint(a.left_eye)
        .distance(b.right_eye.midpoint(b.left_eye));
    apart < SAME_FACE_EYE_DISTANCES * eye_distance
}

/// Of faces whose boxes overlap (IoU 0.3 or more), whose estimates located the same face
/// ([`same_face`]), or of which one's box holds both eyes located in another kept before it, the
/// one with the most confident estimate (a face without an estimate last; between equally
/// confident ones, such as two refused with confidence 0, the higher face score), preferring one
/// whose box holds both eyes it located: a box the features were followed out of (from a false
/// alarm beside the face, say) does not show where the face is. The face score decides between
/// refused readings of one spot whatever order they were found in: seen on a close, turned face
/// in glasses, where one lens and the cheek read as a small face (score 0.987) had hidden the
/// whole face (0.999). A box holding both eyes of a face already kept is that face seen again,
/// often from a view that takes in the whole head, whose walk of crops may have stopped on
/// something else (eyes of two faces, say) before reaching it; two people's faces cannot both
/// fit in one face box.
pub(crate) fn most_confident_of_overlapping(mut all: Vec<FoundBox>) -> Vec<FoundBox> {
    let confidence = |r: &Option<FaceReport>| r.as_ref().map_or(-1.0, |r| r.confidence);
    let face_score = |r: &Option<FaceReport>| r.and_then(|r| r.face_score).unwrap_or(-1.0);
    let holds_its_eyes = |f: &FoundBox| {
        f.report
            .as_ref()
            .is_some_and(|r| holds_eyes(&f.face_box, r))
    };
    all.sort_by(|a, b| {
        holds_its_eyes(b)
            .cmp(&holds_its_eyes(a))
            .then(confidence(&b.report).total_cmp(&confidence(&a.report)))
            .then(face_score(&b.report).total_cmp(&face_score(&a.report)))
    });
    let mut kept: Vec<FoundBox> = Vec::new();
    for f in all {
        let duplicate = |k: &FoundBox| {
            k.face_box.iou(&f.face_box) >= 0.3
                || matches!((&k.report, &f.report), (Some(a), Some(b)) if same_face(a, b))
                || matches!(&k.report, Some(a) if holds_eyes(&f.face_box, a))
        };
        if !kept.iter().any(duplicate) {
            kept.push(f);
        }
    }
    refuse_nested(&mut kept);
    kept
}

/// Refuses (as [`Refusal::NotFaceLike`]) the accepted estimate of a face when one's box holds
/// both eyes located in another face kept beside it that is credible too (accepted, or refused
/// only for its pose): two people's faces cannot both fit in one face box, so one of the two is
/// not a face, and which one cannot be told from the pair. Seen on heads rolled 45 degrees and
/// sheared: a box around head and shoulders whose located "eyes" were a shoulder and the real
/// face, accepted with high confidence, while the real face inside it was refused for its pose.
/// A face refused for any other reason is a weak claim and refuses nothing.
fn refuse_nested(kept: &mut [FoundBox]) {
    let credible = |r: &FaceReport| matches!(r.refused, None | Some(Refusal::UnreliablePose));
    let nested: Vec<usize> = (0..kept.len())
        .filter(|&i| {
            let FoundBox {
                face_box: a_box,
                report: Some(a),
            } = &kept[i]
            else {
                return false;
            };
            a.k.is_some()
                && kept.iter().enumerate().any(|(j, f)| {
                    f.report.as_ref().is_some_and(|b| {
                        i != j
                            && credible(b)
                            && (holds_eyes(a_box, b) || holds_eyes(&f.face_box, a))
                    })
                })
        })
        .collect();
    for i in nested {
        if let Some(r) = kept[i].report.as_mut() {
            r.k = None;
            r.refused = Some(Refusal::NotFaceLike);
        }
    }
}

/// [`combined_shear`] of the faces in `found` that gave an estimate.
pub(crate) fn measured_shear(found: &[FoundBox]) -> Option<f64> {
    let reports: Vec<FaceReport> = found.iter().filter_map(|f| f.report).collect();
    combined_shear(&reports)
}

/// Each face's stated uncertainty: the half-width of the window its estimate and the truth are
/// expected in. The confidence is a model of the chance that the estimate is within 0.10 of the
/// truth, so two accepted faces whose estimates are more than twice this apart cannot both be
/// right.
pub(crate) const FACE_UNCERTAINTY: f64 = 0.10;

/// The image's shear from its faces, and which faces disagree with it.
#[derive(Debug, Clone, PartialEq, Default)]
pub(crate) struct Consensus {
    /// The confidence-weighted median of the consistent majority, `None` when no face has an
    /// accepted estimate or no consistent group outweighs the rest.
    pub k: Option<f64>,
    /// The faces (indices) with accepted estimates outside the majority.
    pub outvoted: Vec<usize>,
    /// Whether faces had accepted estimates but no consistent group outweighed the others.
    pub no_majority: bool,
}

/// The consistent majority of the faces' accepted estimates: the estimates that fit in one
/// window of width `2 FACE_UNCERTAINTY` (all within [`FACE_UNCERTAINTY`] of one shear) with
/// the largest total confidence. When that total is more than half of all accepted faces'
/// confidence, the image's shear is the group's confidence-weighted median, moved if need be to
/// within [`FACE_UNCERTAINTY`] of every face of the group, and the faces outside it are
/// outvoted; otherwise the faces disagree and the image gets no shear (a wrong correction is
/// worse than none). One face, or faces that all agree, is its own majority.
pub(crate) fn consensus(faces: &[FaceReport]) -> Consensus {
    let accepted: Vec<(usize, f64, f64)> = faces
        .iter()
        .enumerate()
        .filter_map(|(i, f)| Some((i, f.k?, f.confidence.max(1e-6))))
        .filter(|(_, k, w)| k.is_finite() && w.is_finite())
        .collect();
    if accepted.is_empty() {
        return Consensus::default();
    }
    let total: f64 = accepted.iter().map(|a| a.2).sum();
    let window = 2.0 * FACE_UNCERTAINTY;
    // Every window worth testing starts at one of the estimates.
    let members = |lo: f64| {
        accepted
            .iter()
            .filter(move |a| a.1 >= lo && a.1 <= lo + window)
            .copied()
    };
    let best = accepted
        .iter()
        .map(|a| (a.1, members(a.1).map(|m| m.2).sum::<f64>()))
        .max_by(|a, b| a.1.total_cmp(&b.1));
    let Some((lo, weight)) = best else {
        return Consensus::default();
    };
    if weight <= 0.5 * total {
        return Consensus {
            k: None,
            outvoted: Vec::new(),
            no_majority: true,
        };
    }
    let group: Vec<(usize, f64, f64)> = members(lo).collect();
    // Where every face of the group can be right: within FACE_UNCERTAINTY of each. The
    // weighted median of two faces is the heavier one's estimate, however slightly heavier.
    let (least, most) = group
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), m| {
            (a.min(m.1), b.max(m.1))
        });
    let all_right = (most - FACE_UNCERTAINTY)..=(least + FACE_UNCERTAINTY);
    Consensus {
        k: weighted_median(group.iter().map(|m| (m.1, m.2)))
            .map(|k| k.clamp(*all_right.start(), *all_right.end())),
        outvoted: accepted
            .iter()
            .filter(|a| !group.iter().any(|m| m.0 == a.0))
            .map(|a| a.0)
            .collect(),
        no_majority: false,
    }
}

/// The image's shear from its faces' accepted estimates ([`consensus`]): the confidence-weighted
/// median of the consistent majority, robust to a minority of faces whose features were
/// mislocated. Faces with refused estimates do not count; `None` when no face has an accepted
/// estimate or the faces disagree with no majority.
pub(crate) fn combined_shear(faces: &[FaceReport]) -> Option<f64> {
    consensus(faces).k
}

/// One standard deviation of a face's estimate, for combining it with the scene's: 90% of the
/// development faces' estimates are within 0.05 of the truth (docs/accuracy.md), a normal
/// error's 1.645 standard deviations.
pub(crate) const FACE_SIGMA: f64 = 0.03;

/// The image's shear from the faces' consensus `faces_k` (of `faces` agreeing faces) and the
/// scene's reading, as `ruler` asks: with [`Ruler::Combine`] and [`Ruler::Scene`], both,
/// combined by their inverse variances, when they agree (within [`FACE_UNCERTAINTY`] plus twice
/// the scene's uncertainty); otherwise the faces' (the last value says whether the two
/// disagree, whatever the ruler); the scene's without faces only with [`Ruler::Scene`].
pub(crate) fn fuse(
    faces_k: Option<f64>,
    faces: usize,
    scene: Option<&SceneShear>,
    ruler: Ruler,
) -> (Option<f64>, Option<ShearSource>, bool) {
    match (faces_k, scene) {
        (Some(kf), Some(s)) if ruler != Ruler::Faces => {
            if (kf - s.k).abs() > FACE_UNCERTAINTY + 2.0 * s.uncertainty {
                return (Some(kf), Some(ShearSource::Faces), true);
            }
            if ruler == Ruler::Auto {
                return (Some(kf), Some(ShearSource::Faces), false);
            }
            let face_var = FACE_SIGMA * FACE_SIGMA / faces.max(1) as f64;
            let scene_var = (s.uncertainty * s.uncertainty).max(1e-8);
            let k = (kf / face_var + s.k / scene_var) / (1.0 / face_var + 1.0 / scene_var);
            (Some(k), Some(ShearSource::FacesAndScene), false)
        }
        (Some(kf), _) => (Some(kf), Some(ShearSource::Faces), false),
        (None, Some(s)) if ruler == Ruler::Scene => (Some(s.k), Some(ShearSource::Scene), false),
        (None, _) => (None, None, false),
    }
}

/// [`consensus`] of `faces`, with the faces it outvotes marked so (`outvoted`).
pub(crate) fn mark_consensus(faces: &mut [FaceReport]) -> Consensus {
    let consensus = consensus(faces);
    for &i in &consensus.outvoted {
        faces[i].outvoted = true;
    }
    consensus
}

#[cfg(test)]
mod fuse_tests {
    use super::*;

    fn scene(k: f64, uncertainty: f64) -> SceneShear {
        SceneShear {
            k,
            uncertainty,
            segments: 6,
            lines: 4,
            length: 2.0,
            roll_degrees: None,
            convergence: 0.0,
            voters: Vec::new(),
        }
    }

    #[test]
    fn agreeing_rulers_are_combined_and_disagreeing_ones_leave_the_faces() {
        let s = scene(0.24, FACE_SIGMA);
        // Reported beside the faces' by default.
        assert_eq!(
            fuse(Some(0.20), 1, Some(&s), Ruler::Auto),
            (Some(0.20), Some(ShearSource::Faces), false)
        );
        let (k, source, disagree) = fuse(Some(0.20), 1, Some(&s), Ruler::Combine);
        // Equal variances: the midpoint.
        assert!((k.expect("a shear") - 0.22).abs() < 1e-12);
        assert_eq!(
            (source, disagree),
            (Some(ShearSource::FacesAndScene), false)
        );
        // Two faces weigh twice one: a third of the way to the scene.
        let (k, ..) = fuse(Some(0.20), 2, Some(&s), Ruler::Combine);
        assert!((k.expect("a shear") - (0.20 + 0.04 / 3.0)).abs() < 1e-12);
        // Beyond FACE_UNCERTAINTY + 2 scene uncertainties: the faces decide, and say so.
        let far = scene(
            0.20 + FACE_UNCERTAINTY + 2.0 * FACE_SIGMA + 0.01,
            FACE_SIGMA,
        );
        assert_eq!(
            fuse(Some(0.20), 1, Some(&far), Ruler::Scene),
            (Some(0.20), Some(ShearSource::Faces), true)
        );
        assert_eq!(
            fuse(Some(0.20), 1, Some(&far), Ruler::Auto),
            (Some(0.20), Some(ShearSource::Faces), true)
        );
        assert_eq!(
            fuse(Some(0.20), 1, None, Ruler::Auto),
            (Some(0.20), Some(ShearSource::Faces), false)
        );
        assert_eq!(
            fuse(Some(0.20), 1, Some(&s), Ruler::Faces),
            (Some(0.20), Some(ShearSource::Faces), false)
        );
    }

    #[test]
    fn the_scene_alone_corrects_only_when_asked() {
        let s = scene(-0.15, 0.02);
        assert_eq!(fuse(None, 0, Some(&s), Ruler::Auto), (None, None, false));
        assert_eq!(fuse(None, 0, Some(&s), Ruler::Combine), (None, None, false));
        assert_eq!(
            fuse(None, 0, Some(&s), Ruler::Scene),
            (Some(-0.15), Some(ShearSource::Scene), false)
        );
        assert_eq!(fuse(None, 0, None, Ruler::Scene), (None, None, false));
    }

    #[test]
    fn a_combined_shear_is_never_further_from_the_faces_than_the_scene_is() {
        // Whatever the two say, the combination lies between them: never worse than the
        // faces alone by more than how far the scene's reading (within its window) is.
        let mut rng = crate::rng::SplitMix64::new(3);
        for _ in 0..1000 {
            let kf = rng.symmetric(0.5);
            let s = scene(kf + rng.symmetric(0.2), 0.001 + rng.next_f64() * 0.03);
            let n = 1 + (rng.next_f64() * 4.0) as usize;
            let (k, source, _) = fuse(Some(kf), n, Some(&s), Ruler::Combine);
            let k = k.expect("a shear");
            if source == Some(ShearSource::FacesAndScene) {
                assert!((k - kf).abs() <= (s.k - kf).abs() + 1e-12);
                assert!((k - kf).abs() <= FACE_UNCERTAINTY + 2.0 * s.uncertainty + 1e-12);
            } else {
                assert_eq!(k, kf);
            }
        }
    }
}

//! Candidate faces from the proposal classifier's windows: where the window expects the eyes,
//! whether it may show a face not found yet, and whether the face found from it is the one it
//! shows.

use image::GrayImage;

use super::combine::{holds_eyes, smaller_eye_distance};
use super::face::MIN_FACE_SCORE;
use super::report::FaceReport;
use super::search::{desheared_view, Detection, NEAR_MISS_MIN_FACE_SCORE};
use crate::config::{DEFAULT_MIN_CONFIDENCE, MIN_NETWORK_FACE};
use crate::detect::boxes::{box_around_eyes, eyes_in_box, EYE_DISTANCE_PER_BOX_WIDTH};
use crate::detect::{ProposalNet, ProposalParams};
use crate::geometry::{Point, Rect};

/// How far (in the window's eye distances) the eyes the network located from a proposal
/// window may be from where the window expects them, for the face to count as the window's.
pub(crate) const PROPOSAL_MAX_OFFSET: f64 = 0.5;

/// How much larger or smaller than the window expects the located eye distance may be.
pub(crate) const PROPOSAL_MAX_SCALE: f64 = 1.5;

/// Where a proposal (see [`proposal_detections`]) expects the eyes' midpoint, and their
/// distance.
pub(crate) fn proposal_eyes(proposal: &Detection) -> (Point, f64) {
    let b = proposal.face_box;
    let (at_x, at_y) = eyes_in_box();
    (
        Point::new(b.x + at_x * b.width, b.y + at_y * b.height),
        b.width * EYE_DISTANCE_PER_BOX_WIDTH,
    )
}

/// The confidence from which a face found hides the network detector's windows of about its
/// size on it ([`window_is_new`]): the default's threshold. A face read with less can be a
/// wrong reading beside a real face (seen: "eyes" on a child's cheek and eye, or half a face
/// below the real eyes, confidence 0) that hid the window reading that face right.
pub(crate) const HIDING_MIN_CONFIDENCE: f64 = DEFAULT_MIN_CONFIDENCE;

/// Whether `face` is sure enough to hide the windows of about its size on it
/// ([`HIDING_MIN_CONFIDENCE`]).
pub(crate) fn hides_windows(face: &FaceReport) -> bool {
    face.confidence >= HIDING_MIN_CONFIDENCE
}

/// Whether the face `r` hides `proposal`: the window's box holds its eyes and it is about the
/// window's size ([`PROPOSAL_MAX_SCALE`]; that face again), or the window's eyes are inside its
/// box and it is about the window's size or larger (part of that face at a smaller scale: a
/// large face's nose and nostrils can look like a small face to the classifier and the network
/// alike). A much larger window around a smaller face is not hidden: that "face" can be the
/// nose of the larger one. Also says whether `r` is much larger than the window.
fn hides(proposal: &Detection, r: &FaceReport) -> (bool, bool) {
    let (eyes, distance) = proposal_eyes(proposal);
    let ratio = r.right_eye.distance(r.left_eye) / distance;
    let at_least_as_large = ratio * PROPOSAL_MAX_SCALE >= 1.0;
    let about_as_large = at_least_as_large && ratio <= PROPOSAL_MAX_SCALE;
    let same_face = holds_eyes(&proposal.face_box, r) && about_as_large;
    let part_of_it = at_least_as_large && r.face_box.contains(eyes);
    (same_face || part_of_it, ratio > PROPOSAL_MAX_SCALE)
}

/// Whether a proposal may show a face not among `found`: no face found hides it (see
/// [`hides`]).
pub(crate) fn proposal_is_new(proposal: &Detection, found: &[(Rect, Option<FaceReport>)]) -> bool {
    found
        .iter()
        .all(|(_, r)| r.is_none_or(|r| !hides(proposal, &r).0))
}

/// [`proposal_is_new`] for the network detector's windows, where only a face sure enough
/// ([`hides_windows`]) hides a window of about its size; any face hides the windows on its parts
/// much smaller than itself. A window an unsure face does not hide is looked at, and its face
/// settled against that one by [`settle_unsure_faces`].
pub(crate) fn window_is_new(window: &Detection, found: &[(Rect, Option<FaceReport>)]) -> bool {
    found.iter().all(|(_, r)| {
        r.is_none_or(|r| {
            let (hidden, much_larger) = hides(window, &r);
            !(hidden && (much_larger || hides_windows(&r)))
        })
    })
}

/// How close (in eye distances, the smaller face's) each eye of two readings must be for them to
/// be one reading of the same eyes: the landmark network's eyes are within 0.10 eye distances of
/// the truth for 96% of the development faces.
pub(crate) const SAME_EYES_EYE_DISTANCES: f64 = 0.25;

/// Whether two readings located the same eyes ([`SAME_EYES_EYE_DISTANCES`]).
fn same_eyes(a: &FaceReport, b: &FaceReport) -> bool {
    let near = SAME_EYES_EYE_DISTANCES * smaller_eye_distance(a, b);
    a.right_eye.distance(b.right_eye) < near && a.left_eye.distance(b.left_eye) < near
}

/// Settles the faces of `found` from `first_new` on, each found from the window its box is
/// (see [`window_is_new`]), against the faces before it that would have hidden that window
/// ([`proposal_is_new`]): a face sure enough ([`hides_windows`]) takes the place of the unsure
/// ones among them, unless one of those located the same eyes ([`same_eyes`]: the same face
/// read again, whose first reading's doubt stands; seen on a small face at a photo's edge,
/// refused for its pose, then read from another window with confidence 0.8 and a shear 0.28
/// off); any other face is dropped (the first reading of a spot stands).
pub(crate) fn settle_unsure_faces(found: &mut Vec<(Rect, Option<FaceReport>)>, first_new: usize) {
    let mut i = first_new;
    while i < found.len() {
        let (b, Some(r)) = found[i] else {
            i += 1;
            continue;
        };
        let window = proposal_detection_in(b);
        let hiding: Vec<usize> = (0..i)
            .filter(|&j| found[j].1.is_some_and(|h| hides(&window, &h).0))
            .collect();
        if hiding.is_empty() {
            i += 1;
        } else if hides_windows(&r)
            && !hiding
                .iter()
                .any(|&j| found[j].1.is_some_and(|h| same_eyes(&h, &r)))
        {
            let unsure: Vec<usize> = hiding
                .into_iter()
                .filter(|&j| found[j].1.is_some_and(|h| !hides_windows(&h)))
                .collect();
            for &j in unsure.iter().rev() {
                found.remove(j);
            }
            i = i + 1 - unsure.len();
        } else {
            found.remove(i);
        }
    }
}

/// Whether the face the network located from a proposal (see [`proposal_detections`]) is the
/// one its window shows: its eyes' midpoint within [`PROPOSAL_MAX_OFFSET`] of where the window
/// expects it and its eye distance within [`PROPOSAL_MAX_SCALE`] of the window's. The network
/// can walk from a window beside a face to part of it, or to another face.
pub(crate) fn proposal_shows(proposal: &Detection, face: &FaceReport) -> bool {
    let (expected_eyes, expected) = proposal_eyes(proposal);
    let distance = face.right_eye.distance(face.left_eye);
    face.right_eye
        .midpoint(face.left_eye)
        .distance(expected_eyes)
        < PROPOSAL_MAX_OFFSET * expected
        && (distance / expected).ln().abs() < PROPOSAL_MAX_SCALE.ln()
}

/// The proposal classifier's windows in `gray` (see [`ProposalNet`]) as
/// candidate boxes of at least `min_width` pixels: each the box a detector would draw around
/// the eyes the window expects, upright and unsheared, marked as a near miss (the network
/// must be as sure of it as of the cascade's near misses, [`NEAR_MISS_MIN_FACE_SCORE`]).
pub(crate) fn proposal_detections(
    net: &ProposalNet,
    gray: &GrayImage,
    min_width: f64,
) -> Vec<Detection> {
    scored_proposal_detections(net, gray, min_width, &ProposalParams::default())
        .into_iter()
        .map(|(d, _)| d)
        .collect()
}

/// The window logit from which the network detector's window needs only the landmark network's
/// usual face score ([`MIN_FACE_SCORE`]); weaker windows need [`NEAR_MISS_MIN_FACE_SCORE`], as
/// the cascade's near misses do. Chosen on the development eval (all nine shears): 1.5 finds 5
/// more faces than 2 (every shear at 99% or more) with the same false faces accepted, 1 finds
/// one more still with a sixth more unmatched ones; 4 and 8 found 0.3-0.6 points fewer.
pub(crate) const STRONG_WINDOW_LOGIT: f32 = 1.5;

/// Faces narrower than this (box width, pixels) need the strict face score whatever their
/// window's logit: most false faces are small. On the development photos with their faces
/// painted over (`eval shear --face-free --min-face 40`), photos with an accepted face fell from
/// 21 to 15 of 871 and unmatched detections at k = 0 from 63 to 31, with the same faces found
/// (their boxes are all wider than 100 px).
pub(crate) const SMALL_WINDOW_FACE_WIDTH: f64 = 80.0;

/// Whether the face the landmark network found from a window of the network detector with
/// `logit` is a face: both networks' words together (see [`STRONG_WINDOW_LOGIT`] and
/// [`SMALL_WINDOW_FACE_WIDTH`]).
pub(crate) fn window_is_face(logit: f32, face: &FaceReport) -> bool {
    let small = face.right_eye.distance(face.left_eye) / EYE_DISTANCE_PER_BOX_WIDTH
        < SMALL_WINDOW_FACE_WIDTH;
    let needed = if logit >= STRONG_WINDOW_LOGIT && !small {
        MIN_FACE_SCORE
    } else {
        NEAR_MISS_MIN_FACE_SCORE
    };
    face.face_score.is_some_and(|s| s >= needed)
}

/// The network detector's windows in `gray` for faces at least `min_width` pixels wide
/// (not below [`MIN_NETWORK_FACE`]), strongest first, each with its logit.
pub(crate) fn network_windows(
    net: &ProposalNet,
    gray: &GrayImage,
    min_width: f64,
) -> Vec<(Detection, f32)> {
    let min_width = min_width.max(f64::from(MIN_NETWORK_FACE));
    scored_proposal_detections(net, gray, min_width, &net.default_params())
}

/// [`network_windows`] in `gray` de-sheared by `k` about its middle row (on a canvas wide
/// enough to lose nothing), moved back to `gray`: each window's shear is `k` plus the shear it
/// regressed in the view. A face sheared by about `k` is upright in the view, where the
/// detector is surest of it. None when the view would be mostly padding or cannot be made
/// ([`desheared_view`]); `k = 0` is the image as it is.
pub(crate) fn network_windows_desheared(
    net: &ProposalNet,
    gray: &GrayImage,
    min_width: f64,
    k: f64,
) -> Vec<(Detection, f32)> {
    if k == 0.0 {
        return network_windows(net, gray, min_width);
    }
    let Some((view, back)) = desheared_view(gray, k, 0.0) else {
        return Vec::new();
    };
    network_windows(net, &view, min_width)
        .into_iter()
        .map(|(d, logit)| {
            let (eyes, eye_distance) = proposal_eyes(&d);
            let eyes = back.to_input(eyes);
            let moved = Detection {
                view_k: d.view_k + k,
                view_roll: d.view_roll,
                ..proposal_detection(eyes, eye_distance)
            };
            (moved, logit)
        })
        .collect()
}

/// [`proposal_detections`] with `params` (its smallest eye distance set from `min_width`), each
/// with the classifier's logit.
pub(crate) fn scored_proposal_detections(
    net: &ProposalNet,
    gray: &GrayImage,
    min_width: f64,
    params: &ProposalParams,
) -> Vec<(Detection, f32)> {
    let params = ProposalParams {
        min_eye_distance: min_width * EYE_DISTANCE_PER_BOX_WIDTH,
        ..*params
    };
    net.propose(gray, &params)
        .into_iter()
        .map(|p| {
            let d = Detection {
                view_k: p.k,
                view_roll: p.roll,
                ..proposal_detection(p.eyes_midpoint, p.eye_distance)
            };
            (d, p.logit)
        })
        .collect()
}

/// The candidate box of a proposal window expecting eyes `eye_distance` apart with their
/// midpoint at `eyes` (see [`proposal_detections`]); [`proposal_eyes`] reads them back.
pub(crate) fn proposal_detection(eyes: Point, eye_distance: f64) -> Detection {
    let width = eye_distance / EYE_DISTANCE_PER_BOX_WIDTH;
    proposal_detection_in(box_around_eyes(eyes, width, width, 0.0))
}

/// The proposal whose box is `face_box`, upright and unsheared.
fn proposal_detection_in(face_box: Rect) -> Detection {
    Detection {
        face_box,
        view_k: 0.0,
        view_roll: 0.0,
        neighbors: 0,
        near_miss: true,
    }
}

/// The box the landmark network is started from to follow `face` into the next video frame:
/// the detector's upright box around its eyes (started upright, the network measures the roll
/// itself; started at the last roll, its per-frame estimates were twice as noisy).
pub fn box_from_eyes(face: &FaceReport) -> Rect {
    let width = face.right_eye.distance(face.left_eye) / EYE_DISTANCE_PER_BOX_WIDTH;
    box_around_eyes(face.right_eye.midpoint(face.left_eye), width, width, 0.0)
}

/// How far (in its eye distances) a face may move from one video frame to the next and still
/// be the face followed.
pub const FOLLOW_MAX_MOVE: f64 = 1.0;
/// How much a followed face's eye distance may change from one video frame to the next.
pub const FOLLOW_MAX_SCALE: f64 = 1.5;

/// Whether `next`, located from `last`'s eyes in the next frame, is still that face: its eyes'
/// midpoint within [`FOLLOW_MAX_MOVE`] eye distances of the last one and its eye distance
/// within [`FOLLOW_MAX_SCALE`] of it (the network can walk from a face that left to another).
pub fn follows(last: &FaceReport, next: &FaceReport) -> bool {
    let d = last.right_eye.distance(last.left_eye);
    let moved = next
        .right_eye
        .midpoint(next.left_eye)
        .distance(last.right_eye.midpoint(last.left_eye));
    let ratio = next.right_eye.distance(next.left_eye) / d;
    moved <= FOLLOW_MAX_MOVE * d && ratio.ln().abs() <= FOLLOW_MAX_SCALE.ln()
}

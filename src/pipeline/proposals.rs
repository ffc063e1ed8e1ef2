//! Candidate faces from the proposal classifier's windows: where the window expects the eyes,
//! whether it may show a face not found yet, and whether the face found from it is the one it
//! shows.

use image::GrayImage;

use super::combine::holds_eyes;
use super::face::MIN_FACE_SCORE;
use super::report::FaceReport;
use super::search::{Detection, NEAR_MISS_MIN_FACE_SCORE};
use crate::config::MIN_NETWORK_FACE;
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

/// Whether a proposal may show a face not among `found`: its box holds the eyes of none of
/// about its size ([`PROPOSAL_MAX_SCALE`]; that face again), and its eyes are inside the box of
/// none of about its size or larger (part of that face at a smaller scale: a large face's nose
/// and nostrils can look like a small face to the classifier and the network alike). A much
/// larger window around a smaller face found is still searched: that "face" can be the nose of
/// the larger one.
pub(crate) fn proposal_is_new(proposal: &Detection, found: &[(Rect, Option<FaceReport>)]) -> bool {
    let (eyes, distance) = proposal_eyes(proposal);
    let b = proposal.face_box;
    found.iter().all(|(_, r)| {
        r.is_none_or(|r| {
            let holds_it = holds_eyes(&b, &r);
            let ratio = r.right_eye.distance(r.left_eye) / distance;
            let at_least_as_large = ratio * PROPOSAL_MAX_SCALE >= 1.0;
            let about_as_large = at_least_as_large && ratio <= PROPOSAL_MAX_SCALE;
            let same_face = holds_it && about_as_large;
            let part_of_it = at_least_as_large && r.face_box.contains(eyes);
            !(same_face || part_of_it)
        })
    })
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
    Detection {
        face_box: box_around_eyes(eyes, width, width, 0.0),
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

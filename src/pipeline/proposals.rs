//! Candidate faces from the proposal classifier's windows: where the window expects the eyes,
//! whether it may show a face not found yet, and whether the face found from it is the one it
//! shows.

use image::GrayImage;

use super::combine::holds_eyes;
use super::report::{FaceReport, FoundBox};
use super::viola_jones_search::Detection;
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

/// Whether the face `r` hides `proposal`: the window's box holds its eyes and it is about the
/// window's size ([`PROPOSAL_MAX_SCALE`]; that face again), or the window's eyes are inside its
/// box and it is about the window's size or larger (part of that face at a smaller scale: a
/// large face's nose and nostrils can look like a small face to the classifier and the network
/// alike). A much larger window around a smaller face is not hidden: that "face" can be the
/// nose of the larger one. Also says whether `r` is much larger than the window.
pub(crate) fn hides(proposal: &Detection, r: &FaceReport) -> (bool, bool) {
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
pub(crate) fn proposal_is_new(proposal: &Detection, found: &[FoundBox]) -> bool {
    found
        .iter()
        .all(|f| f.report.is_none_or(|r| !hides(proposal, &r).0))
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
pub(crate) fn proposal_detection_in(face_box: Rect) -> Detection {
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
pub(crate) fn box_from_eyes(face: &FaceReport) -> Rect {
    let width = face.right_eye.distance(face.left_eye) / EYE_DISTANCE_PER_BOX_WIDTH;
    box_around_eyes(face.right_eye.midpoint(face.left_eye), width, width, 0.0)
}

/// How far (in its eye distances) a face may move from one video frame to the next and still
/// be the face followed.
pub(crate) const FOLLOW_MAX_MOVE: f64 = 1.0;
/// How much a followed face's eye distance may change from one video frame to the next.
pub(crate) const FOLLOW_MAX_SCALE: f64 = 1.5;

/// Whether `next`, located from `last`'s eyes in the next frame, is still that face: its eyes'
/// midpoint within [`FOLLOW_MAX_MOVE`] eye distances of the last one and its eye distance
/// within [`FOLLOW_MAX_SCALE`] of it (the network can walk from a face that left to another).
pub(crate) fn follows(last: &FaceReport, next: &FaceReport) -> bool {
    let d = last.right_eye.distance(last.left_eye);
    let moved = next
        .right_eye
        .midpoint(next.left_eye)
        .distance(last.right_eye.midpoint(last.left_eye));
    let ratio = next.right_eye.distance(next.left_eye) / d;
    moved <= FOLLOW_MAX_MOVE * d && ratio.ln().abs() <= FOLLOW_MAX_SCALE.ln()
}

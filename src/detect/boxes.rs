//! Where a face's features sit in the detector's box, and the boxes drawn from them: the
//! geometry that ties a Viola-Jones box (alt2, OpenCV's parameters) to the eyes it holds.

use crate::geometry::{Point, Rect};

/// Where the subject's right eye sits in a detector box, as fractions of the box width/height:
/// the median over 2532 Caltech development faces matched to `haarcascade_frontalface_alt2`
/// detections (docs/how-it-works.md).
pub(crate) const RIGHT_EYE_IN_BOX: (f64, f64) = (0.3184, 0.397);
/// Where the subject's left eye sits in a detector box (same measurement).
pub(crate) const LEFT_EYE_IN_BOX: (f64, f64) = (0.698, 0.394);
/// Eye distance divided by the detector box width (same measurement). Used to derive a face box
/// from located eyes exactly as the detector would draw it.
pub const EYE_DISTANCE_PER_BOX_WIDTH: f64 = 0.381;

/// How many eye distances the side of a network's crop spans (the landmark network's and the
/// proposal classifier's windows): from above the brows to below the chin (the
/// eyes' midpoint sits [`EYES_ABOVE_CENTRE`] above the crop's centre, the mouth about 1.1 eye
/// distances below the eyes and the chin about 1.6).
pub const CROP_EYE_DISTANCES: f64 = 3.3;

/// How far above the crop's centre the eyes' midpoint sits, in eye distances.
pub const EYES_ABOVE_CENTRE: f64 = 0.35;

/// Where the eyes' midpoint sits in a detector box, as fractions of its width and height.
pub(crate) fn eyes_in_box() -> (f64, f64) {
    (
        (RIGHT_EYE_IN_BOX.0 + LEFT_EYE_IN_BOX.0) / 2.0,
        (RIGHT_EYE_IN_BOX.1 + LEFT_EYE_IN_BOX.1) / 2.0,
    )
}

/// The detector-style face box for a face whose eye centres are known (training crops are cut
/// from the same normalised face the detector's box gives at run time).
pub fn face_box_from_eyes(right_eye: Point, left_eye: Point) -> Rect {
    let width = right_eye.distance(left_eye) / EYE_DISTANCE_PER_BOX_WIDTH;
    let mid = right_eye.midpoint(left_eye);
    let mid_in_box = eyes_in_box();
    Rect::new(
        mid.x - mid_in_box.0 * width,
        mid.y - mid_in_box.1 * width,
        width,
        width,
    )
}

/// The `width x height` box that, turned by `roll` radians about its centre, has its eye row's
/// midpoint at `eyes`.
pub(crate) fn box_around_eyes(eyes: Point, width: f64, height: f64, roll: f64) -> Rect {
    let (at_x, at_y) = eyes_in_box();
    // The eyes' offset from the box centre, turned as the face is in the input.
    let (ox, oy) = ((at_x - 0.5) * width, (at_y - 0.5) * height);
    let (s, c) = roll.sin_cos();
    let centre = Point::new(eyes.x - (c * ox - s * oy), eyes.y - (s * ox + c * oy));
    Rect::new(
        centre.x - width / 2.0,
        centre.y - height / 2.0,
        width,
        height,
    )
}

/// Where `face_box`, turned by `roll` radians about its centre, predicts the eyes' midpoint
/// (the inverse of [`box_around_eyes`]).
pub(crate) fn eyes_of_box(face_box: Rect, roll: f64) -> Point {
    let (at_x, at_y) = eyes_in_box();
    let centre = face_box.center();
    let (ox, oy) = (
        (at_x - 0.5) * face_box.width,
        (at_y - 0.5) * face_box.height,
    );
    let (s, c) = roll.sin_cos();
    Point::new(centre.x + c * ox - s * oy, centre.y + s * ox + c * oy)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_from_eyes_puts_the_eyes_where_the_detector_does() {
        let (r, l) = (Point::new(100.0, 80.0), Point::new(138.1, 80.0));
        let b = face_box_from_eyes(r, l);
        assert!((b.width - 100.0).abs() < 1e-9, "{b:?}");
        let mid = eyes_of_box(b, 0.0);
        assert!(mid.distance(r.midpoint(l)) < 1e-9, "{mid:?}");
    }

    #[test]
    fn box_around_eyes_inverts_eyes_of_box_at_any_roll() {
        for roll in [-0.8, -0.2, 0.0, 0.4, 1.0] {
            let eyes = Point::new(50.0, 70.0);
            let b = box_around_eyes(eyes, 80.0, 90.0, roll);
            assert!(eyes_of_box(b, roll).distance(eyes) < 1e-9, "roll {roll}");
        }
    }
}

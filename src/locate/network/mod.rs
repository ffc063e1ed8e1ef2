//! Facial landmarks (both eye centres, the nose point and the mouth centre) located by a small
//! convolutional network in a crop of the face, and the shear read off the same crop.
//!
//! The network is trained by this project (`scripts/train_landmarks.py`, on crops that
//! `dev::landmark_crops::export_crops` cuts from the Caltech development faces) with the crops sheared
//! and turned at random, so that it has no preference for an unsheared face: a landmark model
//! trained on upright faces only pulls its points back towards an upright face and under-reads
//! the shear. Where the crop comes from is described by a [`CropFrame`]; the same frame maps
//! the points back to the image.

mod crop;
mod net;

#[cfg(feature = "dev")]
pub(crate) use crop::crop_shear;
pub(crate) use crop::residual_from_crop_shear;
pub use crop::CropFrame;
#[cfg(feature = "dev")]
pub(crate) use net::RUNS;
pub use net::{LandmarkNet, NetOutput, Workspace};

use crate::estimate::{shear_and_roll, yaw_corrected};
use crate::geometry::Point;

/// Side of the crop the network sees, pixels.
#[cfg(feature = "dev")]
pub(crate) const CROP_SIZE: usize = 96;

pub(crate) use crate::detect::boxes::{CROP_EYE_DISTANCES, EYES_ABOVE_CENTRE};

/// The crop frame that shows a face whose eyes' midpoint is at `eyes_midpoint` (image pixels)
/// and whose eyes are `eye_distance` apart in the upright, unsheared face, with the shear `k`
/// and the roll `roll` (radians) removed, `size` pixels square: the eyes' midpoint lands
/// [`EYES_ABOVE_CENTRE`] eye distances above the crop's centre, and the eyes
/// `size / CROP_EYE_DISTANCES` crop pixels apart.
pub fn frame_around_eyes(
    eyes_midpoint: Point,
    eye_distance: f64,
    k: f64,
    roll: f64,
    size: usize,
) -> CropFrame {
    frame_with_geometry(
        eyes_midpoint,
        eye_distance,
        k,
        roll,
        (size, CROP_EYE_DISTANCES, EYES_ABOVE_CENTRE),
    )
}

/// [`frame_around_eyes`] for a crop geometry of (side, eye distances across it, eyes'
/// midpoint above its centre in eye distances).
fn frame_with_geometry(
    eyes_midpoint: Point,
    eye_distance: f64,
    k: f64,
    roll: f64,
    (size, eye_distances, eyes_above_centre): (usize, f64, f64),
) -> CropFrame {
    let mut frame = CropFrame {
        centre: eyes_midpoint,
        scale: eye_distance * eye_distances / size as f64,
        k,
        roll,
        size,
    };
    // Move the centre so that the crop point of the eyes shows `eyes_midpoint`.
    let o = frame.crop_centre();
    let eyes_in_crop = Point::new(o, o - eyes_above_centre * size as f64 / eye_distances);
    let shown = frame.to_image(eyes_in_crop);
    frame.centre = Point::new(
        2.0 * eyes_midpoint.x - shown.x,
        2.0 * eyes_midpoint.y - shown.y,
    );
    frame
}

/// How far the mouth axis's shear is extrapolated away from the nose axis's to cancel yaw, for
/// the network's points (see [`crate::estimate::yaw_corrected`]). Not tuned (the filters' value
/// when the network was added): with [`NETWORK_SHEAR_WEIGHT`] at 1 the points' shear only feeds
/// the confidence feature `|k_network - k_points|`, whose weight is fitted with it.
pub(crate) const NETWORK_YAW_EXTRAPOLATION: f64 = 0.3;

/// The weight of the network's own reading of the shear in the estimate; the rest is the shear
/// the located points give ([`LocatedFace::k_points`]).
pub(crate) const NETWORK_SHEAR_WEIGHT: f64 = 1.0;

/// Most crops per face ([`locate_within`]).
pub(crate) const MAX_PASSES: usize = 8;

/// How much work `locate_within` may spend on one face: the most crops, the most reads per
/// crop pixel and axis when rendering them (`CropFrame::render_with`), and how little the
/// estimate must change for it to stop re-cropping.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Budget {
    /// Most crops per face.
    pub max_passes: usize,
    /// Most reads per crop pixel and axis.
    pub max_supersampling: usize,
    /// Change of the estimated shear below which it stops (0.03 for stills).
    pub shear_tolerance: f64,
    /// Change of the estimated roll, radians, below which it stops (0.05 for stills).
    pub roll_tolerance: f64,
    /// Whether each crop is also read mirrored and the two readings averaged
    /// (`LandmarkNet::averaged_with_mirrored`): twice the network's time per crop for steadier points.
    /// A crop that reads as no face (a face score under 0.001) is not read again. Used with the
    /// network detector only (the Viola-Jones searches read once).
    pub mirrored: bool,
}

impl Budget {
    /// For stills (what `locate_within` uses): up to 8 crops, stopping when the shear changes by
    /// less than 0.03 and the roll by less than 0.05 rad from one crop to the next, each crop
    /// read as it is and mirrored.
    pub const STILL: Self = Self {
        max_passes: MAX_PASSES,
        max_supersampling: crop::MAX_SUPERSAMPLING,
        shear_tolerance: SHEAR_TOLERANCE,
        roll_tolerance: ROLL_TOLERANCE,
        mirrored: true,
    };

    /// For video, where a temporal filter averages the frames' estimates and the frame rate
    /// matters: 2 crops (the first from the tracker's box, the second around the eyes found
    /// there), 2 reads per axis, and tighter tolerances so that a frame almost always takes its
    /// second crop (docs/video.md); each crop read once, not also mirrored.
    pub const VIDEO: Self = Self {
        max_passes: 2,
        max_supersampling: 2,
        shear_tolerance: VIDEO_SHEAR_TOLERANCE,
        roll_tolerance: VIDEO_ROLL_TOLERANCE,
        mirrored: false,
    };
}

impl Default for Budget {
    fn default() -> Self {
        Self::STILL
    }
}

/// Change of the estimated shear below which [`locate_within`] stops re-cropping: what is left is read
/// by the network instead of removed by the crop, about as well; a tighter tolerance buys
/// consistency between starts for more crops (docs/how-it-works.md).
pub(crate) const SHEAR_TOLERANCE: f64 = 0.03;

/// [`Budget::VIDEO`]'s shear tolerance: with the stills' looser one a frame often stops at its
/// first crop, made from the tracker's box, whose reading moves with the box from frame to frame.
pub(crate) const VIDEO_SHEAR_TOLERANCE: f64 = 0.01;

/// [`Budget::VIDEO`]'s roll tolerance, radians.
pub(crate) const VIDEO_ROLL_TOLERANCE: f64 = 0.02;

/// How many crops [`locate_within`] makes of something that is not a face before it gives up: when
/// the face score of each of the first `NO_FACE_PASSES` crops is below [`NO_FACE_SCORE`], the
/// last reading is returned. Most boxes the thorough search asks about are not faces, and their
/// crops never settle.
pub(crate) const NO_FACE_PASSES: usize = 3;

/// From this crop on, the walk of crops stops when the shear changed no less than at the crop
/// before (`stalled` in this module): the estimate is no longer closing in on a fixed point, and
/// further crops cost time without settling it.
pub(crate) const STALL_PASSES: usize = 3;

/// Whether a walk of crops has stalled at crop `pass` (1 for the first): from [`STALL_PASSES`]
/// on, the estimated shear changed by `change` at this crop and by `previous_change` at the
/// one before, and did not shrink.
fn stalled(pass: usize, change: f64, previous_change: f64) -> bool {
    pass >= STALL_PASSES && change >= previous_change
}

/// The face score under which a crop counts as showing no face for [`NO_FACE_PASSES`]: the
/// network's face score on non-face crops is mostly below 0.001, on faces mostly above 0.9.
pub(crate) const NO_FACE_SCORE: f64 = 0.001;

/// How many crops [`locate_within`] makes of something that is hardly a face: when neither of
/// the first `UNLIKELY_FACE_PASSES` crops reads above [`UNLIKELY_FACE_SCORE`], the last reading
/// is returned. Most windows of a cluttered frame read 0.001-0.5 and wander for three or four
/// crops; a face that reads that low twice seldom ends as one (on the first 300 development
/// photos at k = 0 and +-0.40, 2 of 881 faces found came from such a start, against 1,263 of
/// 6,399 crops saved), and the face score a face needs is 0.9.
pub(crate) const UNLIKELY_FACE_PASSES: usize = 2;

/// The face score under which a crop counts as hardly a face for [`UNLIKELY_FACE_PASSES`].
pub(crate) const UNLIKELY_FACE_SCORE: f64 = 0.1;

/// Whether a walk of crops gives up on something that is not a face after crop `pass` (1 for
/// the first), the best face score of its crops so far being `best_face_score`: after
/// [`NO_FACE_PASSES`] crops all under [`NO_FACE_SCORE`], after [`UNLIKELY_FACE_PASSES`] all
/// under [`UNLIKELY_FACE_SCORE`], or at the first crop when it reads under
/// `first_crop_min_face` (the caller's doubt about the start, such as a detector window's;
/// 0: no such doubt).
fn gives_up(pass: usize, best_face_score: f64, first_crop_min_face: f64) -> bool {
    (pass >= NO_FACE_PASSES && best_face_score < NO_FACE_SCORE)
        || (pass >= UNLIKELY_FACE_PASSES && best_face_score < UNLIKELY_FACE_SCORE)
        || (pass == 1 && best_face_score < first_crop_min_face)
}

/// The face score from which a crop read as it is is read again mirrored (with
/// [`Budget::mirrored`]): the mirrored reading steadies the points of a face, while a crop
/// reading under this is most often not one (a third of a cluttered frame's network runs).
pub(crate) const MIRROR_MIN_FACE_SCORE: f64 = 0.5;

/// Change of the estimated roll (radians, about 2.9 degrees) below which [`locate_within`] stops.
pub(crate) const ROLL_TOLERANCE: f64 = 0.05;

/// The largest shear [`locate_within`] will crop with (as the filters' `MAX_SHEAR`).
pub(crate) const MAX_CROP_SHEAR: f64 = 0.8;

/// What the network found in one face, image pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct LocatedFace {
    /// Subject's right eye centre (image left).
    pub(crate) right_eye: Point,
    /// Subject's left eye centre (image right).
    pub(crate) left_eye: Point,
    /// The nose point (Caltech's nose annotation: the lower nose).
    pub(crate) nose: Point,
    /// The mouth centre.
    pub(crate) mouth: Point,
    /// The shear the points give: the mouth axis's shear-and-roll reading extrapolated away from
    /// the nose axis's by 0.3 to cancel yaw; `None` when the points allow none.
    pub(crate) k_points: Option<f64>,
    /// The nose axis's own reading.
    pub(crate) k_nose: Option<f64>,
    /// The mouth axis's own reading.
    pub(crate) k_mouth: Option<f64>,
    /// The network's own reading of the shear, in the image's frame (`k_points` where the
    /// crop's roll leaves no image shear for that reading, near 45 degrees).
    pub(crate) k_network: f64,
    /// The estimate: the network's own reading `k_network`, weighted against `k_points` by
    /// the network shear weight (1: `k_network` alone).
    pub(crate) k: f64,
    /// The head's roll under that shear, radians (as [`crate::estimate::ShearRoll::roll`]).
    pub(crate) roll: f64,
    /// Each heatmap's spread (right eye, left eye, nose, mouth) in eye distances of the crop.
    pub(crate) spread: [f64; 4],
    /// The network's face score on the last crop: the chance that it shows a face at all.
    pub(crate) face: f64,
    /// Crops made.
    pub(crate) passes: usize,
    /// The frame of the last crop.
    pub(crate) frame: CropFrame,
}

impl LandmarkNet {
    /// The crop frame of this network's geometry around eyes at `eyes_midpoint`, `eye_distance`
    /// apart in the upright face, with `k` and `roll` removed (see [`frame_around_eyes`]).
    pub fn frame(&self, eyes_midpoint: Point, eye_distance: f64, k: f64, roll: f64) -> CropFrame {
        frame_with_geometry(
            eyes_midpoint,
            eye_distance,
            k,
            roll,
            (
                self.size(),
                self.crop_eye_distances(),
                self.eyes_above_centre(),
            ),
        )
    }
}

/// The distance between two image points in the face de-sheared by `k` (turning it upright
/// does not change distances): the eye distance of the upright face.
fn upright_distance(a: Point, b: Point, k: f64) -> f64 {
    let (dx, dy) = (b.x - a.x - k * (b.y - a.y), b.y - a.y);
    dx.hypot(dy).max(f64::MIN_POSITIVE)
}

/// [`locate_within`] with the stills' budget ([`Budget::STILL`]).
#[cfg(test)]
pub(crate) fn locate(
    net: &LandmarkNet,
    gray: &image::GrayImage,
    start: CropFrame,
    ws: &mut Workspace,
) -> Option<LocatedFace> {
    locate_within(net, gray, start, Budget::STILL, 0.0, ws)
}

/// Locates the landmarks of the face that `start` frames (from a detector's box, or a previous
/// estimate) and estimates its shear: the network reads a crop, the shear and roll are
/// estimated from what it found, and the face is cropped again around the eyes found with
/// that shear and roll removed, until the estimate stops changing (below the budget's tolerances) or after the budget's
/// crops (at least one, each rendered with at most its reads per pixel). The
/// network then sees a nearly upright, unsheared face, the kind it reads best. A walk whose
/// estimate stops closing in is ended too, and something that is not a face is given up on
/// after two or three crops ([`gives_up`]), or after the first when a start in doubt (a detector
/// window) reads under `first_crop_min_face` there (0: no such doubt). `None` when
/// a crop cannot be made or the network's reading is not finite.
pub(crate) fn locate_within(
    net: &LandmarkNet,
    gray: &image::GrayImage,
    start: CropFrame,
    budget: Budget,
    first_crop_min_face: f64,
    ws: &mut Workspace,
) -> Option<LocatedFace> {
    let mut frame = start;
    let mut found = None;
    let mut best_face_score = f64::NEG_INFINITY;
    let mut previous_change = f64::INFINITY;
    for pass in 1..=budget.max_passes.max(1) {
        let crop = frame.render_with(gray, budget.max_supersampling)?;
        let direct = net.run(&crop, ws);
        // A crop that reads as no face as it is is not read again mirrored: most windows of
        // a face-free frame, at half the cost.
        let out = if budget.mirrored && direct.face >= MIRROR_MIN_FACE_SCORE {
            net.averaged_with_mirrored(direct, &crop, ws)
        } else {
            direct
        };
        let face = read_face(net, &out, frame, pass)?;
        let change = (face.k - frame.k).abs();
        let converged = change < budget.shear_tolerance
            && (face.roll - frame.roll).abs() < budget.roll_tolerance;
        best_face_score = best_face_score.max(face.face);
        let no_face = gives_up(pass, best_face_score, first_crop_min_face);
        let stalled = stalled(pass, change, previous_change);
        previous_change = change;
        found = Some(face);
        if converged || no_face || stalled {
            break;
        }
        let distance = upright_distance(face.right_eye, face.left_eye, face.k);
        let next = net.frame(
            face.right_eye.midpoint(face.left_eye),
            distance,
            face.k.clamp(-MAX_CROP_SHEAR, MAX_CROP_SHEAR),
            face.roll,
        );
        if !next.is_valid() {
            break;
        }
        frame = next;
    }
    found
}

/// The face the network's output on the crop of `frame` describes.
fn read_face(
    net: &LandmarkNet,
    out: &NetOutput,
    frame: CropFrame,
    passes: usize,
) -> Option<LocatedFace> {
    let [right_eye, left_eye, nose, mouth] = out.points.map(|p| frame.to_image(p));
    // Near 45 degrees of roll an image shear barely changes the crop's own shear, and some
    // readings have no image shear at all; the points' shear stands in there.
    let residual = residual_from_crop_shear(out.shear, frame.roll);
    let eye_line = Point::new(left_eye.x - right_eye.x, left_eye.y - right_eye.y);
    let mid = right_eye.midpoint(left_eye);
    let axis = |p: Point| Point::new(p.x - mid.x, p.y - mid.y);
    let k_nose = shear_and_roll(eye_line, axis(nose)).map(|s| s.k);
    let k_mouth = shear_and_roll(eye_line, axis(mouth)).map(|s| s.k);
    let k_points = match (k_nose, k_mouth) {
        (Some(n), Some(m)) => Some(yaw_corrected(n, m, NETWORK_YAW_EXTRAPOLATION)),
        (None, Some(m)) => Some(m),
        (Some(n), None) => Some(n),
        (None, None) => None,
    };
    let k_network = match residual {
        Some(r) => frame.k + r,
        None => k_points?,
    };
    if !k_network.is_finite() {
        return None;
    }
    let k = match k_points {
        Some(p) => NETWORK_SHEAR_WEIGHT * k_network + (1.0 - NETWORK_SHEAR_WEIGHT) * p,
        None => k_network,
    };
    let roll = eye_line.y.atan2(eye_line.x - k * eye_line.y);
    let unit = net.size() as f64 / net.crop_eye_distances();
    Some(LocatedFace {
        right_eye,
        left_eye,
        nose,
        mouth,
        k_points,
        k_nose,
        k_mouth,
        k_network,
        k,
        roll,
        spread: out.spread.map(|s| s / unit),
        face: out.face,
        passes,
        frame,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The committed Yale fixture face, grey.
    fn fixture_gray() -> image::GrayImage {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/fixtures/faces/subject01.normal.jpeg"
        );
        image::open(path).expect("fixture").into_luma8()
    }

    /// A rough start on the fixture (off the face's middle, too small, a wrong shear of -0.4
    /// and roll of 0.3 rad), so that the stills' budget takes more than two crops to settle
    /// (three with this network and tolerance).
    fn rough_start(net: &LandmarkNet) -> CropFrame {
        net.frame(Point::new(170.0, 110.0), 45.0, -0.4, 0.3)
    }

    #[test]
    fn the_estimate_hardly_depends_on_the_start() {
        // Six starts: off-centre, too large or too small, with wrong shears and rolls. With
        // `SHEAR_TOLERANCE` 0.03 the fixture's estimates spread over 0.019 (0.016 to 0.035, the
        // outlier the start rolled by 0.3 rad); with 0.01 over 0.018, with 0.001 over 0.001.
        // The bound is the measured spread with some room, so that a looser stopping rule or a
        // worse iteration fails here.
        let net = LandmarkNet::embedded().expect("built-in network");
        let gray = fixture_gray();
        let mut ws = Workspace::default();
        let estimates: Vec<f64> = [
            (160.0, 100.0, 60.0, 0.0, 0.0),
            (160.0, 100.0, 60.0, 0.4, 0.0),
            (160.0, 100.0, 60.0, -0.4, 0.0),
            (150.0, 120.0, 80.0, 0.3, 0.2),
            (170.0, 90.0, 40.0, -0.3, -0.2),
            (160.0, 100.0, 60.0, 0.0, 0.3),
        ]
        .into_iter()
        .map(|(x, y, d, k, roll)| {
            let start = net.frame(Point::new(x, y), d, k, roll);
            let found = locate(&net, &gray, start, &mut ws).expect("a face");
            assert!(found.face > 0.9, "face score {}", found.face);
            found.k
        })
        .collect();
        let lo = estimates.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = estimates.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        assert!(hi - lo < 0.025, "estimates {estimates:?}");
    }

    #[test]
    fn a_walk_stalls_when_its_change_stops_shrinking_from_the_third_crop() {
        assert_eq!(STALL_PASSES, 3);
        // The first two crops never stall, whatever the changes.
        assert!(!stalled(1, 0.2, f64::INFINITY));
        assert!(!stalled(2, 0.2, 0.1));
        // From the third: a shrinking change goes on, an equal or growing one stops.
        assert!(!stalled(3, 0.05, 0.1));
        assert!(stalled(3, 0.1, 0.1));
        assert!(stalled(4, 0.12, 0.1));
        assert!(!stalled(8, 0.031, 0.04));
    }

    #[test]
    fn a_walk_gives_up_on_what_reads_as_no_face() {
        // Without doubt about the start: after three crops under 0.001, or two under 0.1.
        assert!(!gives_up(1, 0.0, 0.0));
        assert!(!gives_up(UNLIKELY_FACE_PASSES - 1, 0.0009, 0.0));
        assert!(gives_up(UNLIKELY_FACE_PASSES, 0.099, 0.0));
        assert!(!gives_up(UNLIKELY_FACE_PASSES, 0.1, 0.0));
        assert!(gives_up(NO_FACE_PASSES, 0.0009, 0.0));
        assert!(!gives_up(8, 0.5, 0.0));
        // A doubted start ends at its first crop when that reads under the bound, and only
        // at the first: from the second on, the usual rules.
        assert!(gives_up(1, 0.009, 0.01));
        assert!(!gives_up(1, 0.01, 0.01));
        assert!(!gives_up(1, 0.5, 0.01));
        assert!(gives_up(UNLIKELY_FACE_PASSES, 0.05, 0.01));
        assert!(!gives_up(UNLIKELY_FACE_PASSES, 0.2, 0.01));
    }

    #[test]
    fn a_doubted_start_on_a_face_is_followed_as_any() {
        // The fixture face's first crop from the rough start reads as a face: the doubt
        // changes nothing. On a flat grey picture the first crop ends the walk.
        let net = LandmarkNet::embedded().expect("built-in network");
        let start = rough_start(&net);
        let mut ws = Workspace::default();
        let gray = fixture_gray();
        let face = locate(&net, &gray, start, &mut ws).expect("a face");
        let doubted = locate_within(&net, &gray, start, Budget::STILL, 0.1, &mut ws);
        assert_eq!(Some(face), doubted);
        let flat = image::GrayImage::from_pixel(320, 240, image::Luma([128]));
        let found =
            locate_within(&net, &flat, start, Budget::STILL, 0.01, &mut ws).expect("a reading");
        assert!(found.face < 0.01, "face score {}", found.face);
        assert_eq!(found.passes, 1);
    }

    #[test]
    fn the_budget_limits_the_crops() {
        let net = LandmarkNet::embedded().expect("built-in network");
        let gray = fixture_gray();
        let start = rough_start(&net);
        let mut ws = Workspace::default();
        let still = locate(&net, &gray, start, &mut ws).expect("a face");
        assert!(still.passes > 2, "{} crops", still.passes);
        let video = locate_within(&net, &gray, start, Budget::VIDEO, 0.0, &mut ws).expect("a face");
        assert_eq!(video.passes, 2);
        let none = Budget {
            max_passes: 0,
            max_supersampling: 0,
            ..Budget::STILL
        };
        let once = locate_within(&net, &gray, start, none, 0.0, &mut ws).expect("a face");
        assert_eq!(once.passes, 1, "at least one crop");
    }

    #[test]
    fn something_that_is_not_a_face_is_given_up_on_early() {
        let net = LandmarkNet::embedded().expect("built-in network");
        let start = rough_start(&net);
        let mut ws = Workspace::default();
        // Uniform noise (a fixed linear congruential sequence): texture, and no face in it.
        let mut state = 12345u32;
        let noise = image::GrayImage::from_fn(320, 240, |_, _| {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            image::Luma([(state >> 24) as u8])
        });
        let flat = image::GrayImage::from_pixel(320, 240, image::Luma([128]));
        let read_once = Budget {
            mirrored: false,
            ..Budget::STILL
        };
        for no_face in [&noise, &flat] {
            let found = locate(&net, no_face, start, &mut ws).expect("a reading");
            assert!(found.face < NO_FACE_SCORE, "face score {}", found.face);
            assert!(found.passes <= NO_FACE_PASSES, "{} crops", found.passes);
            // No crop read as a face, so none was read again mirrored.
            let once = locate_within(&net, no_face, start, read_once, 0.0, &mut ws);
            assert_eq!(Some(found), once);
        }
        // A face from the same rough start is followed to the end (as in
        // `the_budget_limits_the_crops`), and scores as one; its crops are read mirrored too.
        let face = locate(&net, &fixture_gray(), start, &mut ws).expect("a face");
        assert!(face.face > 0.9, "face score {}", face.face);
        let once = locate_within(&net, &fixture_gray(), start, read_once, 0.0, &mut ws);
        assert_ne!(Some(face), once);
        // It stopped because its estimate settled, not because it was given up on.
        assert!(
            (face.k - face.frame.k).abs() < SHEAR_TOLERANCE
                && (face.roll - face.frame.roll).abs() < ROLL_TOLERANCE,
            "{face:?}"
        );
    }

    #[test]
    fn the_eyes_land_where_the_frame_puts_them() {
        for (k, roll) in [(0.0, 0.0), (0.3, 0.0), (-0.2, 0.25)] {
            let f = frame_around_eyes(Point::new(120.0, 80.0), 40.0, k, roll, 96);
            let o = f.crop_centre();
            let eyes = f.from_image(Point::new(120.0, 80.0));
            let expected_y = o - EYES_ABOVE_CENTRE * 96.0 / CROP_EYE_DISTANCES;
            assert!((eyes.x - o).abs() < 1e-9 && (eyes.y - expected_y).abs() < 1e-9);
            // An upright face's eyes, turned and sheared as the frame says, are
            // size / CROP_EYE_DISTANCES apart in the crop.
            let (s, c) = roll.sin_cos();
            let turned = |dx: f64| Point::new(120.0 + c * dx, 80.0 + s * dx);
            let sheared = |p: Point| Point::new(p.x + k * (p.y - 80.0), p.y);
            let (r, l) = (
                f.from_image(sheared(turned(-20.0))),
                f.from_image(sheared(turned(20.0))),
            );
            assert!((r.distance(l) - 96.0 / CROP_EYE_DISTANCES).abs() < 1e-9);
            assert!((r.y - l.y).abs() < 1e-9, "level in the crop");
        }
    }
}

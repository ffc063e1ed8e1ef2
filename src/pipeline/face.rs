//! One face end to end: the features located in its box (by the landmark network, or by the
//! filters with their second searches), and the shear estimated from them.

use std::cell::RefCell;

use image::GrayImage;

use super::confidence::{
    confidence, network_confidence, plausibility, ConfidenceModel, Doubt, LocatedPoints,
};
use super::report::{FaceReport, Refusal};
use super::viola_jones_search::Detection;
use super::Unshear;
use crate::config::Locator;
use crate::detect::boxes::{eyes_of_box, face_box_from_eyes, EYE_DISTANCE_PER_BOX_WIDTH};
use crate::estimate::{estimate_face, shear_and_roll, FeatureGeometry};
use crate::filters::Correlator;
use crate::geometry::{Point, Rect};
use crate::locate::filters::{nostril_band, FacePoints, FeatureLocator, NormalizedFace};
use crate::locate::network::{self, Budget, LandmarkNet, LocatedFace};

/// How far (degrees) the roll measured on a face may be from the roll its features were searched
/// at before the filters search it again in the face turned upright by it: the filters were
/// trained on nearly upright faces. Chosen on development faces (docs/how-it-works.md).
pub(crate) const REALIGN_ROLL_DEGREES: f64 = 2.5;

/// How far (as a fraction) the located eye distance over the box width may be from
/// [`EYE_DISTANCE_PER_BOX_WIDTH`] before the filters search again in the box scaled to the eyes
/// found: the filters were trained at one scale, and detector boxes vary by about 9%.
pub(crate) const RESCALE_EYE_RATIO: f64 = 0.05;

/// Most searches in a face turned upright by its measured roll (see [`REALIGN_ROLL_DEGREES`]):
/// a strongly rolled face's first roll reading is short of the truth (its features were searched
/// for upright), so the next search, turned by it, reads more of the roll.
pub(crate) const REALIGN_PASSES: usize = 3;

/// The network's face score below which a detection is taken for something else and dropped:
/// the score is the network's chance that its crop shows a face; true faces of the development set
/// almost all score above 0.9, and textured wall beside a face scored 0.73.
pub(crate) const MIN_FACE_SCORE: f64 = 0.9;

/// The face score from which a network detector window's reading short of [`MIN_FACE_SCORE`]
/// is doubtful: once every window has been judged, such a window that no face found explains
/// is read again from starts turned [`RETRY_ROLL_DEGREES`] each way (`Unshear::read_box`). The
/// network, started upright on a small face rolled about 15 degrees and sheared by 0.4, can
/// settle on a reading that trades roll for shear (one eye 12 px off, score 0.85) and lose a
/// face found at k = 0. A face found so is reported with its estimate refused
/// ([`Refusal::UnreliablePose`]) and no confidence: where its reading starts decides it. On the
/// development eval (nine shears) 0.7 found 1-2 more faces at every shear but k = 0, with the
/// same estimates; read again in place, it had also accepted three false faces (a dress print,
/// two knobs, hair); 0.5 reported a fifth more unmatched detections.
pub(crate) const RETRY_MIN_FACE_SCORE: f64 = 0.7;

/// How far (degrees) the second and third starts of a doubtful reading are turned
/// ([`RETRY_MIN_FACE_SCORE`]).
pub(crate) const RETRY_ROLL_DEGREES: f64 = 15.0;

thread_local! {
    /// One correlator (FFT plans and buffers) per thread, reused by every face it processes.
    static CORRELATOR: RefCell<Option<Correlator>> = const { RefCell::new(None) };
    /// One landmark-network workspace per thread.
    static NET_WORKSPACE: RefCell<network::Workspace> = RefCell::new(network::Workspace::default());
}

/// What the landmark network read in one box ([`Unshear::read_box`]).
// As large as the `Result<FaceReport, _>` it names: a reading is moved a few times, not stored.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum BoxReading {
    /// A face, with its estimate (which may be refused).
    Face(FaceReport),
    /// No face: nothing read, or a face score well short of a face's.
    NoFace,
    /// No face, but a face score short of a face's by little ([`RETRY_MIN_FACE_SCORE`]): worth
    /// reading again from turned starts.
    Doubtful,
}

impl BoxReading {
    /// The face read, if any.
    pub(crate) fn face(self) -> Option<FaceReport> {
        match self {
            Self::Face(r) => Some(r),
            Self::NoFace | Self::Doubtful => None,
        }
    }
}

/// Where to start locating one face's features (see [`Unshear::estimate_face`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FaceStart {
    /// A shear already known roughly (a view's, or the previous video frame's): the features
    /// are first searched in the face de-sheared by it.
    pub k: f64,
    /// The head roll, radians, the box is turned by about its centre (where a turned view
    /// found the face).
    pub roll: f64,
    /// The landmark network's work on this face; `None`: the corrector's
    /// ([`Config::network_budget`](crate::Config::network_budget)). The filters have none.
    pub budget: Option<Budget>,
}

impl Unshear {
    /// Locates the features in one face box and estimates its shear, starting from `start`;
    /// `None` when the box shows no face (the network's face score) or the points allow no
    /// estimate.
    ///
    /// With the filters, while the roll measured differs from the roll searched at by
    /// a few degrees or more the features are searched again in the face turned
    /// upright by it, and once more in the box scaled to the eyes found; the most confident
    /// estimate is kept. The network crops again around the eyes it finds until the estimate
    /// settles.
    pub fn estimate_face(
        &self,
        gray: &GrayImage,
        face_box: Rect,
        start: FaceStart,
    ) -> Option<FaceReport> {
        let budget = start.budget.unwrap_or(self.config.network_budget);
        self.estimate_turned_within(gray, face_box, start.k, start.roll, budget)
    }

    /// [`Self::estimate_face`] for a detection, starting from the view it was found in.
    pub(crate) fn estimate_detection(
        &self,
        gray: &GrayImage,
        detection: &Detection,
    ) -> Option<FaceReport> {
        self.estimate_turned_within(
            gray,
            detection.face_box,
            detection.view_k,
            detection.view_roll,
            self.config.network_budget,
        )
    }

    /// [`Self::estimate_face_in_turned_view`] with the landmark network limited to `budget`
    /// (the filters have no budget).
    fn estimate_turned_within(
        &self,
        gray: &GrayImage,
        face_box: Rect,
        start_k: f64,
        roll: f64,
        budget: Budget,
    ) -> Option<FaceReport> {
        if self.locator() == Locator::Network {
            let net = &self.network;
            return self
                .network_reading(net, gray, face_box, start_k, roll, budget, false, 0.0)
                .face();
        }
        let mut best = self.locate_and_estimate(gray, face_box, start_k, roll)?;
        let (mut last, mut searched_roll) = (best, roll);
        let mut best_roll = roll;
        for _ in 0..REALIGN_PASSES {
            let measured_roll = last.roll_degrees.to_radians();
            if (measured_roll - searched_roll).abs() < REALIGN_ROLL_DEGREES.to_radians()
                || !measured_roll.is_finite()
            {
                break;
            }
            // The detector's box, turned about its centre: re-centring it on the eyes found
            // measured worse (see REALIGN_ROLL_DEGREES).
            let Some(next) =
                self.locate_and_estimate(gray, face_box, last.k_measured, measured_roll)
            else {
                break;
            };
            if next.confidence > best.confidence {
                best = next;
                best_roll = measured_roll;
            }
            (last, searched_roll) = (next, measured_roll);
        }
        // The box scaled about its centre to the eyes found (see RESCALE_EYE_RATIO).
        let ratio =
            best.right_eye.distance(best.left_eye) / face_box.width / EYE_DISTANCE_PER_BOX_WIDTH;
        if (ratio - 1.0).abs() >= RESCALE_EYE_RATIO && (0.5..2.0).contains(&ratio) {
            let scaled = face_box.scaled_about_center(ratio);
            let next =
                self.locate_and_estimate_in(gray, scaled, face_box, best.k_measured, best_roll);
            if let Some(next) = next.filter(|n| n.confidence > best.confidence) {
                best = next;
            }
        }
        Some(best)
    }

    /// The features located in `face_box` turned by `roll` (see
    /// [`Self::estimate_face_in_turned_view`]), starting from the view de-sheared by `start_k`,
    /// and the estimate from them.
    fn locate_and_estimate(
        &self,
        gray: &GrayImage,
        face_box: Rect,
        start_k: f64,
        roll: f64,
    ) -> Option<FaceReport> {
        self.locate_and_estimate_in(gray, face_box, face_box, start_k, roll)
    }

    /// [`Self::locate_and_estimate`] with the features searched in `search_box` while the
    /// report, and the confidence's eye-distance term, keep the detector's `face_box`.
    fn locate_and_estimate_in(
        &self,
        gray: &GrayImage,
        search_box: Rect,
        face_box: Rect,
        start_k: f64,
        roll: f64,
    ) -> Option<FaceReport> {
        if !can_search(gray, search_box) {
            return None;
        }
        let face = NormalizedFace::rotated(gray, search_box, roll);
        let size = self.filters.size();
        let points = CORRELATOR.with(|cell| {
            let mut slot = cell.borrow_mut();
            let correlator = match slot.take() {
                Some(c) if c.size() == size => c,
                _ => Correlator::new(size),
            };
            let mut locator = FeatureLocator::with_correlator(&self.filters, correlator);
            let mut points = locator.locate_from(&face, start_k);
            for _ in 0..self.config.refinements {
                match estimate_face(&geometry(&points), self.config.shear_model) {
                    Some(e) => {
                        // The nose filter ran in the first pass only; its point stays.
                        points = FacePoints {
                            nose_tip: points.nose_tip,
                            nose_tip_psr: points.nose_tip_psr,
                            ..locator.locate(&face, Some(e.k))
                        }
                    }
                    None => break,
                }
            }
            *slot = Some(locator.into_correlator());
            points
        });
        let estimate = estimate_face(&geometry(&points), self.config.shear_model)?;
        let psr = [
            points.psr[0],
            points.psr[1],
            points.psr[2],
            points.psr[3],
            points.mouth_psr,
        ];
        let model = ConfidenceModel::for_filters(self.filters.kind);
        let learned = confidence(&points, &estimate, face_box, &model);
        let located = LocatedPoints {
            face_box,
            right_eye: points.right_eye,
            left_eye: points.left_eye,
            nose: points.nose_tip,
            mouth: points.mouth,
            k: estimate.k,
            roll: estimate.roll,
            nose_mouth_spread: None,
        };
        let (k, confidence, refused) = self.verdict(gray, &located, learned);
        Some(FaceReport {
            face_box,
            right_eye: points.right_eye,
            left_eye: points.left_eye,
            right_nostril: points.right_nostril,
            left_nostril: points.left_nostril,
            mouth: points.mouth,
            k,
            k_measured: estimate.k,
            refused,
            outvoted: false,
            k_nose: estimate.k_nose,
            k_mouth: estimate.k_mouth,
            nose_tip: points.nose_tip,
            k_nose_tip: estimate.k_nose_tip,
            nose_tip_psr: points.nose_tip_psr,
            roll_degrees: estimate.roll.to_degrees(),
            confidence,
            psr,
            locator: Locator::Filters,
            k_network: None,
            k_points: None,
            spread: None,
            face_score: None,
        })
    }

    /// [`Self::estimate_face`] by the landmark network, [`BoxReading::Doubtful`] when the box
    /// gives no face but a face score from [`RETRY_MIN_FACE_SCORE`]. With `turned`, the box is
    /// instead read from starts turned [`RETRY_ROLL_DEGREES`] each way and the better reading
    /// kept; a face found so is reported with its estimate refused and no confidence. Never
    /// doubtful with the filters, which have no face score.
    pub(crate) fn read_box(
        &self,
        gray: &GrayImage,
        face_box: Rect,
        start: FaceStart,
        turned: bool,
    ) -> BoxReading {
        self.read_doubted_box(gray, face_box, start, turned, 0.0)
    }

    /// [`Self::read_box`] from a start in doubt: with the landmark network, the reading ends
    /// at its first crop when that reads under `first_crop_min_face` as a face (see
    /// [`network::locate_within`]; 0: as [`Self::read_box`]).
    pub(crate) fn read_doubted_box(
        &self,
        gray: &GrayImage,
        face_box: Rect,
        start: FaceStart,
        turned: bool,
        first_crop_min_face: f64,
    ) -> BoxReading {
        if self.locator() != Locator::Network {
            return self
                .estimate_face(gray, face_box, start)
                .map_or(BoxReading::NoFace, BoxReading::Face);
        }
        let budget = start.budget.unwrap_or(self.config.network_budget);
        let net = &self.network;
        let (k, roll) = (start.k, start.roll);
        let doubt = first_crop_min_face;
        self.network_reading(net, gray, face_box, k, roll, budget, turned, doubt)
    }

    /// The landmark network's estimate for the face in `face_box` (turned by `roll` about its
    /// centre, where a turned view found it), starting from the view de-sheared by `start_k`:
    /// the first crop is placed where the box predicts the eyes, and [`landmarks::locate`]
    /// crops again around the eyes it finds until the estimate settles (which also takes care
    /// of a tilted head and a box of the wrong size, the filters' second searches). The
    /// nostrils are then found with the eye filter below the network's eyes.
    /// With `turned`, the box is read from turned starts instead, as [`Self::read_box`] says;
    /// with `first_crop_min_face` above 0, a first crop reading under it ends each walk
    /// ([`network::locate_within`]).
    #[allow(clippy::too_many_arguments)]
    fn network_reading(
        &self,
        net: &LandmarkNet,
        gray: &GrayImage,
        face_box: Rect,
        start_k: f64,
        roll: f64,
        budget: Budget,
        turned: bool,
        first_crop_min_face: f64,
    ) -> BoxReading {
        if !can_search(gray, face_box) || !start_k.is_finite() || !roll.is_finite() {
            return BoxReading::NoFace;
        }
        // Where the box predicts the eyes' midpoint, turned with the box about its centre.
        let eyes = eyes_of_box(face_box, roll);
        let locate = |roll: f64| {
            let start = net.frame(
                eyes,
                EYE_DISTANCE_PER_BOX_WIDTH * face_box.width,
                start_k,
                roll,
            );
            NET_WORKSPACE.with(|ws| {
                let ws = &mut ws.borrow_mut();
                network::locate_within(net, gray, start, budget, first_crop_min_face, ws)
            })
        };
        let found = if turned {
            [RETRY_ROLL_DEGREES, -RETRY_ROLL_DEGREES]
                .into_iter()
                .filter_map(|turn| locate(roll + turn.to_radians()))
                .reduce(|a, b| if b.face > a.face { b } else { a })
        } else {
            locate(roll)
        };
        let Some(found) = found else {
            return BoxReading::NoFace;
        };
        if found.face < MIN_FACE_SCORE {
            // Not a face: a false detection, which must not report a shear.
            return if !turned && found.face >= RETRY_MIN_FACE_SCORE {
                BoxReading::Doubtful
            } else {
                BoxReading::NoFace
            };
        }
        if found.roll.abs() > crate::estimate::MAX_ROLL {
            // A face rolled beyond what the search looks for (turned views up to 45 degrees and
            // the cascade's tolerance about them) and where shear and roll stop being separable
            // (see MAX_ROLL): on the development photos these were patterns the network read
            // sideways or upside down, and copies of faces found upright in another box.
            return BoxReading::NoFace;
        }
        let nostrils = self.nostrils_below(gray, &found);
        let eye_line = Point::new(
            found.left_eye.x - found.right_eye.x,
            found.left_eye.y - found.right_eye.y,
        );
        let mid = found.right_eye.midpoint(found.left_eye);
        let nostril_mid = nostrils[0].0.midpoint(nostrils[1].0);
        let k_nostrils = shear_and_roll(
            eye_line,
            Point::new(nostril_mid.x - mid.x, nostril_mid.y - mid.y),
        )
        .map(|r| r.k);
        let learned = network_confidence(&found, face_box, &ConfidenceModel::NETWORK);
        let located = LocatedPoints {
            face_box,
            right_eye: found.right_eye,
            left_eye: found.left_eye,
            nose: Some(found.nose),
            mouth: Some(found.mouth),
            k: found.k,
            roll: found.roll,
            nose_mouth_spread: Some(found.spread[2].min(found.spread[3])),
        };
        let (mut k, mut confidence, mut refused) = self.verdict(gray, &located, learned);
        if turned {
            // Where the reading starts decides it (roll and shear are not told apart): no
            // confidence, so that it hides no window and a sure reading of the face replaces it.
            confidence = 0.0;
            if k.is_some() {
                (k, refused) = (None, Some(Refusal::UnreliablePose));
            }
        }
        BoxReading::Face(FaceReport {
            face_box,
            right_eye: found.right_eye,
            left_eye: found.left_eye,
            right_nostril: nostrils[0].0,
            left_nostril: nostrils[1].0,
            mouth: Some(found.mouth),
            k,
            k_measured: found.k,
            refused,
            outvoted: false,
            k_nose: k_nostrils,
            k_mouth: found.k_mouth,
            nose_tip: Some(found.nose),
            k_nose_tip: found.k_nose,
            nose_tip_psr: 0.0,
            roll_degrees: found.roll.to_degrees(),
            confidence,
            psr: [0.0, 0.0, nostrils[0].1, nostrils[1].1, 0.0],
            locator: Locator::Network,
            k_network: Some(found.k_network),
            k_points: found.k_points,
            spread: Some(found.spread),
            face_score: Some(found.face),
        })
    }

    /// Whether a face's estimate is accepted: its confidence (the learned one times the ruled
    /// [`plausibility`]) and the estimate, or `None` and why. An estimate beyond
    /// [`Config::max_shear`](crate::Config::max_shear) is refused whatever its confidence:
    /// no camera makes it in a usable picture, and correcting by it would destroy the photo.
    fn verdict(
        &self,
        gray: &GrayImage,
        p: &LocatedPoints,
        learned: f64,
    ) -> (Option<f64>, f64, Option<Refusal>) {
        let ruled = plausibility(p, gray.width(), gray.height());
        let confidence = learned * ruled.factor;
        let min = self.config.min_confidence;
        let refused = if !(p.k.is_finite() && p.k.abs() <= self.config.max_shear) {
            Some(Refusal::ImplausibleShear)
        } else if confidence >= min && (confidence > 0.0 || min == 0.0) && ruled.factor > 0.0 {
            None
        } else if learned >= min {
            Some(match ruled.doubt {
                Some(Doubt::OutsideImage) => Refusal::OutsideImage,
                Some(Doubt::NotFaceLike) => Refusal::NotFaceLike,
                Some(Doubt::UnreliablePose) => Refusal::UnreliablePose,
                None => Refusal::LowConfidence,
            })
        } else {
            Some(Refusal::LowConfidence)
        };
        (refused.is_none().then_some(p.k), confidence, refused)
    }

    /// The paper's nostrils below the network's eyes, in the face de-sheared by its estimate.
    fn nostrils_below(&self, gray: &GrayImage, found: &LocatedFace) -> [(Point, f64); 2] {
        let face_box = face_box_from_eyes(found.right_eye, found.left_eye);
        let size = self.filters.size();
        // Only the rows the two nostril patches read: about a third of the face, the same
        // values there (a whole normalised face was about a tenth of a face's estimate).
        let (v_lo, v_hi) = nostril_band(face_box, found.right_eye, found.left_eye, found.k, size);
        let face = NormalizedFace::band(gray, face_box, v_lo, v_hi);
        CORRELATOR.with(|cell| {
            let mut slot = cell.borrow_mut();
            let correlator = match slot.take() {
                Some(c) if c.size() == size => c,
                _ => Correlator::new(size),
            };
            let mut locator = FeatureLocator::with_correlator(&self.filters, correlator);
            let nostrils = locator.nostrils_below(&face, found.right_eye, found.left_eye, found.k);
            *slot = Some(locator.into_correlator());
            nostrils
        })
    }
}

/// The points the estimators use.
fn geometry(p: &FacePoints) -> FeatureGeometry {
    FeatureGeometry {
        right_eye: p.right_eye,
        left_eye: p.left_eye,
        right_pair: (p.right_eye_point, p.right_nose_point),
        left_pair: (p.left_eye_point, p.left_nose_point),
        nose: p.right_nostril.midpoint(p.left_nostril),
        mouth: p.mouth,
        nose_tip: p.nose_tip,
    }
}

/// Whether a face can be searched for in `b` of `gray`: a non-empty image and a box of finite,
/// positive size.
fn can_search(gray: &GrayImage, b: Rect) -> bool {
    let positive = |v: f64| v > 0.0 && v.is_finite();
    gray.width() > 0 && gray.height() > 0 && positive(b.width) && positive(b.height)
}

//! Eyes and nostrils located with the correlation filters, in the face normalised to 150 px wide
//! (paper section IV).
//!
//! The face box is resampled once into a [`NormalizedFace`]: the box scaled to
//! [`FACE_WIDTH`] pixels wide (aspect kept), with a margin around it. Eye crops of the filter size
//! are cut at the expected eye positions, correlated, and the peak inside a search window is the
//! eye. The nostrils are found the same way with the left-eye filter in crops below each eye, as
//! the paper does. Points are then moved to the pair the shear formula compares: each eye centre
//! towards its inner canthus, each nostril out to the alar side wall, so that on an upright,
//! unsheared face the two points of a side lie on one vertical line.
//!
//! Crops can be cut from a *de-sheared* view of the face (rows shifted by `-k (v - eye row)`),
//! which lets the estimator re-measure with the shear it already found removed; see
//! [`FeatureLocator::locate`].
//!
//! The nose needs one step the paper does not have: under strong shear the nose slides sideways
//! out of a nostril crop placed for an upright face, so a third filter, trained on the whole
//! lower nose, first finds the nose in a wide window and measures the shear from it, iterating in
//! the de-sheared face (`FeatureLocator::iterated_nose`); the nostril crops are then cut
//! from the face de-sheared by that estimate.
//!
//! Every geometric constant below says its unit (normalised-face pixels, face box 150 px wide, or
//! eye distances) and how it was chosen.

use image::GrayImage;

use crate::detect::boxes::{LEFT_EYE_IN_BOX, RIGHT_EYE_IN_BOX};
use crate::filters::{normalize_patch, Correlator, EyeFilters, Peak};
use crate::geometry::{Point, Rect};
use crate::resample::{bilinear_clamped, resample, resample_rows};

/// Width of the normalised face, pixels (the paper's 150).
pub(crate) const FACE_WIDTH: f64 = 150.0;

/// Where each nostril is searched, relative to its eye, in eye distances: inwards (towards the
/// nose) and downwards. From the dlib 68-point markup (43 faces, points 32 and 34 against the eye
/// centres of 36-41 and 42-47): the nostrils lie 0.12-0.17 eye distances from the midline (the
/// eyes 0.5), i.e. 0.35 inwards, and 0.70 below the eye line; the eye filter's response on them
/// peaks a little lower, 0.74 (median on the Caltech development faces).
pub(crate) const NOSTRIL_FROM_EYE: (f64, f64) = (0.35, 0.74);
/// Half-size of each nostril's search window, in eye distances: sideways under half the nostril
/// spacing (0.26-0.3), so a window does not reach the other nostril; vertically the nose length
/// varies more (pitch, the person).
pub(crate) const NOSTRIL_SEARCH: (f64, f64) = (0.12, 0.18);
/// Where the nose filter is searched: below the eyes' midpoint by this many eye distances.
/// Caltech development faces: the annotated nose point lies a median 0.29 box widths below the eye
/// line, 0.76 eye distances.
pub(crate) const NOSE_BELOW_EYES: f64 = 0.76;
/// Half-size (eye distances) of the nose search window: sideways it must follow the nose under
/// shear (`k * 0.76` eye distances: 0.45 covers |k| = 0.6), vertically nose length and pitch.
pub(crate) const NOSE_SEARCH: (f64, f64) = (0.45, 0.15);
/// Where the mouth filter is searched: below the eyes' midpoint by this many eye distances, in the
/// face de-sheared by the nose's estimate. Caltech development faces (eye distance >= 20 px): the
/// annotated mouth centre lies a median 1.10 eye distances below the eye line (std 0.15).
pub(crate) const MOUTH_BELOW_EYES: f64 = 1.10;
/// Half-size (eye distances) of the mouth search window: sideways the residual shear after the
/// nose's estimate and the mouth's own spread (std 0.08), vertically its spread (std 0.15;
/// 5th-95th percentile 0.90-1.32).
///
/// Sideways 0.15: on the development faces (MOSSE filters, k = 0 and +-0.40) it places as many
/// mouths within 0.05 as a wider window and accepts fewer wrong estimates; narrower windows
/// miss the mouth of strongly sheared faces.
pub(crate) const MOUTH_SEARCH: (f64, f64) = (0.15, 0.25);

/// Sideways half-range (eye distances) of the nose search after the first pass, when the view
/// is already de-sheared by an estimate: the residual is small, and a narrower window keeps the
/// peak from jumping to the mouth corners or a cheek.
pub(crate) const NOSE_RESIDUAL_SEARCH: f64 = 0.25;
/// Most passes of `FeatureLocator::iterated_nose`. Each pass costs one 64x64
/// correlation (about 40 us).
pub(crate) const NOSE_ITERATIONS: usize = 8;
/// The largest shear the nose iteration will move to. Rolling-shutter skew of a panning camera
/// rarely exceeds |k| = 0.6; an iteration running past 0.8 has lost the nose, and stopping there
/// keeps a lost face from producing an absurd estimate.
pub(crate) const MAX_SHEAR: f64 = 0.8;
/// Change in `k` below which the nose iteration stops.
pub(crate) const NOSE_TOLERANCE: f64 = 0.002;

/// The mouth is searched where the nose's estimate of the shear puts it; when the peak found
/// there lies on the search window's edge (the mouth is beyond the window) and the view the
/// search started in (the detection's) differs from that estimate by more than this, the mouth
/// is also searched where that view puts it, and a peak inside that window is taken. A nose
/// misread (a turned head moves the nose tip sideways; a beard or a shadow pulls the nose
/// filter) would otherwise put the mouth window beside the mouth: on the first 300 Caltech
/// development faces at k = 0, 41 of the 50 mouths found more than 0.12 eye distances sideways
/// off had a nose estimate more than 0.12 off. Taking the sharper of the two peaks instead did
/// better at k = 0 but pulled estimates towards the detection's view (see the README, *Beyond
/// the paper*).
pub(crate) const MOUTH_SECOND_VIEW_MIN_SHEAR: f64 = 0.03;

/// The mouth is searched once more in its own view: the view de-sheared by the shear that puts
/// the mouth found first straight below the eyes' midpoint (less the eye line's slope, a head's
/// roll), when that differs from the view it was found in by at least this. The view the
/// mouth is first searched in is the nose's estimate, and the nose is the least reliable
/// feature: on the first 300 Caltech development faces with both eyes within 0.05, the mouth
/// lay within 0.05 eye distances sideways of its annotation for 86-90% of faces whose nose
/// estimate was within 0.05 of the truth but for 59-70% of those whose nose was 0.10-0.20 off.
/// Searched again where it points itself, the mouth sees a nearly upright view and a window
/// centred on it (see the README, *Beyond the paper*, for what this changed).
pub(crate) const MOUTH_OWN_VIEW_MIN_SHEAR: f64 = 0.01;

/// Candidate positions per eye: the highest value of its filter's correlation in the search
/// window and the highest local maxima after it. With the box drawn from the annotated eyes (scale and position jittered by
/// 8%), the right pair is among the 4 x 4 for 90-93% of Caltech development faces, while the
/// highest peaks alone pair right for 77%.
pub const EYE_CANDIDATES: usize = 4;
const _: () = assert!(
    EYE_CANDIDATES > 0,
    "the pair search needs each eye's highest value"
);

/// What the eye-pair search scores each candidate pair by, in the order of
/// [`EyePair::features`] and `EYE_PAIR_WEIGHTS` (normalised-face measures, distances as
/// fractions of the eye distance the face box predicts):
/// * `right_height`, `left_height`: each peak's correlation value over its eye's highest;
/// * `right_psr`, `left_psr`: each peak's peak-to-sidelobe ratio, over 10;
/// * `scale_error_sq`: the squared relative difference of the pair's distance from the box's
///   (an eye found on the temple or the hair beside it makes the pair too wide or too narrow);
/// * `tilt_sq`: the squared slope of the line through the pair;
/// * `centre_dx_sq`, `centre_dy_sq`: the squared offsets of the pair's midpoint from the box's;
/// * `symmetry`: the correlation of the patch around the right-eye candidate with the mirrored
///   patch around the left-eye candidate (two eyes look like each other's mirror images; an
///   eye and a strand of hair do not);
/// * `gradient_symmetry`: the same for the patches' gradients (the horizontal one mirrored),
///   which a smooth change of lighting across the face does not move.
pub const EYE_PAIR_FEATURES: [&str; 10] = [
    "right_height",
    "left_height",
    "right_psr",
    "left_psr",
    "scale_error_sq",
    "tilt_sq",
    "centre_dx_sq",
    "centre_dy_sq",
    "symmetry",
    "gradient_symmetry",
];

/// Weights of [`EYE_PAIR_FEATURES`] in a candidate pair's score; the highest score wins.
///
/// Fitted by `scripts/fit_eye_pairs.py` (a conditional logit: a softmax over each face's pairs,
/// choosing the pair nearest the annotated eyes) to the candidates the `eye_pair_features`
/// example collects on the Caltech development faces whose eyes are 25 to 40 px apart, none of
/// them among the faces `eval shear` measures (40 px and more), and generated into
/// `src/fitted.rs`, which names the commands and the fit's cross-validated accuracy. The fit
/// replaced a hand-set score (the two peak heights, less 5 x the squared scale error, plus 0.5 x
/// the symmetry), which chose the right pair slightly less often.
pub(crate) const EYE_PAIR_WEIGHTS: [f64; EYE_PAIR_FEATURES.len()] = crate::fitted::EYE_PAIR_WEIGHTS;

/// Side of the patches compared for the pair's symmetry (pixels of the 150-px face): 24, about
/// the eye and its lids (the eye distance is about 57).
pub(crate) const EYE_SYMMETRY_PATCH: usize = 24;

/// Half-size of the eye search window (pixels of the normalised face). The detector's eye
/// positions spread by 3.7-5.3 px (1 std) at 150 px; 14 px is about 3 std.
pub(crate) const EYE_SEARCH: (usize, usize) = (14, 12);

/// Offset from the eye centre towards the inner canthus (between the plica semilunaris and the
/// canthus, paper Fig. 3), as a fraction of the eye distance. dlib markup: the inner canthus is
/// 0.31 eye distances from the midline, the eye centre 0.5; the point between canthus and plica is
/// taken at 0.28, i.e. 0.22 in from the centre.
pub(crate) const EYE_TO_INNER_CANTHUS: f64 = 0.22;
/// Offset from the detected nostril out to the alar side wall, as a fraction of the eye distance.
/// dlib markup: the alae (31, 35) are 0.23-0.28 from the midline, the nostrils 0.12-0.17, so 0.10.
/// Both offsets are mirror-symmetric, so they cancel in the two-sided average of equation 5; they
/// only make each side's own estimate meaningful. Measured on unsheared Caltech development
/// faces, one side alone still reads about +0.06 (the nose point sits slightly inside the eye
/// point), which the other side's -0.06 cancels.
pub(crate) const NOSTRIL_TO_ALAR: f64 = 0.10;

/// Margins (normalised pixels) added around the face box when it is resampled: room for crops
/// that reach past the box and for de-shearing up to |k| = 1 over the crop rows.
const MARGIN_X: usize = 80;
const MARGIN_Y: usize = 40;

/// The face box resampled so that it is `FACE_WIDTH` pixels wide, with a margin.
///
/// Normalised coordinates `(u, v)` have `(0, 0)` at the box's top-left corner; image coordinates
/// are `x = box.x + u * scale`, `y = box.y + v * scale`.
#[derive(Debug, Clone)]
pub struct NormalizedFace {
    /// Samples, row-major, `width` per row, covering `u in [-MARGIN_X, width - MARGIN_X)`: all
    /// `height` rows, or only a band of them from `first_row` on ([`Self::band`]).
    pixels: Vec<f32>,
    /// The first row `pixels` holds (0 unless a band).
    first_row: usize,
    width: usize,
    height: usize,
    /// Image pixels per normalised pixel.
    scale: f64,
    face_box: Rect,
    /// How far the normalised frame is turned against the image, radians (0: axis-aligned;
    /// see [`NormalizedFace::rotated`]).
    roll: f64,
}

impl NormalizedFace {
    /// Resamples `face_box` of `gray` to `FACE_WIDTH` pixels wide (aspect kept), with a
    /// triangle (area-weighted when shrinking) filter and edge replication outside the image.
    pub fn new(gray: &GrayImage, face_box: Rect) -> Self {
        let face = Self::frame(face_box, 0.0);
        let rows = 0..face.height;
        face.with_rows(gray, rows)
    }

    /// [`Self::new`] with only the rows that the normalised rows `v_lo..=v_hi` read (bilinearly:
    /// each row's neighbour below too) resampled: the same values there, bit for bit, for a
    /// caller that reads only a band of the face, such as [`FeatureLocator::nostrils_below`]
    /// through [`nostril_band`]. Reading outside the band is a caller's error: it reads the
    /// band's nearest row instead (and fails a debug assertion).
    pub(crate) fn band(gray: &GrayImage, face_box: Rect, v_lo: f64, v_hi: f64) -> Self {
        let face = Self::frame(face_box, 0.0);
        let last = (face.height - 1) as f64;
        let row = |v: f64| (v + MARGIN_Y as f64).floor().clamp(0.0, last) as usize;
        let (lo, hi) = (row(v_lo), row(v_hi));
        face.with_rows(gray, lo.min(hi)..hi.max(lo) + 2)
    }

    /// This upright frame with its rows `rows` (clipped to its height) resampled from `gray`.
    fn with_rows(mut self, gray: &GrayImage, rows: std::ops::Range<usize>) -> Self {
        self.first_row = rows.start.min(self.height);
        self.pixels = resample_rows(
            gray,
            self.face_box.x - MARGIN_X as f64 * self.scale,
            self.face_box.y - MARGIN_Y as f64 * self.scale,
            self.scale,
            self.width,
            self.height,
            rows,
        );
        self
    }

    /// The geometry of the face normalised from `face_box`, turned by `roll`, without pixels.
    fn frame(face_box: Rect, roll: f64) -> Self {
        let scale = face_box.width / FACE_WIDTH;
        let box_h = (face_box.height / scale).round().max(1.0) as usize;
        Self {
            pixels: Vec::new(),
            first_row: 0,
            width: FACE_WIDTH as usize + 2 * MARGIN_X,
            height: box_h + 2 * MARGIN_Y,
            scale,
            face_box,
            roll,
        }
    }

    /// Row `y` (0 at the top of the whole face) of the samples held.
    fn row(&self, y: usize) -> &[f32] {
        let held = self.pixels.len() / self.width.max(1);
        debug_assert!(
            y >= self.first_row && y < self.first_row + held,
            "row {y} outside the band {}..{}",
            self.first_row,
            self.first_row + held
        );
        let i = y.saturating_sub(self.first_row).min(held.saturating_sub(1));
        &self.pixels[i * self.width..(i + 1) * self.width]
    }

    /// Like [`Self::new`], but the normalised frame is turned by `roll` radians about the box's
    /// centre (positive: clockwise on screen), so that a face whose head is tilted by `roll`
    /// appears upright in it; `Self::to_image` maps its points back to the image.
    ///
    /// The box is first resampled axis-aligned at the normalised scale (area-weighted, so large
    /// faces do not alias) over a region holding the turned frame, which is then read
    /// bilinearly.
    pub fn rotated(gray: &GrayImage, face_box: Rect, roll: f64) -> Self {
        if roll == 0.0 || !roll.is_finite() {
            return Self::new(gray, face_box);
        }
        let mut face = Self::frame(face_box, roll);
        let (scale, width, height) = (face.scale, face.width, face.height);
        // The image region the turned frame covers, in image pixels.
        let corners = [
            (-(MARGIN_X as f64), -(MARGIN_Y as f64)),
            ((width - MARGIN_X) as f64, -(MARGIN_Y as f64)),
            (-(MARGIN_X as f64), (height - MARGIN_Y) as f64),
            ((width - MARGIN_X) as f64, (height - MARGIN_Y) as f64),
        ]
        .map(|(u, v)| face.to_image(Point::new(u, v)));
        let x0 = corners.iter().map(|p| p.x).fold(f64::INFINITY, f64::min) - scale;
        let y0 = corners.iter().map(|p| p.y).fold(f64::INFINITY, f64::min) - scale;
        let x1 = corners
            .iter()
            .map(|p| p.x)
            .fold(f64::NEG_INFINITY, f64::max)
            + scale;
        let y1 = corners
            .iter()
            .map(|p| p.y)
            .fold(f64::NEG_INFINITY, f64::max)
            + scale;
        let (aw, ah) = (
            ((x1 - x0) / scale).ceil() as usize + 2,
            ((y1 - y0) / scale).ceil() as usize + 2,
        );
        let aligned = resample(gray, x0, y0, scale, aw, ah);
        // `to_image` is affine: each pixel's source in `aligned` is the row's first plus the
        // turned unit step (one sine and cosine per face, not per pixel).
        let (sin, cos) = roll.sin_cos();
        let mut pixels = vec![0f32; width * height];
        for (j, row) in pixels.chunks_exact_mut(width).enumerate() {
            let first = face.to_image(Point::new(-(MARGIN_X as f64), j as f64 - MARGIN_Y as f64));
            let (sx, sy) = ((first.x - x0) / scale, (first.y - y0) / scale);
            for (i, o) in row.iter_mut().enumerate() {
                let i = i as f64;
                *o = bilinear_clamped(&aligned, aw, ah, sx + cos * i, sy + sin * i);
            }
        }
        face.pixels = pixels;
        face
    }

    /// Image pixels per normalised pixel.
    #[cfg(test)]
    pub(crate) fn scale(&self) -> f64 {
        self.scale
    }

    /// Image coordinates of a normalised point.
    pub(crate) fn to_image(&self, p: Point) -> Point {
        if self.roll == 0.0 {
            return Point::new(
                self.face_box.x + p.x * self.scale,
                self.face_box.y + p.y * self.scale,
            );
        }
        // Offsets from the box centre, scaled to image pixels and turned by the roll.
        let (s, c) = self.roll.sin_cos();
        let (cu, cv) = self.centre();
        let (du, dv) = ((p.x - cu) * self.scale, (p.y - cv) * self.scale);
        Point::new(
            self.face_box.x + cu * self.scale + c * du - s * dv,
            self.face_box.y + cv * self.scale + s * du + c * dv,
        )
    }

    /// Normalised coordinates of an image point.
    #[allow(clippy::wrong_self_convention)] // The inverse of `to_image`.
    pub fn from_image(&self, p: Point) -> Point {
        if self.roll == 0.0 {
            return Point::new(
                (p.x - self.face_box.x) / self.scale,
                (p.y - self.face_box.y) / self.scale,
            );
        }
        let (s, c) = self.roll.sin_cos();
        let (cu, cv) = self.centre();
        let (dx, dy) = (
            p.x - self.face_box.x - cu * self.scale,
            p.y - self.face_box.y - cv * self.scale,
        );
        Point::new(
            cu + (c * dx + s * dy) / self.scale,
            cv + (-s * dx + c * dy) / self.scale,
        )
    }

    /// The box centre in normalised coordinates (the pivot of the roll).
    fn centre(&self) -> (f64, f64) {
        (FACE_WIDTH / 2.0, self.face_box.height / self.scale / 2.0)
    }

    /// Bilinear sample at normalised `(u, v)`, edge-replicated.
    fn sample(&self, u: f64, v: f64) -> f32 {
        let x = (u + MARGIN_X as f64).clamp(0.0, (self.width - 1) as f64);
        let y = (v + MARGIN_Y as f64).clamp(0.0, (self.height - 1) as f64);
        let (x0, y0) = (x.floor() as usize, y.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(self.width - 1), (y0 + 1).min(self.height - 1));
        let (fx, fy) = ((x - x0 as f64) as f32, (y - y0 as f64) as f32);
        let (row0, row1) = (self.row(y0), self.row(y1));
        let top = row0[x0] + (row0[x1] - row0[x0]) * fx;
        let bottom = row1[x0] + (row1[x1] - row1[x0]) * fx;
        top + (bottom - top) * fy
    }

    /// Cuts a `size x size` patch centred on normalised `centre` (the patch's `(size/2, size/2)`
    /// sample lands on it) from the view de-sheared by `k` about row `pivot_v`: the sample at
    /// `(u, v)` of that view is taken at `(u + k (v - pivot_v), v)` of the face.
    pub(crate) fn patch(&self, centre: Point, size: usize, k: f64, pivot_v: f64, out: &mut [f32]) {
        let half = (size / 2) as f64;
        let last_x = self.width.saturating_sub(1);
        for (j, row) in out.chunks_exact_mut(size).enumerate() {
            let v = centre.y - half + j as f64;
            let u0 = centre.x - half + k * (v - pivot_v);
            // Along a row the samples are one pixel apart, so the row pair and both weights are
            // the same for the whole row: only the columns move (the hot loop of the locator).
            let y = (v + MARGIN_Y as f64).clamp(0.0, (self.height - 1) as f64);
            let y0 = y.floor() as usize;
            let y1 = (y0 + 1).min(self.height - 1);
            let fy = (y - y0 as f64) as f32;
            let (row0, row1) = (self.row(y0), self.row(y1));
            let x_start = u0 + MARGIN_X as f64;
            let first = x_start.floor();
            let fx = (x_start - first) as f32;
            // The samples whose column pair `first + i`, `first + i + 1` lies inside the face
            // are one run, `lo..hi`, read without a test per sample (so the compiler vectorises
            // it); those before and after it take the edge-replicating `sample`. NaN gives an
            // empty run.
            let lo = (-first).max(0.0).min(size as f64) as usize;
            let hi = (last_x as f64 - first).clamp(lo as f64, size as f64) as usize;
            for (i, o) in row[..lo].iter_mut().enumerate() {
                *o = self.sample(u0 + i as f64, v);
            }
            if hi > lo {
                let a = (first + lo as f64) as usize;
                let n = hi - lo;
                let (left0, right0) = (&row0[a..a + n], &row0[a + 1..a + n + 1]);
                let (left1, right1) = (&row1[a..a + n], &row1[a + 1..a + n + 1]);
                for ((((o, &l0), &r0), &l1), &r1) in row[lo..hi]
                    .iter_mut()
                    .zip(left0)
                    .zip(right0)
                    .zip(left1)
                    .zip(right1)
                {
                    let top = l0 + (r0 - l0) * fx;
                    let bottom = l1 + (r1 - l1) * fx;
                    *o = top + (bottom - top) * fy;
                }
            }
            for (i, o) in row.iter_mut().enumerate().skip(hi) {
                *o = self.sample(u0 + i as f64, v);
            }
        }
    }
}

/// Where the nostril searches below eyes at `right_eye` and `left_eye` (normalised-face pixels
/// of a de-sheared view) are centred, right then left, and their window.
fn nostril_searches(right_eye: Point, left_eye: Point) -> (Point, Point, (usize, usize)) {
    let eye_distance = right_eye.distance(left_eye).max(1.0);
    let (inward, down) = (
        NOSTRIL_FROM_EYE.0 * eye_distance,
        NOSTRIL_FROM_EYE.1 * eye_distance,
    );
    let window = (
        (NOSTRIL_SEARCH.0 * eye_distance).round().max(1.0) as usize,
        (NOSTRIL_SEARCH.1 * eye_distance).round().max(1.0) as usize,
    );
    let below = |eye: Point, dir: f64| Point::new(eye.x + dir * inward, eye.y + down);
    (below(right_eye, 1.0), below(left_eye, -1.0), window)
}

/// Eyes at image points `right_eye` and `left_eye` in `face`'s view de-sheared by `k` about
/// their row, and that row (normalised-face pixels).
fn eyes_in_view(
    face: &NormalizedFace,
    right_eye: Point,
    left_eye: Point,
    k: f64,
) -> (Point, Point, f64) {
    let (r, l) = (face.from_image(right_eye), face.from_image(left_eye));
    let pivot_v = (r.y + l.y) / 2.0;
    let view = |p: Point| Point::new(p.x - k * (p.y - pivot_v), p.y);
    (view(r), view(l), pivot_v)
}

/// The normalised rows, first and last, that [`FeatureLocator::nostrils_below`] reads with
/// patches of side `patch_size` in the upright face normalised from `face_box`, for eyes at
/// image points `right_eye` and `left_eye` and shear `k`: what [`NormalizedFace::band`] needs
/// to resample. (A shear moves the patches' columns, never their rows.)
pub(crate) fn nostril_band(
    face_box: Rect,
    right_eye: Point,
    left_eye: Point,
    k: f64,
    patch_size: usize,
) -> (f64, f64) {
    let frame = NormalizedFace::frame(face_box, 0.0);
    let (r, l, _) = eyes_in_view(&frame, right_eye, left_eye, k);
    let (right, left, _) = nostril_searches(r, l);
    // `patch` reads rows `centre - size / 2` to `centre - size / 2 + size - 1`.
    let half = (patch_size / 2) as f64;
    (
        right.y.min(left.y) - half,
        right.y.max(left.y) - half + patch_size.saturating_sub(1) as f64,
    )
}

/// The expected positions of both eyes in the normalised face (from the detector-box medians).
pub fn expected_eyes(face: &NormalizedFace) -> (Point, Point) {
    let h = face.face_box.height / face.scale;
    (
        Point::new(RIGHT_EYE_IN_BOX.0 * FACE_WIDTH, RIGHT_EYE_IN_BOX.1 * h),
        Point::new(LEFT_EYE_IN_BOX.0 * FACE_WIDTH, LEFT_EYE_IN_BOX.1 * h),
    )
}

/// One located feature: its normalised position (in the de-sheared view it was found in) and
/// the correlation peak.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Located {
    /// Position in normalised-face pixels of the view it was found in.
    pub position: Point,
    /// The correlation peak (displacement and peak-to-sidelobe ratio).
    pub peak: Peak,
}

/// One candidate pair of eyes and the measures the pair search scores it by.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EyePair {
    /// The right-eye candidate.
    pub right: Located,
    /// The left-eye candidate.
    pub left: Located,
    /// The pair's [`EYE_PAIR_FEATURES`].
    pub features: [f64; EYE_PAIR_FEATURES.len()],
}

impl EyePair {
    /// The pair's score: its features weighed by `EYE_PAIR_WEIGHTS`.
    pub fn score(&self) -> f64 {
        self.features
            .iter()
            .zip(EYE_PAIR_WEIGHTS)
            .map(|(f, w)| f * w)
            .sum()
    }
}

/// What [`FeatureLocator::eye_pairs`] found.
#[derive(Debug, Clone, PartialEq)]
pub enum EyeSearch {
    /// Either eye's highest value lies on its window's edge: the two highest values (right,
    /// left), not paired.
    Unpaired(Located, Located),
    /// Every right-eye candidate paired with every left-eye candidate (never empty).
    Pairs(Vec<EyePair>),
}

/// Scales `v` to zero mean and unit length (all zeros when constant), so that the dot product
/// of two such vectors is their normalised correlation
/// (`filters::zero_mean_correlation`).
fn standardize(v: &mut [f32]) {
    let n = v.len().max(1) as f64;
    let mean = v.iter().map(|&x| f64::from(x)).sum::<f64>() / n;
    let norm = v
        .iter()
        .map(|&x| (f64::from(x) - mean).powi(2))
        .sum::<f64>()
        .sqrt();
    let inv = if norm > 0.0 { 1.0 / norm } else { 0.0 };
    for x in v.iter_mut() {
        *x = ((f64::from(*x) - mean) * inv) as f32;
    }
}

/// The dot product of two equally long vectors, accumulated in `f64`.
fn dot(a: &[f32], b: &[f32]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(&x, &y)| f64::from(x) * f64::from(y))
        .sum()
}

/// Length of [`gradients`]' output for a square patch of `side`.
fn gradient_len(side: usize) -> usize {
    2 * side.saturating_sub(2).pow(2)
}

/// The central-difference gradients of a square patch's interior: all horizontal ones, then all
/// vertical ones.
fn gradients(patch: &[f32], side: usize, out: &mut [f32]) {
    let inner = side.saturating_sub(2);
    let (gx, gy) = out.split_at_mut(inner * inner);
    for y in 1..=inner {
        for x in 1..=inner {
            let at = |xx: usize, yy: usize| patch[yy * side + xx];
            let i = (y - 1) * inner + (x - 1);
            gx[i] = at(x + 1, y) - at(x - 1, y);
            gy[i] = at(x, y + 1) - at(x, y - 1);
        }
    }
}

/// The nose filter's converged result (see `FeatureLocator::iterated_nose`).
#[derive(Debug, Clone, Copy, PartialEq)]
struct NoseTip {
    /// The shear the iteration converged on.
    k: f64,
    /// The nose filter's last peak, normalised coordinates of the face as it is.
    position: Point,
    /// That peak's peak-to-sidelobe ratio.
    psr: f64,
}

/// The four feature points of a face, in image pixels, with their confidences.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FacePoints {
    /// Subject's right eye centre (image left).
    pub right_eye: Point,
    /// Subject's left eye centre (image right).
    pub left_eye: Point,
    /// Subject's right nostril (image left).
    pub right_nostril: Point,
    /// Subject's left nostril (image right).
    pub left_nostril: Point,
    /// The eye point moved towards the inner canthus, right side (the eq. 5 point).
    pub right_eye_point: Point,
    /// The eye point moved towards the inner canthus, left side.
    pub left_eye_point: Point,
    /// The nostril moved out to the alar side wall, right side (the eq. 5 point).
    pub right_nose_point: Point,
    /// The nostril moved out to the alar side wall, left side.
    pub left_nose_point: Point,
    /// Peak-to-sidelobe ratios: right eye, left eye, right nostril, left nostril.
    pub psr: [f64; 4],
    /// The mouth centre, image pixels, when the filters have a mouth filter.
    pub mouth: Option<Point>,
    /// The mouth peak's peak-to-sidelobe ratio (0 without a mouth filter).
    pub mouth_psr: f64,
    /// The lower nose as the nose filter found it (image pixels), when the nose's estimate set
    /// the view (`FeatureLocator::locate_from`); `None` for a view given by the caller.
    pub nose_tip: Option<Point>,
    /// The nose filter's peak-to-sidelobe ratio (0 without `nose_tip`).
    pub nose_tip_psr: f64,
    /// The shear of the view the features were found in (the nose's estimate, or the `k`
    /// passed to [`FeatureLocator::locate`]).
    pub view_k: f64,
}

/// Finds eyes and nostrils with a pair of eye filters. Holds the FFT plans and buffers: make one
/// per thread and reuse it.
pub struct FeatureLocator<'f> {
    filters: &'f EyeFilters,
    correlator: Correlator,
    patch: Vec<f32>,
    /// Buffers of the eye pairs' symmetry tests: each candidate's patch ([`EYE_SYMMETRY_PATCH`]
    /// squared; the left eye's mirrored) and its gradients.
    right_mirror: Vec<f32>,
    left_mirror: Vec<f32>,
    right_gradients: Vec<f32>,
    left_gradients: Vec<f32>,
}

impl std::fmt::Debug for FeatureLocator<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FeatureLocator")
            .field("size", &self.filters.size())
            .finish()
    }
}

impl<'f> FeatureLocator<'f> {
    /// A locator using `filters` (plans its FFTs here).
    #[cfg(any(test, feature = "dev"))]
    pub fn new(filters: &'f EyeFilters) -> Self {
        Self::with_correlator(filters, Correlator::new(filters.size()))
    }

    /// A locator reusing `correlator` (which must be of the filters' size), so that FFT plans are
    /// made once per thread rather than once per face.
    pub(crate) fn with_correlator(filters: &'f EyeFilters, correlator: Correlator) -> Self {
        let size = filters.size();
        debug_assert_eq!(correlator.size(), size);
        Self {
            filters,
            correlator,
            patch: vec![0.0; size * size],
            right_mirror: Vec::new(),
            left_mirror: Vec::new(),
            right_gradients: Vec::new(),
            left_gradients: Vec::new(),
        }
    }

    /// Gives the correlator back, for the next locator.
    pub(crate) fn into_correlator(self) -> Correlator {
        self.correlator
    }

    fn find(
        &mut self,
        face: &NormalizedFace,
        centre: Point,
        k: f64,
        pivot_v: f64,
        window: (usize, usize),
        left_filter: bool,
    ) -> Located {
        let filters = self.filters;
        let filter = if left_filter {
            &filters.left_eye
        } else {
            &filters.right_eye
        };
        self.find_with(face, centre, k, pivot_v, window, filter)
    }

    /// Both eyes in the view de-sheared by `k`: the best-scoring of [`Self::eye_pairs`], or the
    /// two highest values when either lies on its window's edge.
    fn find_eyes(&mut self, face: &NormalizedFace, k: f64) -> (Located, Located) {
        match self.eye_pairs(face, k, EYE_CANDIDATES) {
            EyeSearch::Unpaired(right, left) => (right, left),
            EyeSearch::Pairs(pairs) => pairs
                .iter()
                .map(|p| (p.score(), p))
                .max_by(|a, b| a.0.total_cmp(&b.0))
                .map(|(_, p)| (p.right, p.left))
                .unwrap_or_else(|| unreachable!("the window's highest values always pair")),
        }
    }

    /// The eye search's candidates in the view de-sheared by `k` (about the expected eye row):
    /// the `candidates` highest peaks of each eye filter's correlation in its window around
    /// [`expected_eyes`] (the window's highest value first, then its other local maxima),
    /// paired each with each and measured for [`EYE_PAIR_FEATURES`]. When either eye's highest
    /// value lies on its window's edge the eye lies beyond the window (a rolled head, a box off
    /// the face) and the window's other peaks are other features: the two highest values are
    /// returned unpaired, as a single search would give them, so that the roll they measure
    /// sends the search to a turned view where the eyes are inside.
    ///
    /// Positions are in normalised-face pixels of the view.
    pub fn eye_pairs(&mut self, face: &NormalizedFace, k: f64, candidates: usize) -> EyeSearch {
        let candidates = candidates.max(1);
        let (exp_right, exp_left) = expected_eyes(face);
        let pivot_v = (exp_right.y + exp_left.y) / 2.0;
        let mut found: [Vec<Located>; 2] = [Vec::new(), Vec::new()];
        for (i, (centre, filter)) in [
            (exp_right, &self.filters.right_eye),
            (exp_left, &self.filters.left_eye),
        ]
        .into_iter()
        .enumerate()
        {
            self.correlate_around(face, centre, k, pivot_v, filter);
            found[i] = self
                .correlator
                .local_maxima_in_window(EYE_SEARCH.0, EYE_SEARCH.1, candidates)
                .into_iter()
                .map(|peak| Located {
                    position: Point::new(centre.x + peak.dx, centre.y + peak.dy),
                    peak,
                })
                .collect();
        }
        let [rights, lefts] = found;
        let (Some(&r0), Some(&l0)) = (rights.first(), lefts.first()) else {
            unreachable!("the window's highest value always leads the candidates")
        };
        if !r0.peak.is_inside(EYE_SEARCH) || !l0.peak.is_inside(EYE_SEARCH) {
            return EyeSearch::Unpaired(r0, l0);
        }
        let expected_distance = exp_right.distance(exp_left).max(1.0);
        let expected_centre = exp_right.midpoint(exp_left);
        // Each eye's peaks are measured against its highest, so the two filters weigh the same.
        let top = (
            f64::from(r0.peak.value).max(f64::from(f32::MIN_POSITIVE)),
            f64::from(l0.peak.value).max(f64::from(f32::MIN_POSITIVE)),
        );
        // Each candidate's patch and gradients once (the left ones mirrored), compared pair by
        // pair below.
        let side = EYE_SYMMETRY_PATCH;
        let area = side * side;
        let grad_len = gradient_len(side);
        for (located, patches, grads, mirrored) in [
            (
                &rights,
                &mut self.right_mirror,
                &mut self.right_gradients,
                false,
            ),
            (
                &lefts,
                &mut self.left_mirror,
                &mut self.left_gradients,
                true,
            ),
        ] {
            patches.resize(located.len() * area, 0.0);
            grads.resize(located.len() * grad_len, 0.0);
            for (i, c) in located.iter().enumerate() {
                let patch = &mut patches[i * area..][..area];
                face.patch(c.position, side, k, pivot_v, patch);
                if mirrored {
                    for row in patch.chunks_exact_mut(side) {
                        row.reverse();
                    }
                }
                let grad = &mut grads[i * grad_len..][..grad_len];
                gradients(patch, side, grad);
                // Standardised once, so that each pair's correlation is a dot product.
                standardize(patch);
                standardize(grad);
            }
        }
        let mut pairs = Vec::with_capacity(rights.len() * lefts.len());
        for (i, r) in rights.iter().enumerate() {
            for (j, l) in lefts.iter().enumerate() {
                let (a, b) = (r.position, l.position);
                let distance = a.distance(b).max(1e-9);
                let scale_error = distance / expected_distance - 1.0;
                let tilt = (b.y - a.y) / (b.x - a.x).abs().max(1e-9);
                let centre = a.midpoint(b);
                let centre_dx = (centre.x - expected_centre.x) / expected_distance;
                let centre_dy = (centre.y - expected_centre.y) / expected_distance;
                let symmetry = dot(
                    &self.right_mirror[i * area..][..area],
                    &self.left_mirror[j * area..][..area],
                );
                let gradient_symmetry = dot(
                    &self.right_gradients[i * grad_len..][..grad_len],
                    &self.left_gradients[j * grad_len..][..grad_len],
                );
                pairs.push(EyePair {
                    right: *r,
                    left: *l,
                    features: [
                        f64::from(r.peak.value) / top.0,
                        f64::from(l.peak.value) / top.1,
                        r.peak.psr / 10.0,
                        l.peak.psr / 10.0,
                        scale_error * scale_error,
                        tilt * tilt,
                        centre_dx * centre_dx,
                        centre_dy * centre_dy,
                        symmetry,
                        gradient_symmetry,
                    ],
                });
            }
        }
        EyeSearch::Pairs(pairs)
    }

    /// Correlates `filter` with the patch around `centre` in the view de-sheared by `k`; the
    /// plane is left in the correlator for its peak searches.
    fn correlate_around(
        &mut self,
        face: &NormalizedFace,
        centre: Point,
        k: f64,
        pivot_v: f64,
        filter: &crate::filters::Filter,
    ) {
        face.patch(centre, self.filters.size(), k, pivot_v, &mut self.patch);
        normalize_patch(&mut self.patch);
        self.correlator.compute_plane(&self.patch, filter);
    }

    fn find_with(
        &mut self,
        face: &NormalizedFace,
        centre: Point,
        k: f64,
        pivot_v: f64,
        window: (usize, usize),
        filter: &crate::filters::Filter,
    ) -> Located {
        self.correlate_around(face, centre, k, pivot_v, filter);
        let peak = self.correlator.peak_in_window(window.0, window.1);
        Located {
            position: Point::new(centre.x + peak.dx, centre.y + peak.dy),
            peak,
        }
    }

    /// Both nostrils, found with the left-eye filter (as the paper) in crops below each eye, in
    /// the view de-sheared by `k`.
    fn find_nostrils(
        &mut self,
        face: &NormalizedFace,
        right_eye: Point,
        left_eye: Point,
        k: f64,
        pivot_v: f64,
    ) -> (Located, Located) {
        let (right_centre, left_centre, window) = nostril_searches(right_eye, left_eye);
        let right = self.find(face, right_centre, k, pivot_v, window, true);
        let left = self.find(face, left_centre, k, pivot_v, window, true);
        (right, left)
    }

    /// The paper's nostrils (the left-eye filter in crops below each eye) below eyes located by
    /// other means (image pixels), in the view of `face` de-sheared by `k` about the eye row:
    /// each nostril in image pixels with its peak-to-sidelobe ratio, right then left.
    pub(crate) fn nostrils_below(
        &mut self,
        face: &NormalizedFace,
        right_eye: Point,
        left_eye: Point,
        k: f64,
    ) -> [(Point, f64); 2] {
        let (r, l, pivot_v) = eyes_in_view(face, right_eye, left_eye, k);
        let (right, left) = self.find_nostrils(face, r, l, k, pivot_v);
        [right, left].map(|n| {
            let p = n.position;
            (
                face.to_image(Point::new(p.x + k * (p.y - pivot_v), p.y)),
                n.peak.psr,
            )
        })
    }

    /// The shear measured from the nose in the view of the face de-sheared by `k_view` (about
    /// the eye row): the nose filter's peak against the eyes' midpoint (a vertical line of the
    /// upright face joins them), added to `k_view`. `wide` searches the whole sideways range
    /// the nose search window; otherwise the search is limited to the residual search window.
    ///
    /// The eyes are given, and the nose returned, in normalised-face coordinates of the view.
    pub(crate) fn nose_shear(
        &mut self,
        face: &NormalizedFace,
        right_eye: Point,
        left_eye: Point,
        k_view: f64,
        wide: bool,
    ) -> (f64, Located) {
        let ed = right_eye.distance(left_eye).max(1.0);
        let mid = right_eye.midpoint(left_eye);
        let centre = Point::new(mid.x, mid.y + NOSE_BELOW_EYES * ed);
        let reach_x = if wide {
            NOSE_SEARCH.0
        } else {
            NOSE_RESIDUAL_SEARCH
        };
        let window = (
            (reach_x * ed).round() as usize,
            (NOSE_SEARCH.1 * ed).round() as usize,
        );
        let size = self.filters.size();
        face.patch(centre, size, k_view, mid.y, &mut self.patch);
        normalize_patch(&mut self.patch);
        let peak = self
            .correlator
            .correlate(&self.patch, &self.filters.nose, window.0, window.1);
        let nose = Point::new(centre.x + peak.dx, centre.y + peak.dy);
        let k =
            (k_view + (nose.x - mid.x) / (nose.y - mid.y).max(1.0)).clamp(-MAX_SHEAR, MAX_SHEAR);
        (
            k,
            Located {
                position: nose,
                peak,
            },
        )
    }

    /// The nose's estimate of the shear, iterated: the nose is measured in the face de-sheared
    /// by the current estimate until the estimate changes by less than a small tolerance (at
    /// most a few passes).
    ///
    /// One pass alone reads only about 70% of the shear: the nose filter matches the whole
    /// 64x64 patch, whose upper part (the nose bridge, near the eye row) moves less under shear
    /// than the nose tip, so the peak lands between them. Measured on 250 Caltech faces at
    /// k = 0.40 with face boxes from the annotated eyes: median 0.289 after one pass. Each pass
    /// removes most of the remaining shear, so the estimate converges on the truth. Returns the
    /// shear and where the nose filter's last peak lies, in the face's own normalised
    /// coordinates (not de-sheared).
    fn iterated_nose(
        &mut self,
        face: &NormalizedFace,
        right_eye: Point,
        left_eye: Point,
        start_k: f64,
    ) -> NoseTip {
        let pivot = right_eye.midpoint(left_eye).y;
        let (mut k, mut found) = self.nose_shear(face, right_eye, left_eye, start_k, true);
        let mut view = start_k;
        for _ in 1..NOSE_ITERATIONS {
            let (next, at) = self.nose_shear(face, right_eye, left_eye, k, false);
            let done = (next - k).abs() < NOSE_TOLERANCE;
            (view, k, found) = (k, next, at);
            if done {
                break;
            }
        }
        let p = found.position;
        NoseTip {
            k,
            position: Point::new(p.x + view * (p.y - pivot), p.y),
            psr: found.peak.psr,
        }
    }

    /// Locates both eyes and both nostrils in `face`, looking at the view de-sheared by `k`
    /// (pass 0 for the face as it is, or `None` to de-shear first by the nose filter's estimate,
    /// `FeatureLocator::nose_shear`),
    /// and returns the points in image pixels.
    ///
    /// The eye row is the pivot of the de-shearing, so the eyes stay where the detector box puts
    /// them and only the nose moves back under them.
    pub fn locate(&mut self, face: &NormalizedFace, k: Option<f64>) -> FacePoints {
        match k {
            Some(k) => self.locate_in_view(face, k, None),
            None => self.locate_from(face, 0.0),
        }
    }

    /// [`Self::locate`] with the nose's estimate, starting from the view de-sheared by `start_k`
    /// (the shear a detection was made under): the eyes are first found there, and the nose
    /// iteration starts there, so that under strong shear the filters see nearly upright
    /// features from the first pass.
    pub(crate) fn locate_from(&mut self, face: &NormalizedFace, start_k: f64) -> FacePoints {
        let (right, left) = self.find_eyes(face, start_k);
        let tip = self.iterated_nose(face, right.position, left.position, start_k);
        FacePoints {
            nose_tip: Some(face.to_image(tip.position)),
            nose_tip_psr: tip.psr,
            ..self.locate_in_view(face, tip.k, Some(start_k))
        }
    }

    /// The mouth, when the filters have a mouth filter, in the view de-sheared by `k` (about
    /// row `pivot_v`), below the eyes `(right, left)` found there: searched in that view, then
    /// in `start_k`'s view when its peak lies on the window's edge (see
    /// [`MOUTH_SECOND_VIEW_MIN_SHEAR`]), then once more in the view its own position implies
    /// (see [`MOUTH_OWN_VIEW_MIN_SHEAR`]).
    fn find_mouth(
        &mut self,
        face: &NormalizedFace,
        (right, left): (Point, Point),
        k: f64,
        start_k: Option<f64>,
        pivot_v: f64,
    ) -> Option<Located> {
        let filter = self.filters.mouth.as_ref()?;
        let eye_distance = right.distance(left).max(1.0);
        let window = (
            (MOUTH_SEARCH.0 * eye_distance).round().max(1.0) as usize,
            (MOUTH_SEARCH.1 * eye_distance).round().max(1.0) as usize,
        );
        let mid = right.midpoint(left);
        // The eyes' midpoint in the view de-sheared by `view` instead of `k`, and a point found
        // there back in the view de-sheared by `k`, where the other points are.
        let mid_in = |view: f64| Point::new(mid.x + (k - view) * (mid.y - pivot_v), mid.y);
        let back = |found: Located, view: f64| {
            let p = found.position;
            Located {
                position: Point::new(p.x + (view - k) * (p.y - pivot_v), p.y),
                peak: found.peak,
            }
        };
        let below = |m: Point, dx: f64| Point::new(m.x + dx, m.y + MOUTH_BELOW_EYES * eye_distance);
        let in_nose_view = self.find_with(face, below(mid, 0.0), k, pivot_v, window, filter);
        let mut mouth = match start_k {
            // A peak on the window's edge marks a mouth beyond the window: look where the view
            // the search started in puts the mouth, and take a peak inside that window.
            Some(start)
                if !in_nose_view.peak.is_inside(window)
                    && (start - k).abs() > MOUTH_SECOND_VIEW_MIN_SHEAR =>
            {
                let in_start_view = self.find_with(
                    face,
                    below(mid_in(start), 0.0),
                    start,
                    pivot_v,
                    window,
                    filter,
                );
                if in_start_view.peak.is_inside(window) {
                    back(in_start_view, start)
                } else {
                    in_nose_view
                }
            }
            _ => in_nose_view,
        };
        // The mouth's own view: the shear that puts it straight below the eyes' midpoint, the
        // eye line's slope (a head's roll) taken out.
        let slope = (left.y - right.y) / (left.x - right.x).abs().max(1.0);
        let drop = mouth.position.y - mid.y;
        if drop >= 1.0 {
            let own = (k + (mouth.position.x - mid.x) / drop + slope).clamp(-MAX_SHEAR, MAX_SHEAR);
            if (own - k).abs() >= MOUTH_OWN_VIEW_MIN_SHEAR {
                let centre = below(mid_in(own), -slope * MOUTH_BELOW_EYES * eye_distance);
                mouth = back(
                    self.find_with(face, centre, own, pivot_v, window, filter),
                    own,
                );
            }
        }
        Some(mouth)
    }

    /// The features in the view de-sheared by `k`; the mouth is also searched in the view
    /// de-sheared by `start_k` when that differs (see [`MOUTH_SECOND_VIEW_MIN_SHEAR`]).
    fn locate_in_view(
        &mut self,
        face: &NormalizedFace,
        k: f64,
        start_k: Option<f64>,
    ) -> FacePoints {
        let (exp_right, exp_left) = expected_eyes(face);
        let pivot_v = (exp_right.y + exp_left.y) / 2.0;
        let (right_eye, left_eye) = self.find_eyes(face, k);
        let eye_distance = right_eye.position.distance(left_eye.position).max(1.0);
        let (right_nostril, left_nostril) =
            self.find_nostrils(face, right_eye.position, left_eye.position, k, pivot_v);
        let mouth = self.find_mouth(
            face,
            (right_eye.position, left_eye.position),
            k,
            start_k,
            pivot_v,
        );
        // From the de-sheared view back to the face as it is, then to image pixels.
        let to_image = |p: Point| face.to_image(Point::new(p.x + k * (p.y - pivot_v), p.y));
        let eye_shift = EYE_TO_INNER_CANTHUS * eye_distance;
        let alar_shift = NOSTRIL_TO_ALAR * eye_distance;
        let moved = |p: Point, dx: f64| to_image(Point::new(p.x + dx, p.y));
        FacePoints {
            right_eye: to_image(right_eye.position),
            left_eye: to_image(left_eye.position),
            right_nostril: to_image(right_nostril.position),
            left_nostril: to_image(left_nostril.position),
            right_eye_point: moved(right_eye.position, eye_shift),
            left_eye_point: moved(left_eye.position, -eye_shift),
            right_nose_point: moved(right_nostril.position, -alar_shift),
            left_nose_point: moved(left_nostril.position, alar_shift),
            psr: [
                right_eye.peak.psr,
                left_eye.peak.psr,
                right_nostril.peak.psr,
                left_nostril.peak.psr,
            ],
            mouth: mouth.map(|m| to_image(m.position)),
            mouth_psr: mouth.map_or(0.0, |m| m.peak.psr),
            nose_tip: None,
            nose_tip_psr: 0.0,
            view_k: k,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::detect::boxes::{face_box_from_eyes, EYE_DISTANCE_PER_BOX_WIDTH};

    /// An eye-like distractor beside the right eye, a copy of that eye slightly stronger than
    /// it, wins the single-eye search; the pair search keeps the eye at the distance the box
    /// predicts and that mirrors the other eye.
    #[test]
    fn the_eye_pair_search_passes_over_a_stronger_eye_like_distractor() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/fixtures/faces/subject01.normal.jpeg");
        let gray = image::open(&path).expect("fixture").to_luma8();
        let filters = EyeFilters::embedded().expect("built-in filters");
        let mut locator = FeatureLocator::new(&filters);
        // Where the filters put the eyes in the box the detector would draw for them.
        let first = NormalizedFace::new(&gray, Rect::new(95.0, 60.0, 130.0, 130.0));
        let seed = locator.locate(&first, Some(0.0));
        let box_ = face_box_from_eyes(seed.right_eye, seed.left_eye);
        let face = NormalizedFace::new(&gray, box_);
        let found = locator.locate(&face, Some(0.0));
        let eye_distance = found.right_eye.distance(found.left_eye);
        // Copy the right eye (image left) 0.2 eye distances outward, with 30% more contrast.
        let eye = found.right_eye;
        let (half_w, half_h) = ((0.15 * eye_distance) as i64, (0.1 * eye_distance) as i64);
        let shift = (0.2 * eye_distance).round() as i64;
        let mean = {
            let mut sum = 0.0;
            for dy in -half_h..=half_h {
                for dx in -half_w..=half_w {
                    let (x, y) = (eye.x as i64 + dx, eye.y as i64 + dy);
                    sum += f64::from(gray.get_pixel(x as u32, y as u32)[0]);
                }
            }
            sum / ((2 * half_w + 1) * (2 * half_h + 1)) as f64
        };
        let mut distracted = gray.clone();
        for dy in -half_h..=half_h {
            for dx in -half_w..=half_w {
                let (x, y) = (eye.x as i64 + dx, eye.y as i64 + dy);
                let v = f64::from(gray.get_pixel(x as u32, y as u32)[0]);
                let boosted = (mean + 1.3 * (v - mean)).clamp(0.0, 255.0) as u8;
                distracted.put_pixel((x - shift) as u32, y as u32, image::Luma([boosted]));
            }
        }
        let face = NormalizedFace::new(&distracted, box_);
        let (exp_right, exp_left) = expected_eyes(&face);
        let pivot_v = (exp_right.y + exp_left.y) / 2.0;
        let single = locator.find(&face, exp_right, 0.0, pivot_v, EYE_SEARCH, false);
        let single_at = face.to_image(single.position);
        assert!(
            single_at.distance(eye) > 0.1 * eye_distance,
            "the distractor should win a single search: {single_at:?} vs eye {eye:?}"
        );
        let paired = locator.locate(&face, Some(0.0));
        assert!(
            paired.right_eye.distance(eye) < 0.05 * eye_distance,
            "pair search: {:?} vs eye {eye:?}",
            paired.right_eye
        );
    }

    fn ramp(w: u32, h: u32) -> GrayImage {
        GrayImage::from_fn(w, h, |x, y| image::Luma([((x * 2 + y) % 256) as u8]))
    }

    #[test]
    fn face_box_from_eyes_puts_eyes_where_the_detector_does() {
        let (r, l) = (Point::new(100.0, 80.0), Point::new(157.0, 80.0));
        let b = face_box_from_eyes(r, l);
        assert!((b.width - 57.0 / EYE_DISTANCE_PER_BOX_WIDTH).abs() < 1e-9);
        let mid_x = (r.x - b.x) / b.width + (l.x - b.x) / b.width;
        assert!((mid_x / 2.0 - (RIGHT_EYE_IN_BOX.0 + LEFT_EYE_IN_BOX.0) / 2.0).abs() < 1e-9);
    }

    #[test]
    fn image_and_normalised_coordinates_round_trip() {
        let img = ramp(300, 300);
        let face = NormalizedFace::new(&img, Rect::new(20.0, 30.0, 225.0, 225.0));
        assert!((face.scale() - 1.5).abs() < 1e-12);
        let p = Point::new(123.4, 56.7);
        let q = face.to_image(face.from_image(p));
        assert!(p.distance(q) < 1e-9);
    }

    #[test]
    fn turned_faces_round_trip_and_show_the_turned_image() {
        // A bright dot; in the face turned by the roll, it appears where `from_image` says.
        let img = GrayImage::from_fn(400, 400, |x, y| {
            let d2 = (f64::from(x) - 230.0).powi(2) + (f64::from(y) - 170.0).powi(2);
            image::Luma([(255.0 * (-d2 / 8.0).exp()) as u8])
        });
        let b = Rect::new(120.0, 110.0, 150.0, 150.0);
        for degrees in [20.0f64, -35.0] {
            let face = NormalizedFace::rotated(&img, b, degrees.to_radians());
            let p = Point::new(12.5, -30.25);
            assert!(face.from_image(face.to_image(p)).distance(p) < 1e-9);
            // The box centre is the pivot.
            let centre = face.to_image(Point::new(75.0, 75.0));
            assert!(centre.distance(Point::new(195.0, 185.0)) < 1e-9);
            let dot = face.from_image(Point::new(230.0, 170.0));
            let mut patch = vec![0f32; 9 * 9];
            face.patch(
                Point::new(dot.x.round(), dot.y.round()),
                9,
                0.0,
                0.0,
                &mut patch,
            );
            let (best, _) =
                patch.iter().enumerate().fold(
                    (0, f32::MIN),
                    |acc, (i, &v)| if v > acc.1 { (i, v) } else { acc },
                );
            let (bx, by) = ((best % 9) as f64 - 4.0, (best / 9) as f64 - 4.0);
            let off = (bx - (dot.x - dot.x.round()), by - (dot.y - dot.y.round()));
            assert!(
                off.0.abs() <= 1.0 && off.1.abs() <= 1.0,
                "{degrees}: {off:?}"
            );
        }
        // A roll of 0 is the axis-aligned face exactly.
        let plain = NormalizedFace::new(&img, b);
        let turned = NormalizedFace::rotated(&img, b, 0.0);
        assert_eq!(plain.pixels, turned.pixels);
    }

    #[test]
    fn deshear_patch_shifts_rows() {
        // A vertical bright line at x = 100; in a view sheared by k, row v shows it at
        // 100 - k (v - pivot).
        let img = GrayImage::from_fn(300, 300, |x, _| {
            image::Luma([if x == 100 { 255 } else { 0 }])
        });
        let face = NormalizedFace::new(&img, Rect::new(0.0, 0.0, 150.0, 150.0));
        let mut patch = vec![0f32; 16 * 16];
        let k = 0.25;
        face.patch(Point::new(100.0, 50.0), 16, k, 42.0, &mut patch);
        // Row j = 0 is v = 42, the pivot: the line at patch column 8.
        let argmax = |row: &[f32]| {
            row.iter()
                .enumerate()
                .max_by(|a, b| a.1.total_cmp(b.1))
                .map(|(i, _)| i)
                .unwrap_or(0)
        };
        assert_eq!(argmax(&patch[0..16]), 8);
        // Row j = 8 is v = 50: the line appears at 100 - 0.25 * 8 = 98, patch column 6.
        assert_eq!(argmax(&patch[8 * 16..9 * 16]), 6);
    }

    /// The per-sample loop `NormalizedFace::patch` replaced: the same arithmetic, with the
    /// inside test made for every sample.
    fn patch_sample_by_sample(
        face: &NormalizedFace,
        centre: Point,
        size: usize,
        k: f64,
        pivot_v: f64,
    ) -> Vec<f32> {
        let half = (size / 2) as f64;
        let last_x = face.width.saturating_sub(1);
        let mut out = vec![0f32; size * size];
        for (j, row) in out.chunks_exact_mut(size).enumerate() {
            let v = centre.y - half + j as f64;
            let u0 = centre.x - half + k * (v - pivot_v);
            let y = (v + MARGIN_Y as f64).clamp(0.0, (face.height - 1) as f64);
            let y0 = y.floor() as usize;
            let y1 = (y0 + 1).min(face.height - 1);
            let fy = (y - y0 as f64) as f32;
            let (row0, row1) = (face.row(y0), face.row(y1));
            let x_start = u0 + MARGIN_X as f64;
            let first = x_start.floor();
            let fx = (x_start - first) as f32;
            for (i, o) in row.iter_mut().enumerate() {
                let x = first + i as f64;
                *o = if x >= 0.0 && (x as usize) < last_x {
                    let a = x as usize;
                    let top = row0[a] + (row0[a + 1] - row0[a]) * fx;
                    let bottom = row1[a] + (row1[a + 1] - row1[a]) * fx;
                    top + (bottom - top) * fy
                } else {
                    face.sample(u0 + i as f64, v)
                };
            }
        }
        out
    }

    #[test]
    fn patches_are_those_of_the_sample_by_sample_loop_bit_for_bit() {
        let img = GrayImage::from_fn(200, 180, |x, y| {
            image::Luma([((x * 7 + y * 3) % 97 + (x * y) % 41) as u8])
        });
        let face = NormalizedFace::new(&img, Rect::new(30.0, 20.0, 120.0, 120.0));
        let (w, h) = (face.width as f64, face.height as f64);
        let mut checked = 0;
        for size in [1, 16, 24, 64] {
            for k in [0.0, 0.37, -0.8] {
                // Inside, across the left and right edges, wholly outside either side, and
                // a centre that is not a number.
                for (cx, cy) in [
                    (60.3, 70.6),
                    (3.2 - MARGIN_X as f64, 10.4),
                    (w - MARGIN_X as f64 - 5.7, 30.1),
                    (-300.0, 50.5),
                    (w + 200.0, 50.5),
                    (20.25, h),
                    (f64::NAN, 40.0),
                ] {
                    let centre = Point::new(cx, cy);
                    let mut patch = vec![0f32; size * size];
                    face.patch(centre, size, k, 40.0, &mut patch);
                    let reference = patch_sample_by_sample(&face, centre, size, k, 40.0);
                    let same = crate::testing::same_bits(&patch, &reference);
                    assert!(same, "size {size}, k {k}, centre {centre:?}");
                    checked += 1;
                }
            }
        }
        assert_eq!(checked, 4 * 3 * 7);
    }

    #[test]
    fn patch_reads_the_face_bilinearly_inside_and_edge_replicated_outside() {
        let img = GrayImage::from_fn(200, 180, |x, y| {
            image::Luma([((x * 7 + y * 3) % 97 + (x * y) % 41) as u8])
        });
        let face = NormalizedFace::new(&img, Rect::new(30.0, 20.0, 120.0, 120.0));
        let (size, k, pivot_v) = (16, 0.37, 40.0);
        // One patch well inside, one reaching past the margin's left edge.
        for centre in [
            Point::new(60.3, 70.6),
            Point::new(3.2 - MARGIN_X as f64, 10.4),
        ] {
            let mut patch = vec![0f32; size * size];
            face.patch(centre, size, k, pivot_v, &mut patch);
            let half = (size / 2) as f64;
            for j in 0..size {
                for i in 0..size {
                    let v = centre.y - half + j as f64;
                    let u = centre.x - half + i as f64 + k * (v - pivot_v);
                    let expected = face.sample(u, v);
                    assert!(
                        (patch[j * size + i] - expected).abs() < 1e-3,
                        "{centre:?} ({i}, {j}): {} vs {expected}",
                        patch[j * size + i]
                    );
                }
            }
        }
    }

    #[test]
    fn turned_face_pixels_are_the_image_at_their_mapped_points() {
        // A linear ramp is reproduced exactly by bilinear reads at unit scale, so every pixel
        // of the turned face must equal the ramp at the image point `to_image` maps it to.
        let ramp = |x: f64, y: f64| 0.5 * x + 0.25 * y;
        let img = GrayImage::from_fn(400, 400, |x, y| {
            image::Luma([ramp(f64::from(x), f64::from(y)) as u8])
        });
        let face = NormalizedFace::rotated(&img, Rect::new(120.0, 110.0, 150.0, 150.0), 0.3);
        for (v, u) in [(0.0, 0.0), (40.0, 75.0), (100.0, 140.0), (-20.0, -30.0)] {
            let p = face.to_image(Point::new(u, v));
            let got = face.sample(u, v);
            assert!(
                (f64::from(got) - ramp(p.x, p.y)).abs() < 1.0,
                "({u}, {v}) -> {p:?}: {got} vs {}",
                ramp(p.x, p.y)
            );
        }
    }

    #[test]
    fn standardized_vectors_correlate_by_their_dot_product() {
        let a = [1.0f32, 4.0, 2.0, 8.0, 5.0];
        let b = [3.0f32, 1.0, 2.0, 7.0, 9.0];
        let (mut sa, mut sb) = (a, b);
        standardize(&mut sa);
        standardize(&mut sb);
        let expected = crate::filters::zero_mean_correlation(&a, &b);
        assert!((dot(&sa, &sb) - expected).abs() < 1e-6);
        assert!((dot(&sa, &sa) - 1.0).abs() < 1e-6);
        let mut flat = [2.0f32; 4];
        standardize(&mut flat);
        assert_eq!(flat, [0.0; 4]);
    }

    #[test]
    fn gradients_of_a_ramp_are_its_slopes() {
        let side = 6;
        let patch: Vec<f32> = (0..side * side)
            .map(|i| (3 * (i % side) + 5 * (i / side)) as f32)
            .collect();
        let mut out = vec![0f32; gradient_len(side)];
        gradients(&patch, side, &mut out);
        let (gx, gy) = out.split_at(16);
        assert!(gx.iter().all(|&g| g == 6.0), "{gx:?}");
        assert!(gy.iter().all(|&g| g == 10.0), "{gy:?}");
    }

    #[test]
    fn a_pair_scores_its_features_by_the_weights() {
        let located = Located {
            position: Point::new(0.0, 0.0),
            peak: Peak {
                dx: 0.0,
                dy: 0.0,
                value: 1.0,
                psr: 5.0,
            },
        };
        for (i, w) in EYE_PAIR_WEIGHTS.iter().enumerate() {
            let mut features = [0.0; EYE_PAIR_FEATURES.len()];
            features[i] = 2.0;
            let pair = EyePair {
                right: located,
                left: located,
                features,
            };
            assert!(
                (pair.score() - 2.0 * w).abs() < 1e-12,
                "{}",
                EYE_PAIR_FEATURES[i]
            );
        }
    }

    /// The fixture's eyes located in the box the detector would draw for them.
    fn fixture_face(filters: &EyeFilters) -> (GrayImage, NormalizedFace) {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/fixtures/faces/subject01.normal.jpeg");
        let gray = image::open(&path).expect("fixture").to_luma8();
        let mut locator = FeatureLocator::new(filters);
        let first = NormalizedFace::new(&gray, Rect::new(95.0, 60.0, 130.0, 130.0));
        let seed = locator.locate(&first, Some(0.0));
        let face = NormalizedFace::new(&gray, face_box_from_eyes(seed.right_eye, seed.left_eye));
        (gray, face)
    }

    #[test]
    fn nostrils_read_from_their_band_are_those_of_the_whole_face_bit_for_bit() {
        let filters = EyeFilters::embedded().expect("built-in filters");
        let (gray, _) = fixture_face(&filters);
        let (w, h) = (f64::from(gray.width()), f64::from(gray.height()));
        let mut locator = FeatureLocator::new(&filters);
        let mut band_rows = 0;
        let mut whole_rows = 0;
        // The fixture's eyes, eyes tilted, small and large faces, faces at and past the
        // photo's edges, with shears up to the largest the network crops with.
        for (right, left, k) in [
            ((132.0, 104.0), (190.0, 103.0), 0.0),
            ((132.0, 104.0), (190.0, 103.0), 0.8),
            ((132.0, 104.0), (190.0, 103.0), -0.8),
            ((130.0, 90.0), (185.0, 118.0), 0.3),
            ((150.0, 100.0), (162.0, 101.0), -0.2),
            ((60.0, 80.0), (230.0, 85.0), 0.1),
            ((5.0, 3.0), (40.0, 4.0), 0.5),
            ((w - 30.0, h - 4.0), (w + 10.0, h - 2.0), -0.4),
            ((-40.0, h + 20.0), (-5.0, h + 22.0), 0.2),
        ] {
            let (r, l) = (Point::new(right.0, right.1), Point::new(left.0, left.1));
            let face_box = face_box_from_eyes(r, l);
            let whole = NormalizedFace::new(&gray, face_box);
            let (v_lo, v_hi) = nostril_band(face_box, r, l, k, filters.size());
            let band = NormalizedFace::band(&gray, face_box, v_lo, v_hi);
            band_rows += band.pixels.len() / band.width;
            whole_rows += whole.height;
            let from_whole = locator.nostrils_below(&whole, r, l, k);
            let from_band = locator.nostrils_below(&band, r, l, k);
            for ((p, psr), (q, qsr)) in from_whole.iter().zip(&from_band) {
                assert_eq!(
                    (p.x.to_bits(), p.y.to_bits(), psr.to_bits()),
                    (q.x.to_bits(), q.y.to_bits(), qsr.to_bits()),
                    "eyes {r:?} {l:?}, k {k}"
                );
            }
        }
        // The point of the band: well under half of the face's rows.
        assert!(
            band_rows * 2 < whole_rows,
            "{band_rows} of {whole_rows} rows"
        );
    }

    #[test]
    fn eye_pairs_pair_every_candidate_and_the_search_keeps_the_best_scored() {
        let filters = EyeFilters::embedded().expect("built-in filters");
        let (_, face) = fixture_face(&filters);
        let mut locator = FeatureLocator::new(&filters);
        let EyeSearch::Pairs(pairs) = locator.eye_pairs(&face, 0.0, EYE_CANDIDATES) else {
            panic!("an upright face's eyes lie inside their windows");
        };
        // Every right candidate with every left one (a window may hold fewer local maxima).
        assert!(
            (2..=EYE_CANDIDATES * EYE_CANDIDATES).contains(&pairs.len()),
            "{} pairs",
            pairs.len()
        );
        // The first pair is both windows' highest values: heights 1 and 1.
        assert_eq!(pairs[0].features[0], 1.0);
        assert_eq!(pairs[0].features[1], 1.0);
        for p in &pairs {
            assert!(p.features.iter().all(|f| f.is_finite()));
            assert!((-1.0..=1.0).contains(&p.features[8]), "{:?}", p.features);
        }
        let best = pairs
            .iter()
            .max_by(|a, b| a.score().total_cmp(&b.score()))
            .expect("pairs");
        let (right, left) = locator.find_eyes(&face, 0.0);
        assert_eq!((right, left), (best.right, best.left));
        // Mirror-image eyes: the right pair's symmetry is high.
        assert!(best.features[8] > 0.5, "{:?}", best.features);
    }

    #[test]
    fn the_mouth_searched_in_a_wrong_view_is_found_again_in_its_own() {
        let filters = EyeFilters::embedded().expect("built-in filters");
        let (_, face) = fixture_face(&filters);
        let mut locator = FeatureLocator::new(&filters);
        let upright = locator.locate(&face, Some(0.0));
        let truth = upright
            .mouth
            .expect("the built-in filters have a mouth filter");
        let eye_distance = upright.right_eye.distance(upright.left_eye);
        // Searched in views 0.15 off either way (the mouth seen sheared, 0.17 eye distances
        // sideways of the window's centre), it is found where the upright view finds it.
        for k in [0.15, -0.15] {
            let wrong = locator.locate(&face, Some(k));
            let mouth = wrong.mouth.expect("mouth");
            assert!(
                mouth.distance(truth) < 0.05 * eye_distance,
                "view {k}: {mouth:?} vs {truth:?} (eye distance {eye_distance})"
            );
        }
    }
}

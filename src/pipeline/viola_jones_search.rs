//! The face search: which views of the image are searched (de-sheared and turned), Viola-Jones
//! in each, and the boxes moved back to the input image.

use std::borrow::Cow;

use image::GrayImage;
use rayon::prelude::*;

use super::combine::{measured_shear, most_confident_of_overlapping};
use super::proposals::{proposal_detections, proposal_is_new, proposal_shows};
use super::report::FoundBox;
use super::Unshear;
use crate::config::Locator;
use crate::detect::boxes::{box_around_eyes, eyes_in_box};
use crate::detect::{Cascade, DetectorParams, FaceDetector};
use crate::geometry::{Point, Rect, Shear};
use crate::warp::{self, Canvas, Interpolation, Placement};

/// Shears whose de-sheared views the quick search tries when the image as it is gives no face
/// with an accepted estimate: the cascade tolerates about |k| = 0.15, so +-0.3 and then +-0.5 leave
/// at most 0.1 of residual shear for every |k| from 0.2 to 0.6.
pub const DEFAULT_SHEAR_HYPOTHESES: [f64; 4] = [0.3, -0.3, 0.5, -0.5];

/// Head rolls (degrees) whose turned views the quick search tries after the de-sheared ones when
/// no view found a face: the cascade tolerates about 10 degrees of roll. The de-sheared views are
/// not also turned: that made a face-free image several times slower to search.
pub const DEFAULT_ROLL_HYPOTHESES: [f64; 2] = [12.0, -12.0];

/// Shears whose de-sheared views the thorough search searches: every 0.15 up to 0.45 each way,
/// so that every |k| up to about 0.5 is left with at most 0.075 of residual shear (the cascade's
/// marginal faces are lost to less than its nominal 0.15 tolerance).
pub const THOROUGH_SHEAR_HYPOTHESES: [f64; 6] = [0.15, -0.15, 0.3, -0.3, 0.45, -0.45];

/// Head rolls (degrees) whose turned views the thorough search searches: with the cascade's
/// tolerance of about 10 degrees, views at 12, 25 and 45 degrees each way reach heads rolled up to
/// about 55 degrees.
pub const THOROUGH_ROLL_HYPOTHESES: [f64; 6] = [12.0, -12.0, 25.0, -25.0, 45.0, -45.0];

/// Where the scale ladder of every other de-sheared view of the thorough search starts, in steps
/// of the scale factor: halfway between OpenCV's rungs, so that neighbouring views scan different
/// scales and a face the cascade barely sees at one scale is still found, at no extra cost.
pub(crate) const THOROUGH_HALF_STEP_LADDER: f64 = 0.5;

/// The smallest head roll (degrees) whose turned view the thorough search also searches
/// de-sheared: a face rolled 25 degrees or more and sheared is upright in neither kind of view
/// alone.
pub(crate) const TURNED_DESHEARED_MIN_ROLL: f64 = 20.0;

/// The shears the strong-roll turned views are de-sheared by when no face was accepted (with an
/// accepted face, its measured shear is used instead).
pub(crate) const TURNED_DESHEARED_SHEARS: [f64; 2] = [0.3, -0.3];

/// The smallest measured shear for which the view de-sheared by it is searched for more faces:
/// rolling-shutter skew is one per frame, so faces the cascade missed sheared may show there.
pub(crate) const MEASURED_VIEW_MIN_SHEAR: f64 = 0.1;

/// The smallest box (pixels wide) kept of those with fewer raw hits than the main detector asks
/// for (the thorough search's lenient boxes): most false alarms are small, and faces this small
/// are too small to measure well anyway.
pub const WEAK_BOX_MIN_WIDTH: f64 = 60.0;

/// The smallest face (pixels) the thorough search looks for in its de-sheared and turned views:
/// they are searched for the faces the image as it is hides, and small boxes there are mostly false
/// alarms.
pub(crate) const THOROUGH_VIEW_MIN_FACE: u32 = 60;

/// Images larger than this (pixels) have their views searched one at a time (each view's scales
/// still in parallel), to bound memory: a turned view of a 12 MP photo is about 35 MB.
pub(crate) const PARALLEL_VIEWS_MAX_PIXELS: u64 = 4_000_000;

/// Most pixels a de-sheared or turned view may have, as a multiple of the input's: beyond it the
/// view is mostly padding (a very tall or very wide image de-sheared or turned), and searching
/// it would cost time and memory out of all proportion to the picture (a 308x56826 image
/// de-sheared by 0.3 is a 1-gigapixel view). Ordinary shapes stay below it: a 9:16 portrait
/// de-sheared by 0.45 and turned by 45 degrees is 3.6 times its input, a 4:1 panorama turned by
/// 45 degrees 3.1 times (docs/performance.md#extreme-shapes).
pub(crate) const MAX_VIEW_PIXELS_RATIO: f64 = 4.0;

/// The pixels of the view of a `width` x `height` image de-sheared by `k` onto a widened canvas
/// and then turned by `roll` radians (the bounding box of the turned canvas).
pub(crate) fn view_pixels(width: u32, height: u32, k: f64, roll: f64) -> f64 {
    let (w, h) = (f64::from(width), f64::from(height));
    let w = w + k.abs() * h;
    let (s, c) = (roll.sin().abs(), roll.cos().abs());
    (w * c + h * s) * (w * s + h * c)
}

/// Whether the view de-sheared by `k` and turned by `roll` stays within
/// [`MAX_VIEW_PIXELS_RATIO`] of the input's pixels.
pub(crate) fn view_is_bounded(width: u32, height: u32, k: f64, roll: f64) -> bool {
    let input = f64::from(width) * f64::from(height);
    (k == 0.0 && roll == 0.0)
        || view_pixels(width, height, k, roll) <= MAX_VIEW_PIXELS_RATIO * input
}

/// The raw hits a box of the thorough search needs: one, as the landmark network's face score,
/// not the detector's neighbour count, decides what is a face.
pub(crate) const THOROUGH_MIN_NEIGHBORS: u32 = 1;

/// How many of the cascade's last stages a window may fail and still count as a near miss in the
/// thorough search: faces the cascade barely sees come and go with a resampling, and near misses
/// bring them back; the network judges them strictly ([`NEAR_MISS_MIN_FACE_SCORE`]).
pub(crate) const THOROUGH_STAGE_SLACK: u32 = 3;

/// The network's face score a near miss (or a proposal window) needs to be taken for a face,
/// stricter than [`MIN_FACE_SCORE`] as the cascade itself turned its windows down: false faces
/// among near misses (ties, collars, fur) score up to about 0.994.
pub(crate) const NEAR_MISS_MIN_FACE_SCORE: f64 = 0.995;

/// Most boxes of one group of overlapping detections the network looks at (one per view): the
/// strongest box is not always the one the network crops well.
pub(crate) const THOROUGH_BOX_TRIES: usize = 3;

/// Box size of alt2 over `haarcascade_frontalface_default` for the same face (the median over
/// 459 faces both find in development photos no accuracy table measures;
/// `scripts/cascade_box_scale.py` measures it).
pub(crate) const DEFAULT_CASCADE_BOX_SCALE: f64 = 0.967;

/// One view the face search scans: the image de-sheared by `k` about its middle row, then
/// turned against a head roll of `roll` radians, scanned from the scale `scale_offset` steps up
/// the detector's ladder ([`DetectorParams::scale_offset`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct View {
    pub(crate) k: f64,
    pub(crate) roll: f64,
    pub(crate) scale_offset: f64,
}

impl View {
    /// The view on OpenCV's scale ladder.
    fn on_default_ladder(k: f64, roll: f64) -> Self {
        Self {
            k,
            roll,
            scale_offset: 0.0,
        }
    }
}

/// A detected face.
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub struct Detection {
    /// The face box in input-image pixels: where the detector's box lies in the de-sheared view,
    /// moved back so that its eye row is where the face's eyes are in the input.
    pub face_box: Rect,
    /// The shear the view was de-sheared by when the face was found (0: the image as it is).
    pub view_k: f64,
    /// The head roll the view was turned against when the face was found, radians (0: not
    /// turned; see [`DEFAULT_ROLL_HYPOTHESES`]).
    pub view_roll: f64,
    /// The detector's neighbour count (raw hits merged into the box; more is surer).
    pub neighbors: u32,
    /// Whether the box is a near miss of the detector, not one of its detections (see
    /// `FaceDetector::detect_with_near_misses` and the thorough search's stage slack).
    pub near_miss: bool,
}

/// A second face detector, asked only when the main one finds no face with an accepted
/// estimate, and how its boxes are mapped onto the main detector's.
///
/// The features are looked for where they sit in the main detector's boxes, so a fallback box is
/// first scaled about its centre by `box_scale` to the size the main detector would give the
/// same face.
#[derive(Debug, Clone)]
pub(crate) struct FallbackDetector {
    /// The detector.
    pub detector: FaceDetector,
    /// Main-detector box size over this detector's, for the same face.
    pub box_scale: f64,
}

impl FallbackDetector {
    /// The embedded `haarcascade_frontalface_default` with `params`, mapped onto alt2's boxes.
    pub fn frontal_face_default(params: DetectorParams) -> Self {
        Self {
            detector: FaceDetector::new(Cascade::frontal_face_default(), params),
            box_scale: DEFAULT_CASCADE_BOX_SCALE,
        }
    }
}

/// The detectors of [`FaceSearch::Thorough`]: both lenient ([`THOROUGH_MIN_NEIGHBORS`]); the
/// one for the de-sheared and turned views also skips boxes under [`THOROUGH_VIEW_MIN_FACE`].
#[derive(Debug, Clone)]
pub(crate) struct ThoroughDetectors {
    pub(crate) as_is: FaceDetector,
    pub(crate) views: FaceDetector,
    /// The de-sheared views ([`THOROUGH_SHEAR_HYPOTHESES`] unless set otherwise): kept here,
    /// not in `Unshear::shear_hypotheses`, so that the filters' quick search (which the
    /// thorough setting falls back to) keeps its own, measured to suit it better.
    pub(crate) shear_hypotheses: Vec<f64>,
}

/// `values` in groups of equal magnitude, the smallest first, each group in the given order.
pub(crate) fn groups_by_magnitude(values: &[f64]) -> Vec<Vec<f64>> {
    let mut sorted = values.to_vec();
    sorted.sort_by(|a, b| a.abs().total_cmp(&b.abs()));
    let mut groups: Vec<Vec<f64>> = Vec::new();
    for v in sorted {
        match groups.last_mut() {
            Some(g) if g[0].abs() == v.abs() => g.push(v),
            _ => groups.push(vec![v]),
        }
    }
    groups
}

impl Unshear {
    /// The lenient detectors when the thorough search is on and the network judges their boxes.
    pub(crate) fn thorough_detectors(&self) -> Option<&ThoroughDetectors> {
        self.thorough
            .as_ref()
            .filter(|_| self.locator() == Locator::Network)
    }

    /// Detects the faces in `gray`: first in the image as it is; when that finds none, in the
    /// image de-sheared by the shear hypotheses, smallest |k| first (both signs together), until
    /// a view finds a face, keeping the strongest of overlapping detections; when that finds
    /// none either, the same with the fallback detector.
    pub fn detect(&self, gray: &GrayImage) -> Vec<Detection> {
        for pass in self.detector_passes() {
            let as_is = self.detect_as_is(pass, gray);
            if !as_is.is_empty() {
                return as_is;
            }
            for group in self.view_groups() {
                let found = self.detect_under_hypotheses(pass, gray, &group);
                if !found.is_empty() {
                    return found;
                }
            }
        }
        Vec::new()
    }

    /// Every view searched after the image as it is, as `(shear, roll in radians)` groups in
    /// search order: the de-sheared views ([`Self::hypothesis_groups`]), then for each roll
    /// magnitude (smallest first) the turned image (see [`DEFAULT_ROLL_HYPOTHESES`] for why
    /// the de-sheared views are not turned too).
    pub(crate) fn view_groups(&self) -> Vec<Vec<(f64, f64)>> {
        let sheared = self
            .hypothesis_groups()
            .into_iter()
            .map(|g| g.into_iter().map(|k| (k, 0.0)).collect());
        let turned = groups_by_magnitude(&self.roll_hypotheses)
            .into_iter()
            .map(|g| g.into_iter().map(|r| (0.0, r.to_radians())).collect());
        sheared.chain(turned).collect()
    }

    /// Every view after the image as it is ([`Self::view_groups`], in search order). With
    /// `alternate_ladders` (the thorough search) the de-sheared groups take turns on the
    /// half-step scale ladder and OpenCV's, starting with the half-step one: see
    /// [`THOROUGH_HALF_STEP_LADDER`]. The turned views stay on OpenCV's.
    pub(crate) fn every_view(&self, alternate_ladders: bool) -> Vec<View> {
        self.view_groups()
            .into_iter()
            .enumerate()
            .flat_map(|(i, group)| {
                let de_sheared = group.iter().all(|&(_, roll)| roll == 0.0);
                let scale_offset = if alternate_ladders && de_sheared && i % 2 == 0 {
                    THOROUGH_HALF_STEP_LADDER
                } else {
                    0.0
                };
                group.into_iter().map(move |(k, roll)| View {
                    k,
                    roll,
                    scale_offset,
                })
            })
            .collect()
    }

    /// The shear hypotheses in groups of equal magnitude, the smallest first: the views nearest
    /// to the image as it is are searched first, and farther ones only if those fail, so a face
    /// is measured from the least warped view that finds it.
    pub(crate) fn hypothesis_groups(&self) -> Vec<Vec<f64>> {
        let shears = self
            .thorough_detectors()
            .map_or(&self.shear_hypotheses, |t| &t.shear_hypotheses);
        groups_by_magnitude(shears)
    }

    /// The main detector (boxes as they are; the lenient one of [`FaceSearch::Thorough`] when
    /// the network judges the boxes), then the fallback if there is one.
    pub(crate) fn detector_passes(&self) -> impl Iterator<Item = (&FaceDetector, f64)> {
        let main = self
            .thorough_detectors()
            .map_or(&self.detector, |t| &t.as_is);
        std::iter::once((main, 1.0))
            .chain(self.fallback.as_ref().map(|f| (&f.detector, f.box_scale)))
    }

    pub(crate) fn detect_as_is(
        &self,
        (detector, box_scale): (&FaceDetector, f64),
        gray: &GrayImage,
    ) -> Vec<Detection> {
        tagged_boxes(detector, gray)
            .map(|(face_box, neighbors, near_miss)| Detection {
                face_box: face_box.scaled_about_center(box_scale),
                view_k: 0.0,
                view_roll: 0.0,
                neighbors,
                near_miss,
            })
            .collect()
    }

    /// Detections in the views de-sheared and turned by each of `hypotheses` (shear, roll), the
    /// strongest of overlapping ones kept (most neighbours, then the smaller hypothesis).
    pub(crate) fn detect_under_hypotheses(
        &self,
        pass: (&FaceDetector, f64),
        gray: &GrayImage,
        hypotheses: &[(f64, f64)],
    ) -> Vec<Detection> {
        let views: Vec<View> = hypotheses
            .iter()
            .map(|&(k, roll)| View::on_default_ladder(k, roll))
            .collect();
        strongest_of_overlapping(self.detect_in_views(pass, gray, &views))
    }

    /// Every detection in `views`, moved back to `gray`, overlapping ones included.
    pub(crate) fn detect_in_views(
        &self,
        pass: (&FaceDetector, f64),
        gray: &GrayImage,
        views: &[View],
    ) -> Vec<Detection> {
        let search = |view: &View| {
            if view.scale_offset == pass.0.params().scale_offset {
                return self.detect_desheared(pass, gray, view.k, view.roll);
            }
            // The same cascade (shared, not copied) on the view's own scale ladder.
            let params = DetectorParams {
                scale_offset: view.scale_offset,
                ..*pass.0.params()
            };
            let detector = FaceDetector::new(pass.0.cascade().clone(), params);
            self.detect_desheared((&detector, pass.1), gray, view.k, view.roll)
        };
        // The views are independent detections: in parallel, so that one image's search uses
        // every core (a batch of images keeps them busy anyway; rayon shares the pool). A large
        // photo's views are searched one at a time, each view's scales still in parallel: a
        // view of a 12 MP photo turned by 45 degrees is about 35 MB, and the detections come
        // out the same in the same order either way.
        let found: Vec<Vec<Detection>> =
            if u64::from(gray.width()) * u64::from(gray.height()) > PARALLEL_VIEWS_MAX_PIXELS {
                views.iter().map(search).collect()
            } else {
                views.par_iter().map(search).collect()
            };
        found.into_iter().flatten().collect()
    }

    /// Detections in `gray` de-sheared by `k` about its middle row and then turned against a
    /// head roll of `roll` radians, moved back to `gray`.
    pub(crate) fn detect_desheared(
        &self,
        (detector, box_scale): (&FaceDetector, f64),
        gray: &GrayImage,
        k: f64,
        roll: f64,
    ) -> Vec<Detection> {
        let Some((view, back)) = desheared_view(gray, k, roll) else {
            return Vec::new();
        };
        let (view, rotation) = if roll == 0.0 {
            (view, None)
        } else {
            let turned = warp::rotate::rotate_gray(&view, -roll);
            // Freed before the search rather than at the end of the function, where a shadowed
            // binding would go: on a 12 MP photo, 16 MB for each view searched at once.
            drop(view);
            match turned {
                Ok((turned, rotation)) => (Cow::Owned(turned), Some(rotation)),
                Err(_) => return Vec::new(),
            }
        };
        tagged_boxes(detector, &view)
            .map(|(b, neighbors, near_miss)| {
                let b = b.scaled_about_center(box_scale);
                // The eye row's midpoint, from the view back to the input; the box keeps its
                // size and is placed around it as the detector placed it (for a turned view,
                // turned about its centre: see `NormalizedFace::rotated`).
                let eyes_in_box = eyes_in_box();
                let in_view = Point::new(
                    b.x + eyes_in_box.0 * b.width,
                    b.y + eyes_in_box.1 * b.height,
                );
                let desheared = rotation.map_or(in_view, |r| r.to_input(in_view));
                let eyes = back.to_input(desheared);
                Detection {
                    face_box: box_around_eyes(eyes, b.width, b.height, roll),
                    view_k: k,
                    view_roll: roll,
                    neighbors,
                    near_miss,
                }
            })
            .collect()
    }

    /// The views, de-sheared and turned at once, that the thorough search adds after its
    /// thirteen: a strongly rolled face that is also sheared is neither upright in a turned view
    /// (still sheared) nor in a de-sheared one (still rolled). Each roll hypothesis of at least
    /// [`TURNED_DESHEARED_MIN_ROLL`] degrees is combined with the shear measured on the accepted
    /// faces of `found` (rolling-shutter skew is one per frame) when that is at least
    /// [`MEASURED_VIEW_MIN_SHEAR`], or with each of [`TURNED_DESHEARED_SHEARS`] when no face was
    /// accepted; none when the faces found measure no shear. Each keeps its turned view's scale
    /// ladder (OpenCV's).
    pub(crate) fn turned_desheared_views(&self, found: &[FoundBox]) -> Vec<View> {
        let shears = match measured_shear(found) {
            Some(k) if k.abs() >= MEASURED_VIEW_MIN_SHEAR => vec![k],
            Some(_) => return Vec::new(),
            None => TURNED_DESHEARED_SHEARS.to_vec(),
        };
        // Each turned view keeps its scale ladder (`every_view`).
        let turned: Vec<View> = self
            .every_view(true)
            .into_iter()
            .filter(|v| v.k == 0.0 && v.roll.to_degrees().abs() >= TURNED_DESHEARED_MIN_ROLL)
            .collect();
        shears
            .iter()
            .flat_map(|&k| turned.iter().map(move |v| View { k, ..*v }))
            .collect()
    }

    /// Faces of `found`'s image that the image de-sheared by the shear measured on `found`'s
    /// accepted faces shows and `found` lacks.
    ///
    /// Rolling-shutter skew is the same for every face of a frame, so when the faces found
    /// measure a shear of at least [`MEASURED_VIEW_MIN_SHEAR`], other faces in the image are
    /// sheared as much and may have been missed by the cascade (each face's own pose decides
    /// whether the cascade tolerates it); one more detection in the view de-sheared by that shear
    /// finds them.
    pub(crate) fn detections_in_measured_view(
        &self,
        gray: &GrayImage,
        found: &[FoundBox],
    ) -> Vec<Detection> {
        let Some(k) = measured_shear(found) else {
            return Vec::new();
        };
        if k.abs() < MEASURED_VIEW_MIN_SHEAR {
            return Vec::new();
        }
        self.detect_under_hypotheses((&self.detector, 1.0), gray, &[(k, 0.0)])
            .into_iter()
            .filter(|d| found.iter().all(|f| f.face_box.iou(&d.face_box) < 0.3))
            .collect()
    }

    /// The Viola-Jones search in every view of every image (the thorough search, or
    /// [`Config::search_every_view`](crate::Config::search_every_view)): the image as it is and
    /// every de-sheared and turned view at once, with the proposal windows added when the
    /// thorough search has them, the fallback detector's pass only when the main one's faces
    /// give no accepted estimate; then, thorough, the turned views of strong rolls again in the
    /// image de-sheared by the shear its faces measured (or one step each way if none was
    /// accepted): a face both rolled and sheared is upright in neither kind of view alone. Of
    /// overlapping faces the one with the higher confidence is kept.
    pub(crate) fn every_view_search(&self, gray: &GrayImage) -> Vec<FoundBox> {
        let mut all: Vec<FoundBox> = Vec::new();
        let thorough = self.thorough_detectors();

        // A face is the first of its group's boxes that the network takes for one: the
        // strongest box can be cropped worse than a weaker one from another view.
        let faces = |mut found: Vec<Detection>| {
            found.retain(|d| self.is_measurable(d));
            overlapping_groups(found)
                .into_iter()
                .filter_map(|group| {
                    tries_of_group(group)
                        .into_iter()
                        .find_map(|d| self.estimate_box(gray, d))
                })
                .collect::<Vec<_>>()
        };
        let views = self.every_view(thorough.is_some());
        for (i, pass) in self.detector_passes().enumerate() {
            let views_pass = match (i, thorough) {
                (0, Some(t)) => (&t.views, 1.0),
                _ => pass,
            };
            let mut found = self.detect_as_is(pass, gray);
            found.extend(self.detect_in_views(views_pass, gray, &views));
            all.extend(faces(found));
            if let (0, Some(_), Some(net)) = (i, thorough, &self.proposals) {
                // Strongest first, each judged against the faces found so far (the
                // cascade's and the stronger windows').
                for d in proposal_detections(net, gray, WEAK_BOX_MIN_WIDTH) {
                    if !proposal_is_new(&d, &all) {
                        continue;
                    }
                    if let Some(FoundBox {
                        face_box,
                        report: Some(r),
                    }) = self.estimate_box(gray, d)
                    {
                        if proposal_shows(&d, &r) {
                            all.push(FoundBox::face(face_box, r));
                        }
                    }
                }
            }
            if any_accepted(&all) {
                break;
            }
        }
        if let Some(t) = thorough {
            let views = self.turned_desheared_views(&all);
            if !views.is_empty() {
                // These views look for faces not found yet: a box, or the face it gives,
                // holding the eyes of a face already found is that face again.
                let found_eyes: Vec<(Point, Point)> = all
                    .iter()
                    .filter_map(|f| f.report.map(|r| (r.right_eye, r.left_eye)))
                    .collect();
                let holds_found = |b: &Rect| {
                    found_eyes
                        .iter()
                        .any(|&(r, l)| b.contains(r) && b.contains(l))
                };
                let mut found = self.detect_in_views((&t.views, 1.0), gray, &views);
                found.retain(|d| !holds_found(&d.face_box));
                // The boxes kept hold no found face; the face a box gave may still be one.
                let new = faces(found)
                    .into_iter()
                    .filter(|f| !f.report.is_some_and(|r| holds_found(&r.face_box)));
                all.extend(new.collect::<Vec<_>>());
            }
        }
        most_confident_of_overlapping(all)
    }

    /// The quick Viola-Jones search: the image as it is; the de-sheared retries (see
    /// [`Self::detect`]) also run when every face found in the image as it is gave no accepted
    /// estimate: a false detection, or a sheared face found but poorly measured, must not hide
    /// a face the retries would find. The views are searched in groups of equal |k|, nearest
    /// first, until one gives an accepted estimate. Of overlapping faces the one with the
    /// higher confidence is kept.
    ///
    /// When the main detector's faces (as they are and in the retries) still give no accepted
    /// estimate, the fallback detector, if set, goes through the same two steps and its faces
    /// join the others.
    pub(crate) fn quick_search(&self, gray: &GrayImage) -> Vec<FoundBox> {
        let mut all: Vec<FoundBox> = Vec::new();
        for (i, pass) in self.detector_passes().enumerate() {
            all.extend(
                self.detect_as_is(pass, gray)
                    .into_iter()
                    .filter_map(|d| self.estimate_box(gray, d)),
            );
            if any_accepted(&all) {
                if i == 0 {
                    // The usual case: the image as it is, in the detector's order, and any
                    // faces the shear measured on these hid from the cascade after them.
                    let more: Vec<Detection> = self.detections_in_measured_view(gray, &all);
                    all.extend(more.into_iter().filter_map(|d| self.estimate_box(gray, d)));
                    return all;
                }
                break;
            }
            for group in self.view_groups() {
                let turned = group.iter().any(|&(_, roll)| roll != 0.0);
                if turned && !all.is_empty() {
                    // Turned views look for faces the cascade cannot see upright; a face already
                    // found (if not trusted) is not searched for again at this extra cost.
                    break;
                }
                all.extend(
                    self.detect_under_hypotheses(pass, gray, &group)
                        .into_iter()
                        .filter_map(|d| self.estimate_box(gray, d)),
                );
                if any_accepted(&all) {
                    break;
                }
            }
            if any_accepted(&all) {
                break;
            }
        }
        most_confident_of_overlapping(all)
    }

    /// Whether the detection `d` is kept: a box the main detector's count would not have given
    /// (the thorough search's lenient boxes) is kept only at a size where a face can be
    /// measured, dropped before it is merged with others or costs the network a look.
    fn is_measurable(&self, d: &Detection) -> bool {
        let strict_neighbors = self.detector.params().min_neighbors;
        (d.neighbors >= strict_neighbors && !d.near_miss) || d.face_box.width >= WEAK_BOX_MIN_WIDTH
    }

    /// The detection `d`'s box with the face estimated in it, if any; `None` with the network
    /// when the box gives no face (its face score below the minimum, or no crop): the network
    /// looked and saw no face there. A near miss stands as a face only on the network's strong
    /// word ([`NEAR_MISS_MIN_FACE_SCORE`]).
    fn estimate_box(&self, gray: &GrayImage, d: Detection) -> Option<FoundBox> {
        let network = self.locator() == Locator::Network;
        let report = self.estimate_detection(gray, &d).filter(|r| {
            !d.near_miss || r.face_score.is_some_and(|s| s >= NEAR_MISS_MIN_FACE_SCORE)
        });
        (!network || report.is_some()).then_some(FoundBox {
            face_box: d.face_box,
            report,
        })
    }
}

/// Whether any face of `found` has an accepted estimate.
fn any_accepted(found: &[FoundBox]) -> bool {
    found
        .iter()
        .any(|f| f.report.is_some_and(|r| r.k.is_some()))
}

/// Where a point of a de-sheared view ([`desheared_view`]) is in the image it was made from.
#[derive(Debug, Clone, Copy)]
pub(crate) struct FromView {
    shear: Shear,
    placement: Placement,
}

impl FromView {
    /// `p` of the view, in the input image.
    pub(crate) fn to_input(self, p: Point) -> Point {
        self.shear.apply(self.placement.to_frame(p))
    }
}

/// `gray` de-sheared by `k` about its middle row, on a canvas wide enough to lose nothing, and
/// the map from it back to `gray`; `None` when the view, turned by `roll` after, would be
/// mostly padding (see [`MAX_VIEW_PIXELS_RATIO`]) or cannot be made.
pub(crate) fn desheared_view(
    gray: &GrayImage,
    k: f64,
    roll: f64,
) -> Option<(Cow<'_, GrayImage>, FromView)> {
    if !view_is_bounded(gray.width(), gray.height(), k, roll) {
        return None;
    }
    let shear = Shear::about_middle(k, gray.height());
    // No shear: the image itself (the warp would be an exact copy, with the default
    // placement: `warp`'s test `zero_shear_is_identity_for_every_variant`).
    let (view, placement) = if k == 0.0 {
        (Cow::Borrowed(gray), Placement::default())
    } else {
        let (view, placement) =
            warp::try_remove_shear_gray(gray, shear, Interpolation::Linear, Canvas::Expand).ok()?;
        (Cow::Owned(view), placement)
    };
    Some((view, FromView { shear, placement }))
}

/// `detector`'s boxes in `gray` with their neighbour counts, its near misses (none unless its
/// [`DetectorParams::stage_slack`] is set) tagged `true`.
pub(crate) fn tagged_boxes(
    detector: &FaceDetector,
    gray: &GrayImage,
) -> impl Iterator<Item = (Rect, u32, bool)> {
    let found = detector.detect_with_near_misses(gray);
    let detected = found.detected.into_iter().map(|(b, n)| (b, n, false));
    detected.chain(found.near_misses.into_iter().map(|(b, n)| (b, n, true)))
}

/// Of detections whose boxes overlap (IoU 0.3 or more), the strongest: a detection before a
/// near miss, then most detector neighbours, then the view least warped (smaller |shear|, then
/// smaller |roll|).
pub(crate) fn strongest_of_overlapping(found: Vec<Detection>) -> Vec<Detection> {
    overlapping_groups(found)
        .into_iter()
        .filter_map(|group| group.into_iter().next())
        .collect()
}

/// Detections grouped by overlap, each group strongest first (see [`strongest_of_overlapping`]
/// for the order): a detection joins the first group whose strongest box it overlaps (IoU 0.3
/// or more), or starts a new one.
pub(crate) fn overlapping_groups(mut found: Vec<Detection>) -> Vec<Vec<Detection>> {
    found.sort_by(|a, b| {
        a.near_miss
            .cmp(&b.near_miss)
            .then(b.neighbors.cmp(&a.neighbors))
            .then(a.view_k.abs().total_cmp(&b.view_k.abs()))
            .then(a.view_roll.abs().total_cmp(&b.view_roll.abs()))
    });
    let mut groups: Vec<Vec<Detection>> = Vec::new();
    for d in found {
        match groups
            .iter_mut()
            .find(|g| g[0].face_box.iou(&d.face_box) >= 0.3)
        {
            Some(group) => group.push(d),
            None => groups.push(vec![d]),
        }
    }
    groups
}

/// The first of a group of overlapping detections (strongest first, [`overlapping_groups`])
/// and the next ones from views not yet tried, at most [`THOROUGH_BOX_TRIES`] in all: the
/// boxes worth a look when the ones before gave no face.
pub(crate) fn tries_of_group(group: Vec<Detection>) -> Vec<Detection> {
    let mut tries: Vec<Detection> = Vec::new();
    for d in group {
        let new_view = tries
            .iter()
            .all(|t| (t.view_k, t.view_roll) != (d.view_k, d.view_roll));
        if new_view && tries.len() < THOROUGH_BOX_TRIES {
            tries.push(d);
        }
    }
    tries
}

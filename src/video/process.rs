//! One frame at a time: measure the motion into it, track the faces and estimate `k` on each,
//! calibrate the readout from them, take `k` (and each row's offset) from the motion once the
//! readout is known, else filter the faces' `k` over time, correct the frame; and the threaded
//! loop that reads, processes and writes a whole clip.

use std::collections::VecDeque;
use std::sync::mpsc;
use std::time::Instant;

use image::GrayImage;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::anchors::{SceneAnchors, ScenePlace};
use super::motion::{BandShift, FrameShift, MotionEstimator, MotionParams};
use super::readout::{
    row_time, Calibration, CalibrationParams, ReadoutCalibrator, RowMotion, ShearSample,
    VelocityCurve, VelocitySample,
};
use super::temporal::{FilterParams, ShearSmoother, Update, DEFAULT_SMOOTHING_LAG};
use super::timing::{readout_from_motion, BandReading, MotionTiming, VelocitySpline};
use super::tracker::{FaceTracker, TrackerParams, TrackerStats};
use super::VideoFrame;
use crate::locate::network::Budget;
use crate::pipeline::{combined_shear, FaceStart};
use crate::warp::Interpolation;
use crate::{FaceReport, Readout, Rect, Region, Result, Unshear};

/// Which `k` corrects the frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum KSource {
    /// The temporally filtered value (default).
    #[default]
    Filtered,
    /// This frame's own estimate; the filtered value on frames without one.
    Raw,
}

/// Where a frame's `k` came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ShearSource {
    /// The image velocity measured between frames times the line time (the readout fraction
    /// known or calibrated).
    Motion,
    /// The faces' shape: this frame's faces, filtered over time.
    Faces,
    /// No measurement: the last `k` held, or decaying to 0.
    #[default]
    None,
}

/// Settings of a video run (default: correct with the smoothed `k`, linear interpolation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProcessOptions {
    /// Face tracking.
    pub tracker: TrackerParams,
    /// Temporal filter of `k`.
    pub filter: FilterParams,
    /// Lag of the fixed-lag smoother, in frames: each frame is corrected (and reported) once
    /// this many later frames have been estimated; 0 for the causal filter alone.
    pub smoothing_lag: usize,
    /// Correct the frames (false: analysis only, frames pass through unchanged).
    pub correct: bool,
    /// Which `k` corrects.
    pub k_source: KSource,
    /// Row resampling.
    pub interpolation: Interpolation,
    /// The landmark network's work per face ([`Budget::VIDEO`] by default: fewer, cheaper
    /// crops than for stills; the temporal filter averages their noise).
    pub network_budget: Budget,
    /// The counter-clockwise turn a player gives the frames for display, degrees (a container's
    /// rotation flag: 0, 90, -90 or 180; other angles are not turned). The frames are analysed
    /// turned upright, so faces are found; turned a quarter (a phone held upright), they were
    /// read out along the picture's columns, and `k` is the displayed picture's vertical shear
    /// (`Unshear::face_by_columns`), undone on the stored frames along their rows.
    pub rotation: i32,
    /// How the frames, as given, were read out: [`Readout::Rows`] for a clip's stored frames
    /// (with [`Self::rotation`]), [`Readout::Columns`] for frames already turned upright from
    /// a clip recorded turned a quarter (OpenCV turns them so): the faces' readings are then
    /// converted to the vertical shear, and the frames (images only) de-sheared along their
    /// columns.
    pub readout: Readout,
    /// The camera's readout fraction `rho` (readout time over frame interval) when known, from a
    /// data sheet or an earlier calibration; `None`: calibrated on the clip from its faces.
    pub readout_fraction: Option<f64>,
    /// Take each frame's shear from the measured motion once `rho` is known (false: from the
    /// faces alone, as without a rolling-shutter model). Frames turned a quarter
    /// ([`Self::rotation`] 90 or -90, [`Readout::Columns`]) always use the faces.
    pub motion: bool,
    /// Also undo vertical motion's stretch (each row read from where the middle row's time puts
    /// it); off by default.
    pub vertical: bool,
    /// [`Region::Image`]: the whole frame (a camera's pan); [`Region::Face`]: each face region
    /// with its own shear, from its own motion once the readout is known (a subject moving in
    /// front of a still camera), the rest untouched.
    pub region: Region,
    /// While `rho` is being calibrated, hold up to this many frames back, so that they too are
    /// corrected from motion once it is known (memory: this many decoded frames; latency: up
    /// to this many frames at the start of a clip). 0 by default (the latency stays
    /// [`Self::smoothing_lag`]); `unshear video` holds [`DEFAULT_CALIBRATION_WINDOW`].
    pub calibration_window: usize,
    /// The motion estimator's settings.
    pub motion_params: MotionParams,
    /// The readout calibration's settings.
    pub calibration: CalibrationParams,
    /// Remove the motion blur along the rows of frames corrected from motion (`None`: off).
    pub deblur: Option<Deblur>,
}

/// Motion blur removal in video: each row of a frame corrected from motion is smeared by its
/// image velocity times the exposure, a box along the row ([`crate::deblur`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Deblur {
    /// Each row's exposure as a fraction of the frame interval, in (0, 1] (4 ms at 30
    /// frames/s is 0.12); `None`: estimated over the clip from the blur itself (the blur's
    /// length over the motion between frames is the exposure, a constant of the camera's
    /// settings like the readout), see [`VideoProcessor::exposure`].
    pub exposure: Option<f64>,
    /// The Wiener filter's noise-to-signal ratio ([`crate::deblur::DEFAULT_NOISE_TO_SIGNAL`]).
    pub noise_to_signal: f64,
}

impl Deblur {
    /// Motion blur removal for an `exposure` (fraction of the frame interval) with the default
    /// filter.
    ///
    /// # Errors
    /// [`crate::Error::InvalidArgument`] when `exposure` is not in (0, 1].
    pub fn new(exposure: f64) -> Result<Self> {
        if !(exposure > 0.0 && exposure <= 1.0) {
            return Err(crate::Error::InvalidArgument(format!(
                "the exposure must be in (0, 1] frame intervals (got {exposure})"
            )));
        }
        Ok(Self {
            exposure: Some(exposure),
            noise_to_signal: crate::deblur::DEFAULT_NOISE_TO_SIGNAL,
        })
    }

    /// Motion blur removal with the exposure estimated from the clip's blur, default filter.
    pub fn estimated() -> Self {
        Self {
            exposure: None,
            noise_to_signal: crate::deblur::DEFAULT_NOISE_TO_SIGNAL,
        }
    }
}

/// Frames moving at least this fast (pixels per frame) have their blur measured for the
/// exposure's estimate: slower ones blur by less than [`crate::deblur::MIN_FOUND_BLUR`] at any
/// exposure under half the frame interval.
const BLUR_SAMPLE_MIN_SPEED: f64 = 8.0;

/// Every this many frames one has its blur measured (about 2 ms a 1080p frame).
const BLUR_SAMPLE_EVERY: u64 = 3;

/// The exposure's estimate is the median of this many frames' at most, and needs at least
/// [`MIN_BLUR_SAMPLES`].
const MAX_BLUR_SAMPLES: usize = 60;

/// Frames whose blur must be measured before the exposure is estimated.
const MIN_BLUR_SAMPLES: usize = 5;

/// Frames `unshear video` holds back while the readout is calibrated (2 s at 30 frames/s).
pub const DEFAULT_CALIBRATION_WINDOW: usize = 60;

impl Default for ProcessOptions {
    fn default() -> Self {
        Self {
            tracker: TrackerParams::default(),
            filter: FilterParams::default(),
            smoothing_lag: DEFAULT_SMOOTHING_LAG,
            correct: true,
            k_source: KSource::Filtered,
            interpolation: Interpolation::Linear,
            network_budget: Budget::VIDEO,
            rotation: 0,
            readout: Readout::Rows,
            readout_fraction: None,
            motion: true,
            vertical: false,
            region: Region::Image,
            calibration_window: 0,
            motion_params: MotionParams::default(),
            calibration: CalibrationParams::default(),
            deblur: None,
        }
    }
}

/// What was found in one frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameResult {
    /// Frame number, from 0.
    pub index: u64,
    /// This frame's own estimate: the median of its faces' `k`, `None` without a usable face.
    pub k_raw: Option<f64>,
    /// This frame's temporally filtered `k`: smoothed with the [`ProcessOptions::smoothing_lag`]
    /// frames after it (the causal filter's value when the lag is 0).
    pub k: f64,
    /// The causal filter's `k` after this frame (from this and earlier frames only; what the
    /// tracker and the estimator of the next frame start from).
    pub k_causal: f64,
    /// The shear the frame was corrected by (`None` when correction is off).
    pub k_applied: Option<f64>,
    /// What the filter did with `k_raw`.
    pub update: Update,
    /// Every tracked face with an estimate, as [`Unshear::estimate_face`] reports it.
    pub faces: Vec<FaceReport>,
    /// The track of each face (same order): a face keeps its number from frame to frame.
    pub tracks: Vec<u64>,
    /// Each face's own image velocity `[vx, vy]`, pixels per frame: its eyes' displacement
    /// from the frame before and to the frame after (averaged when both are known).
    pub face_velocities: Vec<Option<[f64; 2]>>,
    /// Each face's shear from its own motion, `rho * vx / H`, once the readout is known.
    pub face_k_motion: Vec<Option<f64>>,
    /// Where [`Self::k`] came from.
    pub k_source: ShearSource,
    /// The readout fraction in use for this frame (given, or calibrated so far).
    pub readout_fraction: Option<f64>,
    /// The image velocity at the middle row's time, `[vx, vy]` pixels per frame (positive:
    /// content moving right and down), when motion was measured.
    pub velocity: Option<[f64; 2]>,
    /// The faces' own shear (`k_raw`) differs from the motion's by more than a face's reading
    /// can (its noise and its own bias, 3 sigma): reported, not hidden.
    pub faces_disagree: bool,
    /// The per-row offsets the frame was corrected by (motion only): output pixel `(x, y)` was
    /// read from `(x + row_shifts[y], y)`.
    #[serde(skip)]
    pub row_shifts: Option<Vec<f64>>,
    /// The motion blur removed at the middle row, pixels ([`ProcessOptions::deblur`], frames
    /// corrected from motion only).
    pub blur: Option<f64>,
}

/// One analysed frame waiting to be corrected and returned.
#[derive(Debug)]
struct Pending {
    frame: VideoFrame,
    result: FrameResult,
    /// The faces' smoothed `k`, once the smoother has it.
    smoothed: Option<f64>,
    /// The content's displacement from the previous frame to this one.
    before: Option<FrameShift>,
    /// ... and from this one to the next.
    after: Option<FrameShift>,
}

/// Readings kept for the readout's calibration at most (then the fit stops growing: a
/// camera's readout is a constant, known well long before).
const MAX_READINGS: usize = 4000;

/// Frame pairs on each side of a frame whose bands the velocity through its readout is fitted
/// to (see `VideoProcessor::row_motion`): 8 frame pairs in all, the pair before the frame's own
/// two and one more than a swing of 6 frames' period spans on either side.
const CURVE_PAIRS: u64 = 4;

/// Frame pairs kept for the readout from the motion alone (30 s at 30 frames/s).
const MAX_TIMING_PAIRS: usize = 900;

/// One face's shear reading for the readout's calibration.
#[derive(Debug, Clone, Copy)]
struct Reading {
    /// The face's identity for the calibration: its place in the scene when it moves with
    /// the scene (see [`SceneAnchors`]), else its track.
    track: u64,
    frame: u64,
    k: f64,
    weight: f64,
    /// Its eyes' row.
    row: f64,
    /// Its own velocity from its eyes' displacement between frames, pixels per frame.
    own_velocity: f64,
}

/// A face's place in one frame, for following it and for the readout calibration.
#[derive(Debug, Clone, Copy)]
struct TrackPoint {
    track: u64,
    /// Eye midpoint.
    mid: crate::Point,
    eye_distance: f64,
    /// Its accepted shear estimate and that estimate's weight.
    k: Option<f64>,
    weight: f64,
    /// Its displacement from the frame before, when the track was there.
    velocity: Option<(f64, f64)>,
    /// Its place in the scene, through the camera's measured motion.
    place: ScenePlace,
}

/// How the frames' `k` were found over a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SourceCounts {
    /// Frames whose `k` came from motion.
    pub motion: u64,
    /// Frames whose `k` came from their faces.
    pub faces: u64,
    /// Frames without a measurement (the last `k` held or decaying).
    pub none: u64,
    /// Motion frames whose faces disagreed with the motion ([`FrameResult::faces_disagree`]).
    pub disagreements: u64,
}

/// Tracker, estimator, motion model and smoother for one clip.
///
/// Frames go in with [`Self::process`] and come out, in order, [`ProcessOptions::smoothing_lag`]
/// frames later (the smoother needs the estimates of the frames after each one), or up to
/// [`ProcessOptions::calibration_window`] frames later while the readout fraction is being
/// calibrated; at the end of the stream [`Self::finish`] returns the frames still held.
#[derive(Debug)]
pub struct VideoProcessor<'a> {
    unshear: &'a Unshear,
    tracker: FaceTracker,
    /// With the network detector: the faces of the last frame, which the landmark network
    /// follows into the next, and the work done.
    followed: Vec<FaceReport>,
    network_stats: TrackerStats,
    smoother: ShearSmoother,
    options: ProcessOptions,
    next_index: u64,
    /// Analysed frames waiting for their smoothed `k` (or for the readout), oldest first.
    pending: VecDeque<Pending>,
    motion: MotionEstimator,
    /// The content's displacement into the last frame analysed.
    last_shift: Option<FrameShift>,
    /// The content's displacement into the frame before the last one, and into the one before
    /// that.
    prev_shift: Option<FrameShift>,
    prev_prev_shift: Option<FrameShift>,
    /// The displacements into the last frames returned (at most [`CURVE_PAIRS`]), each with
    /// its frame pair's first frame.
    emitted: VecDeque<(u64, FrameShift)>,
    /// Every face reading for the readout's calibration, and the band displacements around
    /// the frames they were read in.
    readings: Vec<Reading>,
    reading_bands: std::collections::HashMap<u64, Vec<(f64, BandShift)>>,
    /// The last fit of the readout over [`Self::readings`].
    fit: Option<Calibration>,
    /// The frame height (rows), for the readings' rates.
    height: u32,
    /// The readout fraction in use: given, or calibrated once known.
    rho: Option<f64>,
    /// Set when the calibration window filled before the readout was known: frames are no
    /// longer held for it.
    window_closed: bool,
    /// The faces of the last two frames analysed (oldest first), with their frame numbers.
    recent: VecDeque<(u64, Vec<TrackPoint>)>,
    next_track: u64,
    /// Where the view is in the scene, and the scene's faces seen so far.
    anchors: SceneAnchors,
    /// Every band displacement measured (up to [`MAX_TIMING_PAIRS`] frame pairs), for the
    /// readout from the motion alone.
    motion_bands: Vec<BandReading>,
    /// The frame pairs the last search of the readout from the motion saw, and what it found.
    timing: (usize, Option<MotionTiming>),
    /// The frame size of a first pass ([`Self::analyse_frame`]).
    analysed_size: Option<(u32, u32)>,
    counts: SourceCounts,
    /// Each measured frame's blur length over its motion: exposure samples.
    blur_samples: Vec<f64>,
}

impl<'a> VideoProcessor<'a> {
    /// A processor using `unshear`'s detector and filters.
    pub fn new(unshear: &'a Unshear, options: ProcessOptions) -> Self {
        Self {
            unshear,
            tracker: FaceTracker::new(unshear.cascade_detector().clone(), options.tracker),
            followed: Vec::new(),
            network_stats: TrackerStats::default(),
            smoother: ShearSmoother::new(options.filter, options.smoothing_lag),
            options,
            next_index: 0,
            pending: VecDeque::with_capacity(options.smoothing_lag.min(64) + 1),
            motion: MotionEstimator::new(options.motion_params),
            last_shift: None,
            prev_shift: None,
            prev_prev_shift: None,
            emitted: VecDeque::with_capacity(CURVE_PAIRS as usize),
            readings: Vec::new(),
            reading_bands: std::collections::HashMap::new(),
            fit: None,
            height: 0,
            rho: options.readout_fraction,
            window_closed: false,
            recent: VecDeque::with_capacity(3),
            next_track: 0,
            anchors: SceneAnchors::default(),
            analysed_size: None,
            motion_bands: Vec::new(),
            timing: (0, None),
            counts: SourceCounts::default(),
            blur_samples: Vec::new(),
        }
    }

    /// The exposure used to remove motion blur ([`ProcessOptions::deblur`]), as a fraction of
    /// the frame interval: the one given, or the median of the frames' blur lengths over their
    /// motion once five frames moving fast enough showed a blur
    /// ([`crate::deblur::blur_length`]); `None` without deblurring or before.
    pub fn exposure(&self) -> Option<f64> {
        let d = self.options.deblur?;
        d.exposure.or_else(|| {
            (self.blur_samples.len() >= MIN_BLUR_SAMPLES)
                .then(|| crate::stats::median(self.blur_samples.clone()))
                .flatten()
        })
    }

    /// Measures the blur of `frame`, which moved `dx` pixels since the last one, for the
    /// exposure's estimate, when the exposure is asked to be estimated.
    fn sample_blur(&mut self, frame: &GrayImage, index: u64, dx: f64) {
        let wanted = self.options.deblur.is_some_and(|d| d.exposure.is_none());
        if !wanted
            || self.blur_samples.len() >= MAX_BLUR_SAMPLES
            || !index.is_multiple_of(BLUR_SAMPLE_EVERY)
            || dx.abs() < BLUR_SAMPLE_MIN_SPEED
        {
            return;
        }
        // The middle third of the rows (a pan changing speed within the frame blurs the top
        // and bottom by other lengths); no longer than the motion (an exposure of at most
        // the frame interval).
        let h = frame.height();
        if let Some(length) = crate::deblur::blur_length(frame, h / 3..2 * h / 3, dx.abs()) {
            self.blur_samples.push(length / dx.abs());
        }
    }

    /// The tracker's work counts.
    pub fn tracker_stats(&self) -> TrackerStats {
        if self.unshear.uses_network_detector() {
            self.network_stats
        } else {
            self.tracker.stats()
        }
    }

    /// Estimates rejected by the filter so far.
    pub fn rejected(&self) -> u64 {
        self.smoother.filter().rejected()
    }

    /// Frames taken in but not returned yet.
    pub fn pending(&self) -> usize {
        self.pending.len()
    }

    /// The readout fraction in use: the one given, or the calibration's once it is known.
    pub fn readout_fraction(&self) -> Option<f64> {
        self.rho
    }

    /// The calibration of the readout fraction from every face reading so far, known or not
    /// (`None` without readings that move).
    pub fn calibration(&self) -> Option<Calibration> {
        self.fit
    }

    /// How the frames returned so far got their `k`.
    pub fn source_counts(&self) -> SourceCounts {
        self.counts
    }

    /// Whether this clip's shear can come from motion: asked for, and frames read out along
    /// their stored rows shown as stored (turned clips keep the faces' model).
    fn motion_model(&self) -> bool {
        self.options.motion && self.options.rotation == 0 && self.options.readout == Readout::Rows
    }

    /// Tracks and estimates one frame's luma, measures its motion and runs the causal filter;
    /// returns the frame's entry (its frame still to be filled in) and the smoothed `k` of the
    /// oldest frame not smoothed yet, when the smoother has it.
    fn analyse(&mut self, stored: &GrayImage) -> (Pending, Option<f64>) {
        // The motion into this frame is measured while its faces are searched for (the faces
        // are followed from where the motion into the last frame would take them).
        let mut motion = std::mem::take(&mut self.motion);
        let measure = self.motion_model();
        let gray = &*upright(stored, self.options.rotation);
        let height = gray.height();
        let (shift, mut faces) = rayon::join(
            || measure.then(|| motion.push(stored)).flatten(),
            || self.faces_in(gray),
        );
        self.motion = motion;
        self.anchors.advance(shift.as_ref().map(|s| (s.dx, s.dy)));
        let index = self.next_index;
        if let Some(dx) = shift.as_ref().map(|s| s.dx) {
            self.sample_blur(stored, index, dx);
        }
        if let Some(s) = shift.as_ref().filter(|_| index > 0) {
            if self.motion_bands.len() < MAX_TIMING_PAIRS * 8 {
                self.motion_bands
                    .extend(s.bands.iter().map(|b| BandReading {
                        pair: index - 1,
                        row: b.row,
                        dx: b.dx,
                        dy: b.dy,
                        sigma: b.sigma,
                    }));
            }
        }
        let before_last = std::mem::replace(&mut self.last_shift, shift.clone());
        self.prev_prev_shift = std::mem::replace(&mut self.prev_shift, before_last);
        if self.options.rotation.abs() == 90 || self.options.readout == Readout::Columns {
            for f in &mut faces {
                self.unshear.face_by_columns(f);
            }
        }
        self.next_index += 1;
        let (tracks, face_velocities) = self.associate(index, &faces, height);
        // Without faces the motion alone may tell the readout: refitted now and then.
        if self.motion_model()
            && self.options.readout_fraction.is_none()
            && index >= 4
            && index.is_multiple_of(if self.rho.is_none() { 5 } else { 30 })
        {
            self.height = height;
            self.refit();
        }
        let face_k_motion = vec![None; faces.len()];
        let k_raw = combined_shear(&faces);
        let (update, due) = self.smoother.push(k_raw);
        if let Some(last) = self.pending.back_mut() {
            last.after = shift.clone();
        }
        let k_causal = self.smoother.filter().k();
        let result = FrameResult {
            index,
            k_raw,
            k: k_causal,
            k_causal,
            k_applied: None,
            update,
            faces,
            tracks,
            face_velocities,
            face_k_motion,
            k_source: ShearSource::None,
            readout_fraction: self.rho,
            velocity: None,
            faces_disagree: false,
            row_shifts: None,
            blur: None,
        };
        let entry = Pending {
            frame: VideoFrame::Image(image::DynamicImage::new_luma8(0, 0)),
            result,
            smoothed: None,
            before: shift,
            after: None,
        };
        (entry, due)
    }

    /// The shear to start this frame's face search from: the motion's when the readout is
    /// known and the content's displacement into this frame was measured, else the causal
    /// filtered shear of the faces.
    fn view_k(&self, height: u32) -> f64 {
        match (self.rho, &self.last_shift) {
            (Some(rho), Some(s)) if self.motion_model() => rho * s.dx / f64::from(height.max(1)),
            _ => self.smoother.filter().k(),
        }
    }

    /// The faces of one upright frame, followed or detected and estimated.
    fn faces_in(&mut self, gray: &GrayImage) -> Vec<FaceReport> {
        // Start from the expected shear: the face is then searched for, and its features
        // located, in a nearly upright view.
        let view_k = self.view_k(gray.height());
        let unshear = self.unshear;
        let budget = self.options.network_budget;
        if unshear.uses_network_detector() {
            return self.follow_and_detect(gray, view_k);
        }
        let boxes = self.tracker.track(gray, view_k);
        let estimate = |&b: &Rect| {
            unshear.estimate_face(
                gray,
                b,
                FaceStart {
                    k: view_k,
                    roll: 0.0,
                    budget: Some(budget),
                },
            )
        };
        if boxes.len() > 1 {
            boxes.par_iter().filter_map(estimate).collect()
        } else {
            boxes.iter().filter_map(estimate).collect()
        }
    }

    /// Where the face at `mid` in the last frame is expected to have moved: its track's own
    /// last displacement, else the content's measured displacement, else nowhere.
    fn expected_move(&self, mid: crate::Point) -> (f64, f64) {
        let own = self.recent.back().and_then(|(_, points)| {
            points
                .iter()
                .find(|p| p.mid.distance(mid) < 1e-6)
                .and_then(|p| p.velocity)
        });
        own.or_else(|| self.last_shift.as_ref().map(|s| (s.dx, s.dy)))
            .unwrap_or((0.0, 0.0))
    }

    /// With the network detector: the faces of the last frame followed into this one by the
    /// landmark network, each started from its last eyes moved by [`Self::expected_move`],
    /// roll and the expected shear `view_k`; and on the frames where detection is due (see
    /// [`TrackerParams`]: every `redetect_interval` frames, every `lost_interval` while no face
    /// is followed) the faces the detector finds in the frame shrunk to `detect_width` columns
    /// that are not followed yet.
    fn follow_and_detect(&mut self, gray: &GrayImage, view_k: f64) -> Vec<FaceReport> {
        let unshear = self.unshear;
        let budget = self.options.network_budget;
        let moved: Vec<FaceReport> = self
            .followed
            .iter()
            .map(|f| {
                let (dx, dy) = self.expected_move(f.right_eye.midpoint(f.left_eye));
                let mut m = *f;
                for p in [&mut m.right_eye, &mut m.left_eye] {
                    p.x += dx;
                    p.y += dy;
                }
                m
            })
            .collect();
        let stats = &mut self.network_stats;
        let frame = stats.frames;
        stats.frames += 1;
        let follow = |last: &FaceReport| {
            let start = FaceStart {
                k: view_k,
                roll: 0.0,
                budget: Some(budget),
            };
            let face_box = crate::pipeline::box_from_eyes(last);
            unshear
                .estimate_face(gray, face_box, start)
                .filter(|r| crate::pipeline::follows(last, r))
                .map(|r| crate::pipeline::FoundBox::face(face_box, r))
        };
        let before = moved.len();
        let mut found: Vec<crate::pipeline::FoundBox> = if before > 1 {
            moved.par_iter().filter_map(follow).collect()
        } else {
            moved.iter().filter_map(follow).collect()
        };
        stats.local_searches += before as u64;
        stats.lost += (before - found.len()) as u64;
        let params = self.options.tracker;
        let interval = if found.is_empty() {
            params.lost_interval
        } else {
            params.redetect_interval
        };
        if frame.is_multiple_of(interval.max(1)) || (before > 0 && found.is_empty()) {
            stats.full_detections += 1;
            unshear.find_new_faces(gray, params.detect_width, view_k, budget, &mut found);
        }
        let mut faces: Vec<FaceReport> = found.into_iter().filter_map(|f| f.report).collect();
        faces.sort_by(|a, b| {
            let size = |f: &FaceReport| f.right_eye.distance(f.left_eye);
            size(b).total_cmp(&size(a))
        });
        faces.truncate(params.max_faces);
        self.followed = faces.clone();
        faces
    }

    /// Gives each face of frame `index` its track: the last frame's face expected nearest to it
    /// (within one eye distance), else a new one. Adds the calibration readings of the frame
    /// before, whose faces' velocities are now known on both sides.
    fn associate(
        &mut self,
        index: u64,
        faces: &[FaceReport],
        height: u32,
    ) -> (Vec<u64>, Vec<Option<[f64; 2]>>) {
        let last: Vec<TrackPoint> = self
            .recent
            .back()
            .filter(|(i, _)| i + 1 == index)
            .map(|(_, p)| p.clone())
            .unwrap_or_default();
        let mut taken = vec![false; last.len()];
        let mut points = Vec::with_capacity(faces.len());
        for f in faces {
            let mid = f.right_eye.midpoint(f.left_eye);
            let eye_distance = f.right_eye.distance(f.left_eye);
            let best = last
                .iter()
                .enumerate()
                .filter(|(i, _)| !taken[*i])
                .map(|(i, p)| {
                    let (dx, dy) = self.expected_move(p.mid);
                    let at = crate::Point::new(p.mid.x + dx, p.mid.y + dy);
                    (i, at.distance(mid), p)
                })
                .filter(|(_, d, p)| *d <= p.eye_distance.max(eye_distance))
                .min_by(|a, b| a.1.total_cmp(&b.1));
            let (track, velocity) = match best {
                Some((i, _, p)) => {
                    taken[i] = true;
                    (p.track, Some((mid.x - p.mid.x, mid.y - p.mid.y)))
                }
                None => {
                    self.next_track += 1;
                    (self.next_track - 1, None)
                }
            };
            let k = f.k.filter(|_| f.refused.is_none());
            points.push(TrackPoint {
                track,
                mid,
                eye_distance,
                k,
                weight: f.confidence.clamp(0.1, 1.0),
                velocity,
                place: self
                    .anchors
                    .place(mid.x, mid.y, k.unwrap_or(0.0), f64::from(height) / 2.0),
            });
        }
        if self.motion_model() {
            self.add_readings(&points, height);
        }
        let tracks = points.iter().map(|p| p.track).collect();
        let velocities = points
            .iter()
            .map(|p| p.velocity.map(|(x, y)| [x, y]))
            .collect();
        self.recent.push_back((index, points));
        while self.recent.len() > 2 {
            self.recent.pop_front();
        }
        (tracks, velocities)
    }

    /// The calibration readings of the last frame analysed before this one: each face with an
    /// accepted estimate, with its own velocity from the frames on both sides of it (or one),
    /// and the content's displacements into and out of its frame; then the readout refitted.
    fn add_readings(&mut self, next: &[TrackPoint], height: u32) {
        let Some((frame, points)) = self.recent.back() else {
            return;
        };
        let frame = *frame;
        self.height = height;
        let mut added = false;
        // The content's mean velocity through the frame: a face moving with it is part of the
        // scene, recognised by its place there when it comes back into view.
        let shifts: Vec<f64> = [&self.prev_shift, &self.last_shift]
            .into_iter()
            .flatten()
            .map(|s| s.dx)
            .collect();
        let background =
            (!shifts.is_empty()).then(|| shifts.iter().sum::<f64>() / shifts.len() as f64);
        for p in points {
            let Some(k) = p.k else { continue };
            if self.readings.len() >= MAX_READINGS {
                break;
            }
            let after = next
                .iter()
                .find(|q| q.track == p.track)
                .and_then(|q| q.velocity);
            let own = match (p.velocity, after) {
                (Some(a), Some(b)) => (a.0 + b.0) / 2.0,
                (Some(a), None) | (None, Some(a)) => a.0,
                (None, None) => continue,
            };
            let still = background.is_some_and(|b| moves_with(own, b));
            let track = if still {
                self.anchors.identify(p.track, p.place, p.eye_distance)
            } else {
                p.track
            };
            self.readings.push(Reading {
                track,
                frame,
                k,
                weight: p.weight,
                row: p.mid.y,
                own_velocity: own,
            });
            added = true;
        }
        if added {
            let n = frame as f64;
            let bands: Vec<(f64, BandShift)> = [
                (n - 2.0, &self.prev_prev_shift),
                (n - 1.0, &self.prev_shift),
                (n, &self.last_shift),
            ]
            .into_iter()
            .flat_map(|(pair, s)| {
                s.iter()
                    .flat_map(move |s| s.bands.iter().map(move |b| (pair, *b)))
            })
            .collect();
            self.reading_bands.insert(frame, bands);
        }
        // Refit every frame until known, then every 15 frames (the fit visits every reading).
        if added && (self.fit.is_none() || self.rho.is_none() || frame % 15 == 0) {
            self.refit();
        }
    }

    /// Fits the readout over the clip so far: to the faces' readings (each reading's rate is
    /// its face's velocity at its rows' time, from the band displacements around its frame when
    /// the face moves with them, exact for a pan changing speed within the frame, else its own
    /// displacement between frames: a subject moving by itself), and to the motion alone (see
    /// [`readout_from_motion`]); the two combined.
    fn refit(&mut self) {
        let params = self.options.calibration;
        let faces = self.fit_faces();
        // The motion alone tells the readout when the speed changes within the readouts; a
        // steady pan leaves it wide open (then the faces decide).
        let motion = self
            .motion_timing()
            .filter(|m| m.uncertainty.is_finite() && m.uncertainty < 0.5 * m.readout_fraction);
        let fit = match (faces, motion) {
            (f, None) => f,
            (None, Some(m)) => Some(Calibration {
                readout_fraction: m.readout_fraction,
                uncertainty: m.uncertainty,
                samples: 0,
                tracks: 0,
                frames: 0,
                motion_pairs: m.pairs,
            }),
            (Some(f), Some(m)) => {
                // Inverse-variance weighted, the uncertainty widened when the two disagree
                // beyond their own uncertainties (Birge's ratio).
                let (wf, wm) = (f.uncertainty.max(1e-6).powi(-2), m.uncertainty.powi(-2));
                let rho = (wf * f.readout_fraction + wm * m.readout_fraction) / (wf + wm);
                let chi2 = (f.readout_fraction - m.readout_fraction).powi(2)
                    / (f.uncertainty.powi(2) + m.uncertainty.powi(2));
                Some(Calibration {
                    readout_fraction: rho,
                    uncertainty: (wf + wm).sqrt().recip() * chi2.sqrt().max(1.0),
                    motion_pairs: m.pairs,
                    ..f
                })
            }
        };
        if self.options.readout_fraction.is_none() {
            if let Some(c) = fit.filter(|c| params.is_known(c)) {
                self.rho = Some(c.readout_fraction);
            }
        }
        self.fit = fit;
    }

    /// The readout from the motion alone, searched again only when the clip has grown by a
    /// fifth (and 8 frame pairs) since the last search: the search visits every frame pair.
    fn motion_timing(&mut self) -> Option<MotionTiming> {
        let pairs = self.motion_bands.len() / 8;
        let (searched, last) = self.timing;
        if searched == 0 || pairs >= searched + (searched / 5).max(8) {
            let found = readout_from_motion(&self.motion_bands, self.height);
            self.timing = (pairs, found);
            return found;
        }
        last
    }

    /// The readout fitted to the faces' readings alone (see [`Self::refit`]). Their rates depend
    /// on `rho`, so the fit is repeated from the last estimate (0.8 at first) until it settles.
    fn fit_faces(&self) -> Option<Calibration> {
        if self.readings.len() < 3 {
            return None;
        }
        let mut rho = self
            .fit
            .map_or(0.8, |c| c.readout_fraction)
            .clamp(0.05, 1.2);
        let mut fit = None;
        for _ in 0..3 {
            let mut calibrator = ReadoutCalibrator::new(self.options.calibration);
            for r in &self.readings {
                calibrator.add(ShearSample {
                    track: r.track,
                    frame: r.frame,
                    k: r.k,
                    rate: self.reading_velocity(r, rho) / f64::from(self.height.max(1)),
                    weight: r.weight,
                });
            }
            fit = calibrator.solve();
            match fit {
                Some(c) if c.readout_fraction > 0.05 && c.readout_fraction <= 1.2 => {
                    let settled = (c.readout_fraction - rho).abs() < 1e-3;
                    rho = c.readout_fraction;
                    if settled {
                        break;
                    }
                }
                _ => break,
            }
        }
        fit
    }

    /// A reading's image velocity at its rows' time for readout `rho` (see [`Self::refit`]).
    fn reading_velocity(&self, r: &Reading, rho: f64) -> f64 {
        let h = self.height;
        let n = r.frame as f64;
        let Some(bands) = self.reading_bands.get(&r.frame).filter(|b| !b.is_empty()) else {
            return r.own_velocity;
        };
        let samples: Vec<VelocitySample> = bands
            .iter()
            .map(|(pair, b)| VelocitySample::from_band(*pair, b.row, b.dx, b.dy, b.sigma, rho, h))
            .collect();
        let Some(curve) = VelocityCurve::fit(&samples, n + rho / 2.0) else {
            return r.own_velocity;
        };
        let t = row_time(n, r.row, rho, h);
        // What the face's own central difference measures of the curve: the mean of its two
        // displacements.
        let background = (curve.mean_velocity(t - 0.5).0 + curve.mean_velocity(t + 0.5).0) / 2.0;
        if moves_with(r.own_velocity, background) {
            curve.velocity(t).0
        } else {
            r.own_velocity
        }
    }

    /// Takes one frame in (tracks, estimates, measures motion, filters) and returns the frames
    /// now due, oldest first, with their results and corrected (unchanged when correction is
    /// off): none while the first `smoothing_lag` frames fill the buffer, or while frames are
    /// held for the readout's calibration; several when a calibration releases them.
    ///
    /// # Errors
    /// Only if the shear to apply is not finite (which the filter never produces).
    pub fn process(&mut self, frame: VideoFrame) -> Result<Vec<(VideoFrame, FrameResult)>> {
        let (mut entry, due) = self.analyse(&frame.luma());
        entry.frame = frame;
        self.queue(entry, due);
        self.drain(false)
    }

    /// The end of the stream: every frame still held, in order, with `k` smoothed over all the
    /// frames seen and corrected as by [`Self::process`].
    ///
    /// # Errors
    /// As [`Self::process`].
    pub fn finish(&mut self) -> Result<Vec<(VideoFrame, FrameResult)>> {
        self.flush_smoother();
        self.drain(true)
    }

    /// Queues an analysed frame, giving the oldest frame not smoothed yet its smoothed `k`
    /// when the smoother has it (`due`).
    fn queue(&mut self, entry: Pending, due: Option<f64>) {
        self.pending.push_back(entry);
        if let Some(k) = due {
            if let Some(p) = self.pending.iter_mut().find(|p| p.smoothed.is_none()) {
                p.smoothed = Some(k);
            }
        }
    }

    /// The end of the stream for the smoother: every queued frame gets its smoothed `k`.
    fn flush_smoother(&mut self) {
        let mut ks = self.smoother.flush().into_iter();
        for p in self.pending.iter_mut().filter(|p| p.smoothed.is_none()) {
            p.smoothed = ks.next().or(Some(p.result.k_causal));
        }
    }

    /// The first of two passes over a clip (a file can be read twice): analyses one frame
    /// (tracks, estimates, measures motion, collects the readout's calibration readings) and
    /// keeps its results, not its pixels. After the last frame, [`Self::end_analysis`]; then
    /// the same frames again, in order, through [`Self::replay`].
    pub fn analyse_frame(&mut self, frame: &VideoFrame) {
        self.analysed_size.get_or_insert(frame.dimensions());
        let (entry, due) = self.analyse(&frame.luma());
        self.queue(entry, due);
    }

    /// The end of the first pass: every frame's `k` smoothed over the whole clip and the
    /// readout fitted to every reading of it, so that the second pass corrects every frame
    /// with the clip's readout (when it was found). Returns the frames analysed.
    pub fn end_analysis(&mut self) -> usize {
        self.flush_smoother();
        if self.motion_model() {
            // Over every frame pair, whatever the last search saw.
            self.timing = (0, None);
            self.refit();
        }
        // Nothing is held in the second pass.
        self.window_closed = true;
        self.pending.len()
    }

    /// The second pass: the next frame of the clip analysed by [`Self::analyse_frame`],
    /// corrected as [`Self::process`] would with the readout found over the whole clip.
    ///
    /// # Errors
    /// [`crate::Error::InvalidArgument`] when more frames come than were analysed; else as
    /// [`Self::process`].
    pub fn replay(&mut self, frame: VideoFrame) -> Result<(VideoFrame, FrameResult)> {
        let Some(mut entry) = self.pending.pop_front() else {
            return Err(crate::Error::InvalidArgument(
                "the second pass has more frames than the first analysed".into(),
            ));
        };
        if self
            .analysed_size
            .is_some_and(|size| size != frame.dimensions())
        {
            return Err(crate::Error::InvalidArgument(
                "the second pass's frames differ from the first's".into(),
            ));
        }
        entry.frame = frame;
        let k = entry.smoothed.unwrap_or(entry.result.k_causal);
        self.emit(entry, k)
    }

    /// Returns the frames at the front that are due: smoothed, and not held for the readout.
    fn drain(&mut self, at_end: bool) -> Result<Vec<(VideoFrame, FrameResult)>> {
        let mut out = Vec::new();
        while let Some(front) = self.pending.front() {
            let Some(smoothed) = front.smoothed else {
                break;
            };
            let waiting = self.motion_model() && self.rho.is_none() && !self.window_closed;
            if waiting && !at_end {
                if self.pending.len() <= self.options.calibration_window {
                    break;
                }
                self.window_closed = true;
            }
            if let Some(p) = self.pending.pop_front() {
                out.push(self.emit(p, smoothed)?);
            }
        }
        Ok(out)
    }

    /// The rolling shutter's row motion in `entry`'s frame, when the readout is known and the
    /// content's displacement around it was measured.
    ///
    /// The velocity through the frame's readout is one spline (the calibration's,
    /// [`VelocitySpline`]) through the bands of up to [`CURVE_PAIRS`] frame pairs on each side
    /// of the frame: the pairs of frames already returned, and those of the frames still held
    /// (the smoothing's lag, or the whole clip on a second pass). With fewer than three frame
    /// pairs at hand, a cubic about the frame ([`VelocityCurve`]).
    fn row_motion(&self, entry: &Pending, height: u32) -> Option<RowMotion> {
        let rho = self.rho.filter(|_| self.motion_model())?;
        let n = entry.result.index as f64;
        let index = entry.result.index;
        let earlier = self
            .emitted
            .iter()
            .filter(|(pair, _)| pair + CURVE_PAIRS >= index && pair + 1 < index)
            .map(|(pair, s)| (*pair as f64, Some(s)));
        let later = self
            .pending
            .iter()
            .take_while(|p| p.result.index < index + CURVE_PAIRS)
            .filter(|p| p.result.index > index)
            .map(|p| (p.result.index as f64, p.after.as_ref()));
        let mut samples = Vec::new();
        let mut pairs = 0;
        for (pair, shift) in earlier
            .chain([(n - 1.0, entry.before.as_ref()), (n, entry.after.as_ref())])
            .chain(later)
        {
            let Some(shift) = shift.filter(|s| !s.bands.is_empty()) else {
                continue;
            };
            pairs += 1;
            for b in &shift.bands {
                samples.push(VelocitySample::from_band(
                    pair, b.row, b.dx, b.dy, b.sigma, rho, height,
                ));
            }
        }
        if pairs >= 3 {
            if let Some(spline) = VelocitySpline::fit(&samples) {
                return Some(RowMotion::of(
                    &spline,
                    n,
                    rho,
                    height,
                    self.options.vertical,
                ));
            }
        }
        let curve = VelocityCurve::fit(&samples, n + rho / 2.0)?;
        Some(RowMotion::of(&curve, n, rho, height, self.options.vertical))
    }

    /// Completes the faces' velocities with the next frame's (now analysed, at the front of the
    /// queue) and, once the readout is known, gives each face its shear from its own motion.
    fn face_motion(&self, result: &mut FrameResult, height: u32) {
        if let Some(next) = self.pending.front() {
            let r = &next.result;
            for (i, track) in result.tracks.iter().enumerate() {
                let after = r
                    .tracks
                    .iter()
                    .position(|t| t == track)
                    .and_then(|j| r.face_velocities[j]);
                let v = &mut result.face_velocities[i];
                *v = match (*v, after) {
                    (Some(a), Some(b)) => Some([(a[0] + b[0]) / 2.0, (a[1] + b[1]) / 2.0]),
                    (a, b) => a.or(b),
                };
            }
        }
        if let Some(rho) = self.rho.filter(|_| self.motion_model()) {
            let h = f64::from(height.max(1));
            result.face_k_motion = result
                .face_velocities
                .iter()
                .map(|v| v.map(|[vx, _]| rho * vx / h))
                .collect();
        }
    }

    /// `--region face`: each face region (its box enlarged as for stills) de-sheared by its
    /// own shear: from its own motion when known, else its own estimate.
    fn correct_faces(
        &self,
        frame: VideoFrame,
        mut result: FrameResult,
    ) -> Result<(VideoFrame, FrameResult)> {
        let margin = 1.0 + 2.0 * crate::pipeline::FACE_REGION_MARGIN;
        let regions: Vec<(Rect, f64)> = result
            .faces
            .iter()
            .zip(&result.face_k_motion)
            .filter_map(|(f, km)| {
                km.or(f.k)
                    .map(|k| (f.face_box.scaled_about_center(margin), k))
            })
            .collect();
        result.k_applied = None;
        let upright = self.options.rotation == 0 && self.options.readout == Readout::Rows;
        if regions.is_empty() || !upright {
            return Ok((frame, result));
        }
        let corrected = frame.remove_shear_in_regions(&regions, self.options.interpolation)?;
        Ok((corrected, result))
    }

    /// Sets the frame's `k` (from motion, else the faces' smoothed value) and corrects it.
    fn emit(&mut self, entry: Pending, k_smoothed: f64) -> Result<(VideoFrame, FrameResult)> {
        let height = entry.frame.dimensions().1;
        let motion = self.row_motion(&entry, height);
        let Pending {
            frame,
            mut result,
            before,
            ..
        } = entry;
        if let Some(b) = before {
            if self.emitted.len() >= CURVE_PAIRS as usize {
                self.emitted.pop_front();
            }
            self.emitted.push_back((result.index.saturating_sub(1), b));
        }
        self.face_motion(&mut result, height);
        result.k = k_smoothed;
        result.readout_fraction = self.rho;
        result.k_source = if result.k_raw.is_some() {
            ShearSource::Faces
        } else {
            ShearSource::None
        };
        if let Some(m) = &motion {
            result.k = m.k;
            result.k_source = ShearSource::Motion;
            result.velocity = Some([m.velocity.0, m.velocity.1]);
            let p = self.options.calibration;
            let allowed = 3.0 * p.reading_noise.hypot(p.bias_spread);
            result.faces_disagree = result.k_raw.is_some_and(|k| (k - m.k).abs() > allowed);
        }
        match result.k_source {
            ShearSource::Motion => self.counts.motion += 1,
            ShearSource::Faces => self.counts.faces += 1,
            ShearSource::None => self.counts.none += 1,
        }
        self.counts.disagreements += u64::from(result.faces_disagree);
        if !self.options.correct {
            return Ok((frame, result));
        }
        if self.options.region == Region::Face {
            return self.correct_faces(frame, result);
        }
        if let (Some(m), KSource::Filtered) = (motion, self.options.k_source) {
            result.k_applied = Some(m.k);
            let interp = self.options.interpolation;
            // The blur is removed from the rows as read, before they are moved: a corrected
            // row's uncovered end is a sharp edge the blur never saw.
            let frame = match self.options.deblur.zip(self.exposure()) {
                Some((d, exposure)) => {
                    let lengths: Vec<f64> = m
                        .row_velocities
                        .iter()
                        .map(|v| exposure * v.abs())
                        .collect();
                    result.blur = lengths.get(lengths.len() / 2).copied();
                    frame.deblur_rows(&lengths, d.noise_to_signal)?
                }
                None => frame,
            };
            let frame = match &m.sources {
                Some(sources) => frame.resample_rows(sources)?,
                None => frame,
            };
            let corrected = frame.shift_rows(&m.shifts, interp)?;
            result.row_shifts = Some(m.shifts);
            return Ok((corrected, result));
        }
        let k = match self.options.k_source {
            KSource::Filtered => result.k,
            KSource::Raw => result.k_raw.unwrap_or(result.k),
        };
        result.k_applied = Some(k);
        // Shown turned a quarter (either way), a shear `s` along the stored rows is the vertical
        // shear `c = -s` of the picture shown: the stored frame is de-sheared by `-c`.
        let stored_k = if self.options.rotation.abs() == 90 {
            -k
        } else {
            k
        };
        let interp = self.options.interpolation;
        let corrected = match (self.options.readout, frame) {
            (Readout::Columns, VideoFrame::Image(img)) => {
                // Along the columns: the row correction on the transposed image.
                use crate::warp::{transpose, try_remove_shear, Canvas};
                let t = transpose(&img);
                let shear = crate::Shear::about_middle(stored_k, t.height());
                let (fixed, _) = try_remove_shear(&t, shear, interp, Canvas::Same)?;
                VideoFrame::Image(transpose(&fixed))
            }
            (Readout::Columns, _) => {
                return Err(crate::Error::InvalidArgument(
                    "frames read out by columns are corrected as images, not YUV".into(),
                ))
            }
            (Readout::Rows, frame) => frame.remove_shear(stored_k, interp)?,
        };
        Ok((corrected, result))
    }
}

/// Whether a face whose own velocity is `own` moves with content moving at `background`
/// (pixels per frame): within 3 px and 10%, what the eyes' displacement is measured to.
fn moves_with(own: f64, background: f64) -> bool {
    (own - background).abs() <= 3.0 + 0.1 * background.abs()
}

/// `stored` turned as a player shows it, `rotation` degrees counter-clockwise (see
/// [`ProcessOptions::rotation`]).
fn upright(stored: &GrayImage, rotation: i32) -> std::borrow::Cow<'_, GrayImage> {
    use image::imageops;
    use std::borrow::Cow;
    match rotation {
        90 => Cow::Owned(imageops::rotate270(stored)),
        -90 => Cow::Owned(imageops::rotate90(stored)),
        180 => Cow::Owned(imageops::rotate180(stored)),
        _ => Cow::Borrowed(stored),
    }
}

/// Where frames come from.
pub trait FrameSource: Send {
    /// The next frame, `None` at the end.
    fn next_frame(&mut self) -> Result<Option<VideoFrame>>;
}

/// Where processed frames go.
pub trait FrameSink: Send {
    /// Writes one frame.
    fn write_frame(&mut self, frame: VideoFrame) -> Result<()>;
    /// Flushes whatever is buffered after the last frame.
    fn finish(&mut self) -> Result<()>;
}

/// What a [`run`] did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RunStats {
    /// Frames processed.
    pub frames: u64,
    /// Wall time, seconds.
    pub seconds: f64,
    /// Estimates rejected by the filter.
    pub rejected: u64,
    /// Tracker work counts.
    pub tracker: TrackerStats,
    /// The readout fraction in use at the end (given, or calibrated).
    pub readout_fraction: Option<f64>,
    /// The calibration from every face reading of the run, known or not.
    pub calibration: Option<Calibration>,
    /// How the frames got their `k`.
    pub sources: SourceCounts,
    /// The exposure motion blur was removed with ([`VideoProcessor::exposure`]).
    pub exposure: Option<f64>,
}

/// Frames in flight between the reading, processing and writing threads.
const QUEUE: usize = 3;

/// Reads every frame of `source`, processes it and writes it to `sink` (if any), calling
/// `on_frame` with each frame's result in order (each frame `smoothing_lag` frames after it was
/// read; the held frames are flushed at the end of the source). Reading and writing run on
/// threads of their own, so that parsing and serialising overlap with detection and correction.
///
/// # Errors
/// The first error of the source, the processing or the sink; processing stops there (frames
/// already written stay written; after a source error the frames read before it, held for the
/// smoother, are still processed and written).
pub fn run(
    source: &mut dyn FrameSource,
    sink: Option<&mut dyn FrameSink>,
    processor: &mut VideoProcessor<'_>,
    on_frame: impl FnMut(&FrameResult),
) -> Result<RunStats> {
    run_pass(source, sink, processor, on_frame, false)
}

/// The first of two passes over a clip: analyses every frame of `source` (see
/// [`VideoProcessor::analyse_frame`]), handing each to `on_frame` after it (to count it, or to
/// keep it for the second pass when the clip is short enough to hold), and ends the analysis;
/// returns the frames analysed. [`replay`] is the second pass.
///
/// # Errors
/// The source's first error.
pub fn analyse(
    source: &mut dyn FrameSource,
    processor: &mut VideoProcessor<'_>,
    mut on_frame: impl FnMut(VideoFrame),
) -> Result<usize> {
    let (tx, rx) = mpsc::sync_channel::<Result<VideoFrame>>(QUEUE);
    std::thread::scope(|scope| -> Result<()> {
        scope.spawn(move || read_into(source, tx));
        for item in rx {
            let frame = item?;
            processor.analyse_frame(&frame);
            on_frame(frame);
        }
        Ok(())
    })?;
    Ok(processor.end_analysis())
}

/// The second of two passes: the frames of `source` (the clip [`analyse`] went through,
/// read again) corrected with what the first pass found and written to `sink`, as [`run`].
///
/// # Errors
/// As [`run`]; [`crate::Error::Video`] when `source` ends before every analysed frame came.
pub fn replay(
    source: &mut dyn FrameSource,
    sink: Option<&mut dyn FrameSink>,
    processor: &mut VideoProcessor<'_>,
    on_frame: impl FnMut(&FrameResult),
) -> Result<RunStats> {
    run_pass(source, sink, processor, on_frame, true)
}

/// Sends the frames of `source` down `tx` until the end, an error, or the receiver is gone.
fn read_into(source: &mut dyn FrameSource, tx: mpsc::SyncSender<Result<VideoFrame>>) {
    loop {
        let next = source.next_frame().transpose();
        let Some(item) = next else { break };
        let failed = item.is_err();
        // The receiver is gone only when processing stopped; nothing more to read then.
        if tx.send(item).is_err() || failed {
            break;
        }
    }
}

/// [`run`], or with `second` [`replay`].
fn run_pass(
    source: &mut dyn FrameSource,
    sink: Option<&mut dyn FrameSink>,
    processor: &mut VideoProcessor<'_>,
    mut on_frame: impl FnMut(&FrameResult),
    second: bool,
) -> Result<RunStats> {
    let start = Instant::now();
    let (in_tx, in_rx) = mpsc::sync_channel::<Result<VideoFrame>>(QUEUE);
    let (out_tx, out_rx) = mpsc::sync_channel::<VideoFrame>(QUEUE);
    let mut frames = 0u64;
    std::thread::scope(|scope| -> Result<()> {
        scope.spawn(move || read_into(source, in_tx));
        let writer = scope.spawn(move || -> Result<()> {
            let Some(sink) = sink else {
                for _ in out_rx {}
                return Ok(());
            };
            for frame in out_rx {
                sink.write_frame(frame)?;
            }
            sink.finish()
        });
        let processed = (|| -> Result<()> {
            // The writer stops only on an error, which is reported below.
            let mut deliver = |(frame, result): (VideoFrame, FrameResult)| {
                frames += 1;
                on_frame(&result);
                out_tx.send(frame).is_ok()
            };
            let mut read_error = None;
            for item in in_rx {
                let frame = match item {
                    Ok(frame) => frame,
                    Err(e) => {
                        read_error = Some(e);
                        break;
                    }
                };
                let out = if second {
                    vec![processor.replay(frame)?]
                } else {
                    processor.process(frame)?
                };
                for out in out {
                    if !deliver(out) {
                        return Ok(());
                    }
                }
            }
            if second {
                let left = processor.pending();
                if read_error.is_none() && left > 0 {
                    read_error = Some(crate::Error::Video(format!(
                        "the second pass over the clip ended {left} frames before the first"
                    )));
                }
                return read_error.map_or(Ok(()), Err);
            }
            // The frames held for the smoother go out even when the source failed, so that a
            // truncated stream yields every frame read before the error.
            for out in processor.finish()? {
                if !deliver(out) {
                    break;
                }
            }
            read_error.map_or(Ok(()), Err)
        })();
        drop(out_tx);
        let written = writer
            .join()
            .unwrap_or_else(|_| Err(crate::Error::Video("the writing thread panicked".into())));
        written.and(processed)
    })?;
    Ok(RunStats {
        frames,
        seconds: start.elapsed().as_secs_f64(),
        rejected: processor.rejected(),
        tracker: processor.tracker_stats(),
        readout_fraction: processor.readout_fraction(),
        calibration: processor.calibration(),
        sources: processor.source_counts(),
        exposure: processor.exposure(),
    })
}

#[cfg(test)]
mod tests {
    use super::upright;
    use image::{GrayImage, Luma};

    #[test]
    fn frames_are_turned_as_players_show_them() {
        // 3 x 2, the top-left pixel marked: where a counter-clockwise turn puts it.
        let mut stored = GrayImage::new(3, 2);
        stored.put_pixel(0, 0, Luma([9]));
        let at = |img: &GrayImage| {
            let p = img.enumerate_pixels().find(|(_, _, p)| p[0] == 9);
            (img.dimensions(), p.map(|(x, y, _)| (x, y)))
        };
        assert_eq!(at(&upright(&stored, 0)), ((3, 2), Some((0, 0))));
        // 90 counter-clockwise: the top-left corner goes to the bottom left.
        assert_eq!(at(&upright(&stored, 90)), ((2, 3), Some((0, 2))));
        // -90 (clockwise, a phone's usual portrait flag): to the top right.
        assert_eq!(at(&upright(&stored, -90)), ((2, 3), Some((1, 0))));
        assert_eq!(at(&upright(&stored, 180)), ((3, 2), Some((2, 1))));
        // Other angles are not turned.
        assert_eq!(at(&upright(&stored, 45)), ((3, 2), Some((0, 0))));
    }
}

//! One frame at a time: track the faces, estimate `k` on each, filter it over time, correct the
//! frame; and the threaded loop that reads, processes and writes a whole clip.

use std::collections::VecDeque;
use std::sync::mpsc;
use std::time::Instant;

use image::GrayImage;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::temporal::{FilterParams, ShearSmoother, Update, DEFAULT_SMOOTHING_LAG};
use super::tracker::{FaceTracker, TrackerParams, TrackerStats};
use super::VideoFrame;
use crate::locate::network::Budget;
use crate::pipeline::{combined_shear, FaceStart};
use crate::warp::Interpolation;
use crate::{FaceReport, Readout, Rect, Result, Unshear};

/// Which `k` corrects the frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum KSource {
    /// The temporally filtered value (default).
    #[default]
    Filtered,
    /// This frame's own estimate; the filtered value on frames without one.
    Raw,
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
    /// ([`Unshear::face_by_columns`]), undone on the stored frames along their rows.
    pub rotation: i32,
    /// How the frames, as given, were read out: [`Readout::Rows`] for a clip's stored frames
    /// (with [`Self::rotation`]), [`Readout::Columns`] for frames already turned upright from
    /// a clip recorded turned a quarter (OpenCV turns them so): the faces' readings are then
    /// converted to the vertical shear, and the frames (images only) de-sheared along their
    /// columns.
    pub readout: Readout,
}

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
}

/// Tracker, estimator and smoother for one clip.
///
/// Frames go in with [`Self::process`] and come out, in order, [`ProcessOptions::smoothing_lag`]
/// frames later (the smoother needs the estimates of the frames after each one); at the end of
/// the stream [`Self::finish`] returns the frames still held.
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
    /// Analysed frames waiting for their smoothed `k`, oldest first.
    pending: VecDeque<(VideoFrame, FrameResult)>,
}

impl<'a> VideoProcessor<'a> {
    /// A processor using `unshear`'s detector and filters.
    pub fn new(unshear: &'a Unshear, options: ProcessOptions) -> Self {
        Self {
            unshear,
            tracker: FaceTracker::new(unshear.detector().clone(), options.tracker),
            followed: Vec::new(),
            network_stats: TrackerStats::default(),
            smoother: ShearSmoother::new(options.filter, options.smoothing_lag),
            options,
            next_index: 0,
            pending: VecDeque::with_capacity(options.smoothing_lag.min(64) + 1),
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

    /// Tracks and estimates one frame's luma and runs the causal filter; `k` is still the
    /// causal value. Returns the result and the smoothed `k` of the oldest pending frame, if
    /// it is due.
    fn analyse(&mut self, stored: &GrayImage) -> (FrameResult, Option<f64>) {
        let gray = &*upright(stored, self.options.rotation);
        let mut faces = self.faces_in(gray);
        if self.options.rotation.abs() == 90 || self.options.readout == Readout::Columns {
            for f in &mut faces {
                self.unshear.face_by_columns(f);
            }
        }
        self.finish_analysis(faces)
    }

    /// The faces of one upright frame, followed or detected and estimated.
    fn faces_in(&mut self, gray: &GrayImage) -> Vec<FaceReport> {
        // Start from the causal filtered shear: the face is then searched for, and its
        // features located, in a nearly upright view.
        let view_k = self.smoother.filter().k();
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

    /// With the network detector: the faces of the last frame followed into this one by the
    /// landmark network, each started from its last eyes, roll and the filtered shear
    /// `view_k`; and on the frames where detection is due (see [`TrackerParams`]: every
    /// `redetect_interval` frames, every `lost_interval` while no face is followed) the faces
    /// the detector finds in the frame shrunk to `detect_width` columns that are not followed
    /// yet.
    fn follow_and_detect(&mut self, gray: &GrayImage, view_k: f64) -> Vec<FaceReport> {
        let unshear = self.unshear;
        let budget = self.options.network_budget;
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
                .map(|r| (face_box, Some(r)))
        };
        let before = self.followed.len();
        let mut found: Vec<(Rect, Option<FaceReport>)> = if before > 1 {
            self.followed.par_iter().filter_map(follow).collect()
        } else {
            self.followed.iter().filter_map(follow).collect()
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
        let mut faces: Vec<FaceReport> = found.into_iter().filter_map(|(_, r)| r).collect();
        faces.sort_by(|a, b| {
            let size = |f: &FaceReport| f.right_eye.distance(f.left_eye);
            size(b).total_cmp(&size(a))
        });
        faces.truncate(params.max_faces);
        self.followed = faces.clone();
        faces
    }

    /// Filters the frame's shear from its `faces` and makes its result.
    fn finish_analysis(&mut self, faces: Vec<FaceReport>) -> (FrameResult, Option<f64>) {
        let k_raw = combined_shear(&faces);
        let (update, due) = self.smoother.push(k_raw);
        let index = self.next_index;
        self.next_index += 1;
        let k_causal = self.smoother.filter().k();
        let result = FrameResult {
            index,
            k_raw,
            k: k_causal,
            k_causal,
            k_applied: None,
            update,
            faces,
        };
        (result, due)
    }

    /// Takes one frame in (tracks, estimates, filters) and returns the frame that is now due,
    /// `smoothing_lag` frames older, with its result and corrected by the chosen `k` (unchanged
    /// when correction is off); `None` while the first `smoothing_lag` frames fill the buffer.
    ///
    /// # Errors
    /// Only if the shear to apply is not finite (which the filter never produces).
    pub fn process(&mut self, frame: VideoFrame) -> Result<Option<(VideoFrame, FrameResult)>> {
        let (result, due) = self.analyse(&frame.luma());
        self.pending.push_back((frame, result));
        let Some(k) = due else {
            return Ok(None);
        };
        match self.pending.pop_front() {
            Some(entry) => self.emit(entry, k).map(Some),
            None => Ok(None),
        }
    }

    /// The end of the stream: every frame still held, in order, with `k` smoothed over all the
    /// frames seen and corrected as by [`Self::process`].
    ///
    /// # Errors
    /// As [`Self::process`].
    pub fn finish(&mut self) -> Result<Vec<(VideoFrame, FrameResult)>> {
        let ks = self.smoother.flush();
        let entries: Vec<_> = self.pending.drain(..).collect();
        entries
            .into_iter()
            .zip(ks)
            .map(|(entry, k)| self.emit(entry, k))
            .collect()
    }

    /// Sets the smoothed `k` of a frame and corrects it.
    fn emit(
        &self,
        (frame, mut result): (VideoFrame, FrameResult),
        k_smoothed: f64,
    ) -> Result<(VideoFrame, FrameResult)> {
        result.k = k_smoothed;
        if !self.options.correct {
            return Ok((frame, result));
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
    mut on_frame: impl FnMut(&FrameResult),
) -> Result<RunStats> {
    let start = Instant::now();
    let (in_tx, in_rx) = mpsc::sync_channel::<Result<VideoFrame>>(QUEUE);
    let (out_tx, out_rx) = mpsc::sync_channel::<VideoFrame>(QUEUE);
    let mut frames = 0u64;
    std::thread::scope(|scope| -> Result<()> {
        scope.spawn(move || loop {
            let next = source.next_frame().transpose();
            let Some(item) = next else { break };
            let failed = item.is_err();
            // The receiver is gone only when processing stopped; nothing more to read then.
            if in_tx.send(item).is_err() || failed {
                break;
            }
        });
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
                if let Some(out) = processor.process(frame)? {
                    if !deliver(out) {
                        return Ok(());
                    }
                }
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

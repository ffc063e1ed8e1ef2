//! One frame at a time: track the faces, estimate `k` on each, filter it over time, correct the
//! frame; and the threaded loop that reads, processes and writes a whole clip.

use std::sync::mpsc;
use std::time::Instant;

use image::GrayImage;
use rayon::prelude::*;

use super::temporal::{FilterParams, ShearFilter, Update};
use super::tracker::{FaceTracker, TrackerParams, TrackerStats};
use super::VideoFrame;
use crate::pipeline::combined_shear;
use crate::warp::Interpolation;
use crate::{FaceReport, Result, Unshear};

/// Which `k` corrects the frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum KSource {
    /// The temporally filtered value (default).
    #[default]
    Filtered,
    /// This frame's own estimate; the filtered value on frames without one.
    Raw,
}

/// Settings of a video run (default: correct with the filtered `k`, linear interpolation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProcessOptions {
    /// Face tracking.
    pub tracker: TrackerParams,
    /// Temporal filter of `k`.
    pub filter: FilterParams,
    /// Correct the frames (false: analysis only, frames pass through unchanged).
    pub correct: bool,
    /// Which `k` corrects.
    pub k_source: KSource,
    /// Row resampling.
    pub interpolation: Interpolation,
}

impl Default for ProcessOptions {
    fn default() -> Self {
        Self {
            tracker: TrackerParams::default(),
            filter: FilterParams::default(),
            correct: true,
            k_source: KSource::Filtered,
            interpolation: Interpolation::Linear,
        }
    }
}

/// What was found in one frame.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameResult {
    /// Frame number, from 0.
    pub index: u64,
    /// This frame's own estimate: the median of its faces' `k`, `None` without a usable face.
    pub k_raw: Option<f64>,
    /// The filtered `k` after this frame.
    pub k: f64,
    /// The shear the frame was corrected by (`None` when correction is off).
    pub k_applied: Option<f64>,
    /// What the filter did with `k_raw`.
    pub update: Update,
    /// Every tracked face with an estimate, as [`Unshear::estimate_face`] reports it.
    pub faces: Vec<FaceReport>,
}

/// Tracker, estimator and filter for one clip.
#[derive(Debug)]
pub struct VideoProcessor<'a> {
    unshear: &'a Unshear,
    tracker: FaceTracker,
    filter: ShearFilter,
    options: ProcessOptions,
    next_index: u64,
}

impl<'a> VideoProcessor<'a> {
    /// A processor using `unshear`'s detector and filters.
    pub fn new(unshear: &'a Unshear, options: ProcessOptions) -> Self {
        Self {
            unshear,
            tracker: FaceTracker::new(unshear.detector().clone(), options.tracker),
            filter: ShearFilter::new(options.filter),
            options,
            next_index: 0,
        }
    }

    /// The tracker's work counts.
    pub fn tracker_stats(&self) -> TrackerStats {
        self.tracker.stats()
    }

    /// Estimates rejected by the filter so far.
    pub fn rejected(&self) -> u64 {
        self.filter.rejected()
    }

    /// Tracks, estimates and filters one frame's luma (no correction).
    pub fn analyse(&mut self, gray: &GrayImage) -> FrameResult {
        let boxes = self.tracker.track(gray, self.filter.k());
        let unshear = self.unshear;
        // Start from the filtered shear: the features are then searched in a nearly upright view.
        let view_k = self.filter.k();
        let faces: Vec<FaceReport> = if boxes.len() > 1 {
            boxes
                .par_iter()
                .filter_map(|&b| unshear.estimate_face_in_view(gray, b, view_k))
                .collect()
        } else {
            boxes
                .iter()
                .filter_map(|&b| unshear.estimate_face_in_view(gray, b, view_k))
                .collect()
        };
        let k_raw = combined_shear(&faces);
        let update = self.filter.update(k_raw);
        let index = self.next_index;
        self.next_index += 1;
        FrameResult {
            index,
            k_raw,
            k: self.filter.k(),
            k_applied: None,
            update,
            faces,
        }
    }

    /// [`Self::analyse`], then the frame corrected by the chosen `k` (unchanged when correction
    /// is off).
    ///
    /// # Errors
    /// Only if the shear to apply is not finite (which the filter never produces).
    pub fn process(&mut self, frame: VideoFrame) -> Result<(VideoFrame, FrameResult)> {
        let mut result = self.analyse(&frame.luma());
        if !self.options.correct {
            return Ok((frame, result));
        }
        let k = match self.options.k_source {
            KSource::Filtered => result.k,
            KSource::Raw => result.k_raw.unwrap_or(result.k),
        };
        result.k_applied = Some(k);
        Ok((frame.remove_shear(k, self.options.interpolation)?, result))
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
/// `on_frame` with each frame's result in order. Reading and writing run on threads of their
/// own, so that parsing and serialising overlap with detection and correction.
///
/// # Errors
/// The first error of the source, the processing or the sink; processing stops there (frames
/// already written stay written).
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
            for item in in_rx {
                let (frame, result) = processor.process(item?)?;
                frames += 1;
                on_frame(&result);
                if out_tx.send(frame).is_err() {
                    // The writer stopped on an error; it is reported below.
                    break;
                }
            }
            Ok(())
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

//! `unshear eval video`: clips of development faces made by the rolling-shutter simulator
//! ([`crate::dev::simulate`]: a camera panning over a panorama of photos, rows read over `rho`
//! of the frame interval, motion blur, sensor noise) run through the video pipeline, scored
//! against the simulator's truth.
//!
//! Each clip runs three ways: as `unshear video` does by default (the readout calibrated on the
//! clip from its faces, then `k` from motion), with the true readout fraction given
//! (`--readout-fraction`), and with the faces alone (`--no-motion`). Per frame: the error of the
//! middle row's `k`; per row: the offset left after the correction (the truth's row offsets
//! minus those applied), and what a single shear per frame would leave at best (the truth's `k`
//! as a straight line); per clip: the readout fraction found.

use std::fmt::Write as _;
use std::time::Instant;

use serde::Serialize;

use crate::dev::simulate::{FrameTruth, Profile, Scene, SimulationParams, Simulator};
use crate::video::color::image_to_yuv;
use crate::video::FilterParams;
use crate::video::TrackerParams;
use crate::video::{Chroma, FrameResult, ProcessOptions, ShearSource, VideoFrame, VideoProcessor};
use crate::{Result, Unshear};

/// The motions a clip can have (the simulator's profiles, at the clip's peak speed).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum MotionKind {
    /// A steady pan.
    Constant,
    /// A camera following someone: pan, ease to a stop, pause, pan back.
    Pause,
    /// A pan whose speed changes within a frame's readout.
    Accelerate,
    /// Hand-held shake.
    Shaky,
    /// A still camera and a subject walking across.
    Walk,
}

impl MotionKind {
    /// Every kind, in table order.
    pub const ALL: [MotionKind; 5] = [
        MotionKind::Constant,
        MotionKind::Pause,
        MotionKind::Accelerate,
        MotionKind::Shaky,
        MotionKind::Walk,
    ];

    /// The name used on the command line and in tables.
    pub fn name(self) -> &'static str {
        match self {
            MotionKind::Constant => "constant",
            MotionKind::Pause => "pause",
            MotionKind::Accelerate => "accelerate",
            MotionKind::Shaky => "shaky",
            MotionKind::Walk => "walk",
        }
    }

    /// The simulator's profile at peak speed `v` px/frame.
    pub fn profile(self, v: f64, seed: u64) -> Profile {
        match self {
            MotionKind::Constant => Profile::Constant { v },
            MotionKind::Pause => Profile::Pause { v },
            MotionKind::Accelerate => Profile::Accelerate { v },
            MotionKind::Shaky => Profile::Shaky { v, seed },
            MotionKind::Walk => Profile::Walk { v },
        }
    }
}

/// What to simulate and how to score it.
#[derive(Debug, Clone, PartialEq)]
pub struct VideoEvalOptions {
    /// Frame width, pixels.
    pub width: u32,
    /// Frame height, pixels.
    pub height: u32,
    /// Frames per clip.
    pub frames: u32,
    /// Frames per second.
    pub fps: f64,
    /// The readout fractions to simulate.
    pub readout_fractions: Vec<f64>,
    /// The motions to simulate.
    pub motions: Vec<MotionKind>,
    /// The peak shear at the middle row: each clip's peak speed is `peak_k * H / rho`.
    pub peak_k: f64,
    /// Exposure over the frame interval (0.12: 1/250 s at 30 frames/s).
    pub exposure: f64,
    /// Sensor noise, grey levels.
    pub noise: f64,
    /// Clips per (motion, readout) setting, each over other faces.
    pub clips: usize,
    /// Frames at the start of each clip not scored (the calibration's and the filter's start).
    pub skip: usize,
    /// Frames `unshear video` holds while calibrating (as its `--calibration-window`).
    pub calibration_window: usize,
    /// Seed of the noise and the shake.
    pub seed: u64,
    /// How each clip is run, in table order.
    pub modes: Vec<Mode>,
}

impl Default for VideoEvalOptions {
    fn default() -> Self {
        Self {
            width: 1280,
            height: 720,
            frames: 90,
            fps: 30.0,
            readout_fractions: vec![0.5, 0.8, 1.0],
            motions: vec![
                MotionKind::Constant,
                MotionKind::Pause,
                MotionKind::Accelerate,
                MotionKind::Shaky,
            ],
            peak_k: 0.3,
            exposure: 0.12,
            noise: 2.0,
            clips: 2,
            skip: 30,
            calibration_window: crate::video::DEFAULT_CALIBRATION_WINDOW,
            seed: 1,
            modes: Mode::ALL.to_vec(),
        }
    }
}

/// How a clip was run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// `unshear video`'s default on a file: the readout calibrated over the whole clip in a
    /// first pass, then every frame's `k` from motion.
    Calibrated,
    /// As `unshear video` runs on a pipe (or with `--one-pass`): the readout calibrated while
    /// correcting, the faces deciding until it is known.
    #[serde(rename = "one-pass")]
    OnePass,
    /// The true readout fraction given.
    Given,
    /// The faces alone (`--no-motion`).
    Faces,
}

impl Mode {
    /// Every mode, in table order.
    pub const ALL: [Mode; 4] = [Mode::Calibrated, Mode::OnePass, Mode::Given, Mode::Faces];

    /// The mode's name on the command line (`eval video --modes`).
    pub fn key(self) -> &'static str {
        match self {
            Mode::Calibrated => "calibrated",
            Mode::OnePass => "one-pass",
            Mode::Given => "given",
            Mode::Faces => "faces",
        }
    }

    fn name(self) -> &'static str {
        match self {
            Mode::Calibrated => "motion, readout calibrated (default)",
            Mode::OnePass => "motion, readout calibrated in one pass (a pipe)",
            Mode::Given => "motion, readout given",
            Mode::Faces => "faces alone (`--no-motion`)",
        }
    }
}

/// One mode's run of one clip.
#[derive(Debug, Clone, Serialize)]
pub struct ModeRun {
    /// How it ran.
    pub mode: Mode,
    /// Per scored frame: `k` minus the truth's `k`.
    pub k_errors: Vec<f64>,
    /// Per scored frame: where its `k` came from.
    pub sources: Vec<ShearSource>,
    /// Per scored frame: whether a face was in view (the truth's).
    pub face_in_view: Vec<bool>,
    /// Row offsets left after the correction, pixels (absolute; every 4th row of every scored
    /// frame).
    pub residuals: Vec<f64>,
    /// The readout fraction in use at the end of the clip, and the whole clip's calibration.
    pub readout_fraction: Option<f64>,
    /// The whole clip's calibration uncertainty, when there was a calibration.
    pub readout_uncertainty: Option<f64>,
    /// Seconds spent in the pipeline (not in rendering).
    pub seconds: f64,
}

/// One clip's runs.
#[derive(Debug, Clone, Serialize)]
pub struct ClipResult {
    /// Its motion.
    pub motion: MotionKind,
    /// The true readout fraction.
    pub readout_fraction: f64,
    /// Which clip of its setting.
    pub clip: usize,
    /// Frames in the clip.
    pub frames: usize,
    /// What a single shear per frame leaves at best (the truth's `k` as a line), pixels, like
    /// [`ModeRun::residuals`].
    pub line_residuals: Vec<f64>,
    /// The runs, in [`VideoEvalOptions::modes`] order.
    pub runs: Vec<ModeRun>,
}

/// Every clip's results.
#[derive(Debug, Clone, Serialize)]
pub struct VideoEvalResult {
    /// Per clip.
    pub clips: Vec<ClipResult>,
}

/// Runs every clip: `scene(i)` gives the scene of the `i`-th clip of a setting (other faces for
/// each), `on_clip` is called after each clip.
///
/// # Errors
/// A scene that cannot be made, or the simulator's or the pipeline's errors.
pub fn evaluate_video(
    unshear: &Unshear,
    options: &VideoEvalOptions,
    scene: impl Fn(usize) -> Result<Scene>,
    mut on_clip: impl FnMut(&ClipResult),
) -> Result<VideoEvalResult> {
    let mut clips = Vec::new();
    for &motion in &options.motions {
        for &rho in &options.readout_fractions {
            for clip in 0..options.clips {
                let params = SimulationParams {
                    width: options.width,
                    height: options.height,
                    frames: options.frames,
                    fps: options.fps,
                    readout_fraction: rho,
                    exposure: options.exposure,
                    motion: MotionKind::profile(
                        motion,
                        options.peak_k * f64::from(options.height) / rho,
                        options.seed + clip as u64,
                    ),
                    vertical: None,
                    noise: options.noise,
                    seed: options.seed.wrapping_mul(31) + clip as u64,
                };
                let sim = Simulator::new(scene(clip)?, params)?;
                let result = run_clip(unshear, options, &sim, motion, rho, clip)?;
                on_clip(&result);
                clips.push(result);
            }
        }
    }
    Ok(VideoEvalResult { clips })
}

/// Rows scored per frame: every 4th.
const ROW_STEP: usize = 4;

fn run_clip(
    unshear: &Unshear,
    options: &VideoEvalOptions,
    sim: &Simulator,
    motion: MotionKind,
    rho: f64,
    clip: usize,
) -> Result<ClipResult> {
    let mut frames = Vec::with_capacity(options.frames as usize);
    let mut truths = Vec::with_capacity(options.frames as usize);
    for n in 0..options.frames {
        let (img, truth) = sim.render(n)?;
        let yuv = image_to_yuv(&image::DynamicImage::ImageRgb8(img), Chroma::Yuv420, false);
        frames.push(VideoFrame::Yuv(yuv));
        truths.push(truth);
    }
    let h = options.height;
    let c = f64::from(h) / 2.0;
    let mut line_residuals = Vec::new();
    for t in truths.iter().skip(options.skip) {
        for y in (0..h as usize).step_by(ROW_STEP) {
            line_residuals.push((t.row_offsets[y] - t.k * (y as f64 - c)).abs());
        }
    }
    let mut runs = Vec::new();
    for &mode in &options.modes {
        let process = ProcessOptions {
            tracker: TrackerParams::for_detector(unshear.uses_network_detector()),
            filter: FilterParams::default().with_times(0.5, 1.0, options.fps),
            network_budget: unshear.config().network_budget,
            readout_fraction: (mode == Mode::Given).then_some(rho),
            motion: mode != Mode::Faces,
            calibration_window: options.calibration_window,
            ..ProcessOptions::default()
        };
        let mut processor = VideoProcessor::new(unshear, process);
        let start = Instant::now();
        let mut results: Vec<FrameResult> = Vec::with_capacity(frames.len());
        if mode == Mode::Calibrated {
            // As `unshear video` runs on a file: the readout calibrated over the whole clip
            // first, then every frame corrected with it.
            for f in &frames {
                processor.analyse_frame(f);
            }
            processor.end_analysis();
            for f in &frames {
                results.push(processor.replay(f.clone())?.1);
            }
        } else {
            for f in &frames {
                results.extend(processor.process(f.clone())?.into_iter().map(|(_, r)| r));
            }
            results.extend(processor.finish()?.into_iter().map(|(_, r)| r));
        }
        let seconds = start.elapsed().as_secs_f64();
        runs.push(score(
            mode,
            &results,
            &truths,
            options.skip,
            h,
            seconds,
            &processor,
        ));
    }
    Ok(ClipResult {
        motion,
        readout_fraction: rho,
        clip,
        frames: frames.len(),
        line_residuals,
        runs,
    })
}

fn score(
    mode: Mode,
    results: &[FrameResult],
    truths: &[FrameTruth],
    skip: usize,
    height: u32,
    seconds: f64,
    processor: &VideoProcessor<'_>,
) -> ModeRun {
    let c = f64::from(height) / 2.0;
    let mut run = ModeRun {
        mode,
        k_errors: Vec::new(),
        sources: Vec::new(),
        face_in_view: Vec::new(),
        residuals: Vec::new(),
        readout_fraction: processor.readout_fraction(),
        readout_uncertainty: processor.calibration().map(|c| c.uncertainty),
        seconds,
    };
    for (r, t) in results.iter().zip(truths).skip(skip) {
        run.k_errors.push(r.k - t.k);
        run.sources.push(r.k_source);
        run.face_in_view.push(!t.faces.is_empty());
        let applied = |y: usize| match &r.row_shifts {
            Some(s) => s[y],
            None => r.k_applied.unwrap_or(r.k) * (y as f64 - c),
        };
        for y in (0..height as usize).step_by(ROW_STEP) {
            run.residuals.push((t.row_offsets[y] - applied(y)).abs());
        }
    }
    run
}

/// The `q`-quantile (0 to 1) of `values`, `None` when empty.
fn quantile(values: &[f64], q: f64) -> Option<f64> {
    let mut v: Vec<f64> = values.iter().copied().filter(|v| v.is_finite()).collect();
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let i = ((v.len() - 1) as f64 * q.clamp(0.0, 1.0)).round() as usize;
    Some(v[i])
}

/// Percentage of `errors` within `tol` (absolute), `None` when empty.
fn within(errors: &[f64], tol: f64) -> Option<f64> {
    (!errors.is_empty()).then(|| {
        100.0 * errors.iter().filter(|e| e.abs() <= tol).count() as f64 / errors.len() as f64
    })
}

fn pct(v: Option<f64>) -> String {
    v.map_or_else(|| "-".into(), |v| format!("{v:.1}%"))
}

fn px(v: Option<f64>) -> String {
    v.map_or_else(|| "-".into(), |v| format!("{v:.2}"))
}

impl VideoEvalResult {
    /// The summary tables (Markdown): per motion and readout fraction, each mode's `k`
    /// accuracy, the residual row offsets, the readout fractions found and the speed.
    pub fn markdown(&self) -> String {
        let mut out = String::new();
        let mut settings: Vec<(MotionKind, f64)> = Vec::new();
        for c in &self.clips {
            if !settings
                .iter()
                .any(|s| s.0 == c.motion && s.1 == c.readout_fraction)
            {
                settings.push((c.motion, c.readout_fraction));
            }
        }
        let _ = writeln!(
            out,
            "| motion | rho | clips | frames scored | mode | k within 0.01 | within 0.03 | median abs error | no face in view: within 0.01 | residual row offset median / p95 (px) | single shear at best: median / p95 (px) | rho found (worst error, in stated sigmas) | frames/s |"
        );
        let _ = writeln!(
            out,
            "|---|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|---|---:|"
        );
        for &(motion, rho) in &settings {
            let clips: Vec<&ClipResult> = self
                .clips
                .iter()
                .filter(|c| c.motion == motion && c.readout_fraction == rho)
                .collect();
            let line: Vec<f64> = clips
                .iter()
                .flat_map(|c| c.line_residuals.clone())
                .collect();
            let mut modes: Vec<Mode> = Vec::new();
            for r in clips.iter().flat_map(|c| &c.runs) {
                if !modes.contains(&r.mode) {
                    modes.push(r.mode);
                }
            }
            for mode in modes {
                let runs: Vec<&ModeRun> = clips
                    .iter()
                    .flat_map(|c| c.runs.iter().filter(|r| r.mode == mode))
                    .collect();
                let errors: Vec<f64> = runs.iter().flat_map(|r| r.k_errors.clone()).collect();
                let faceless: Vec<f64> = runs
                    .iter()
                    .flat_map(|r| {
                        r.k_errors
                            .iter()
                            .zip(&r.face_in_view)
                            .filter(|(_, f)| !**f)
                            .map(|(e, _)| *e)
                    })
                    .collect();
                let residuals: Vec<f64> = runs.iter().flat_map(|r| r.residuals.clone()).collect();
                let abs: Vec<f64> = errors.iter().map(|e| e.abs()).collect();
                let rho_found = match mode {
                    Mode::Calibrated | Mode::OnePass => {
                        let found: Vec<(f64, Option<f64>)> = runs
                            .iter()
                            .filter_map(|r| r.readout_fraction.map(|f| (f, r.readout_uncertainty)))
                            .collect();
                        let worst = found
                            .iter()
                            .map(|(f, _)| (f - rho).abs() / rho)
                            .fold(0.0, f64::max);
                        // The error in units of the stated uncertainty: about 1 when it is fair.
                        let sigmas = found
                            .iter()
                            .filter_map(|(f, u)| u.map(|u| (f - rho).abs() / u.max(1e-12)))
                            .fold(0.0, f64::max);
                        if found.is_empty() {
                            "not found".to_string()
                        } else {
                            format!(
                                "{} of {} ({:.1}%, {sigmas:.1} sigma)",
                                found.len(),
                                runs.len(),
                                100.0 * worst
                            )
                        }
                    }
                    Mode::Given => "given".into(),
                    Mode::Faces => "-".into(),
                };
                let frames: usize = clips.iter().map(|c| c.frames).sum();
                let seconds: f64 = runs.iter().map(|r| r.seconds).sum();
                let faceless_cell = if faceless.is_empty() {
                    "no such frame".to_string()
                } else {
                    format!(
                        "{} ({} frames)",
                        pct(within(&faceless, 0.01)),
                        faceless.len()
                    )
                };
                let _ = writeln!(
                    out,
                    "| {} | {rho} | {} | {} | {} | {} | {} | {:.4} | {faceless_cell} | {} / {} | {} / {} | {rho_found} | {:.0} |",
                    motion.name(),
                    clips.len(),
                    errors.len(),
                    mode.name(),
                    pct(within(&errors, 0.01)),
                    pct(within(&errors, 0.03)),
                    quantile(&abs, 0.5).unwrap_or(f64::NAN),
                    px(quantile(&residuals, 0.5)),
                    px(quantile(&residuals, 0.95)),
                    px(quantile(&line, 0.5)),
                    px(quantile(&line, 0.95)),
                    frames as f64 / seconds.max(1e-9),
                );
            }
        }
        out
    }

    /// Per clip and mode, one JSON object a line: the setting, `k` within 0.01, the residual
    /// median and 95th percentile, the readout found.
    pub fn json_lines(&self) -> String {
        let mut out = String::new();
        for c in &self.clips {
            for r in &c.runs {
                let abs: Vec<f64> = r.k_errors.iter().map(|e| e.abs()).collect();
                let line = serde_json::json!({
                    "motion": c.motion,
                    "readout_fraction": c.readout_fraction,
                    "clip": c.clip,
                    "mode": r.mode,
                    "frames_scored": r.k_errors.len(),
                    "k_within_0_01": within(&r.k_errors, 0.01),
                    "k_median_abs_error": quantile(&abs, 0.5),
                    "k_max_abs_error": quantile(&abs, 1.0),
                    "motion_frames": r.sources.iter().filter(|s| **s == ShearSource::Motion).count(),
                    "residual_median": quantile(&r.residuals, 0.5),
                    "residual_p95": quantile(&r.residuals, 0.95),
                    "line_residual_p95": quantile(&c.line_residuals, 0.95),
                    "readout_found": r.readout_fraction,
                    "readout_uncertainty": r.readout_uncertainty,
                    "seconds": r.seconds,
                });
                let _ = writeln!(out, "{line}");
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_and_shares_of_known_values() {
        let v = [0.005, -0.02, 0.0, 0.5, -0.009];
        assert_eq!(within(&v, 0.01), Some(60.0));
        assert_eq!(quantile(&[3.0, 1.0, 2.0], 0.5), Some(2.0));
        assert_eq!(quantile(&[3.0, 1.0, 2.0], 1.0), Some(3.0));
        assert_eq!(quantile(&[], 0.5), None);
        assert_eq!(within(&[], 0.01), None);
    }

    #[test]
    fn every_motion_has_a_profile_at_its_speed() {
        for m in MotionKind::ALL {
            assert_eq!(m.profile(120.0, 1).peak(), 120.0, "{}", m.name());
        }
    }
}

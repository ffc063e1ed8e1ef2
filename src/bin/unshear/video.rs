//! `unshear video`: y4m files and pipes, frame folders; per-frame JSON; progress on stderr.
//!
//! `IN` is a `.y4m` file, `-` (a y4m stream on stdin) or a folder of numbered frames. `OUT` is
//! `-` (y4m on stdout), a path ending in `.y4m`, or otherwise a folder that receives
//! `000000.png`, `000001.png`, ... (`--frame-format`). Without `-o` nothing is written (analysis).

use std::fs::File;
use std::io::{BufReader, BufWriter, IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use clap::{Args, ValueEnum};
use serde::Serialize;

use crate::args::{InterpArg, ModelArgs};
use crate::models::load_models;
use crate::report::{face, r4, JsonFace};
use crate::usage_error;
use unshear::imageio::WriteOptions;
use unshear::video::frames::{list_frames, FrameFolderReader, FrameFolderWriter};
use unshear::video::temporal::{FilterParams, DEFAULT_SMOOTHING_LAG};
use unshear::video::tracker::TrackerParams;
use unshear::video::y4m::{Y4mReader, Y4mWriter};
use unshear::video::{
    run, Chroma, FrameResult, FrameSink, FrameSource, KSource, ProcessOptions, RunStats,
    VideoFormat, VideoProcessor,
};

/// `unshear video`.
#[derive(Debug, Args)]
pub struct VideoArgs {
    /// Input: a .y4m file, `-` for a y4m stream on stdin, or a folder of numbered frames.
    #[arg(value_name = "IN")]
    pub input: PathBuf,
    /// Output: `-` for y4m on stdout, a .y4m file, or a folder for numbered frames
    /// [default: none, analysis only].
    #[arg(short = 'o', long = "output", value_name = "OUT")]
    pub output: Option<PathBuf>,
    /// Write one JSON line per frame: `--json` to stdout, `--json=FILE` to a file.
    #[arg(
        long,
        value_name = "FILE",
        num_args = 0..=1,
        require_equals = true,
        default_missing_value = "-"
    )]
    pub json: Option<PathBuf>,
    /// Do not correct: frames are written unchanged (analysis only).
    #[arg(long)]
    pub no_correct: bool,
    /// Correct each frame by the filtered k or by its own raw estimate (the filtered k on
    /// frames without one).
    #[arg(long, value_enum, default_value_t = KSourceArg::Filtered)]
    pub k_source: KSourceArg,
    /// Row resampling.
    #[arg(long, value_enum, default_value_t = InterpArg::Linear)]
    pub interp: InterpArg,
    /// Full face detection every N frames (faces are tracked in between).
    #[arg(long, value_name = "N", default_value_t = 30)]
    pub redetect: u64,
    /// While no face is tracked, full detection every N frames.
    #[arg(long, value_name = "N", default_value_t = 5)]
    pub lost_interval: u64,
    /// Full detection on the frame shrunk to at most this width (0: full size; smallest face
    /// found: 20 * width / PX pixels).
    #[arg(long, value_name = "PX", default_value_t = 640)]
    pub detect_width: u32,
    /// Smooth k over this many later frames (a fixed-lag smoother): each frame is corrected
    /// once N more frames have been estimated, so output lags input by N frames (0: the causal
    /// filter, no delay).
    #[arg(long, value_name = "N", default_value_t = DEFAULT_SMOOTHING_LAG)]
    pub smoothing_lag: usize,
    /// Without a face, hold the filtered k for this many seconds...
    #[arg(long, value_name = "SECONDS", default_value_t = 0.5)]
    pub hold: f64,
    /// ...then let it decay to 0 with this time constant.
    #[arg(long, value_name = "SECONDS", default_value_t = 1.0)]
    pub decay: f64,
    /// Frame rate of a frame folder (y4m streams carry their own).
    #[arg(long, value_name = "FPS", default_value_t = 25.0)]
    pub fps: f64,
    /// Chroma layout of y4m output made from a frame folder.
    #[arg(long, value_enum, default_value_t = ChromaArg::C420)]
    pub chroma: ChromaArg,
    /// Image format of frames written to a folder (its extension).
    #[arg(long, value_name = "EXT", default_value = "png")]
    pub frame_format: String,
    /// Replace existing output files (inputs are never overwritten).
    #[arg(long)]
    pub force: bool,
    #[command(flatten)]
    pub model: ModelArgs,
}

/// Largest `--smoothing-lag`: the processor holds that many decoded frames in memory.
const MAX_SMOOTHING_LAG: usize = 250;

/// `--k-source`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum KSourceArg {
    /// The temporally filtered k.
    Filtered,
    /// Each frame's own estimate.
    Raw,
}

/// `--chroma`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ChromaArg {
    /// 4:2:0 (`C420jpeg`).
    #[value(name = "420")]
    C420,
    /// 4:2:2.
    #[value(name = "422")]
    C422,
    /// 4:4:4.
    #[value(name = "444")]
    C444,
    /// Grey only.
    Mono,
}

/// One frame, as printed by `--json`.
#[derive(Debug, Serialize)]
struct JsonFrame {
    frame: u64,
    k_raw: Option<f64>,
    k: f64,
    faces: Vec<JsonFace>,
}

fn json_line(r: &FrameResult) -> String {
    let line = JsonFrame {
        frame: r.index,
        k_raw: r.k_raw.map(r4),
        k: r4(r.k),
        faces: r.faces.iter().map(face).collect(),
    };
    // Plain structs with finite or null numbers: serialisation cannot fail.
    serde_json::to_string(&line).unwrap_or_default()
}

fn is_stdio(p: &Path) -> bool {
    p.as_os_str() == "-"
}

fn is_y4m_path(p: &Path) -> bool {
    p.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("y4m"))
}

/// Where frames come from, and what an output stream's header should be.
enum Input {
    Y4m(Box<dyn FrameSource>, Vec<u8>, VideoFormat),
    Frames(FrameFolderReader),
}

fn open_input(a: &VideoArgs) -> Result<Input> {
    let max = a.model.max_pixels;
    if is_stdio(&a.input) {
        let reader = Y4mReader::new(BufReader::with_capacity(1 << 20, std::io::stdin()), max)
            .context("reading y4m from stdin")?;
        let (header, format) = (reader.header().to_vec(), reader.format().clone());
        return Ok(Input::Y4m(Box::new(reader), header, format));
    }
    if a.input.is_dir() {
        let paths = list_frames(&a.input)?;
        let reader = FrameFolderReader::new(paths, max)
            .with_context(|| format!("reading the first frame in {}", a.input.display()))?;
        return Ok(Input::Frames(reader));
    }
    let file = File::open(&a.input).with_context(|| format!("opening {}", a.input.display()))?;
    let reader = Y4mReader::new(BufReader::with_capacity(1 << 20, file), max)
        .with_context(|| format!("reading {}", a.input.display()))?;
    let (header, format) = (reader.header().to_vec(), reader.format().clone());
    Ok(Input::Y4m(Box::new(reader), header, format))
}

/// A y4m writer for the input: its own header for a y4m input, a made one for frames.
fn y4m_sink<W: Write + Send>(
    w: W,
    header: Option<&[u8]>,
    made: &VideoFormat,
) -> unshear::Result<Y4mWriter<W>> {
    match header {
        Some(h) => Y4mWriter::with_header(w, h),
        None => Y4mWriter::new(w, made),
    }
}

/// `unshear video`.
pub fn video(a: VideoArgs) -> Result<()> {
    let json_to_stdout = a.json.as_deref().is_some_and(is_stdio);
    let y4m_to_stdout = a.output.as_deref().is_some_and(is_stdio);
    if json_to_stdout && y4m_to_stdout {
        usage_error("--json and -o - would both write to stdout; use --json=FILE");
    }
    if !(a.hold.is_finite() && a.hold >= 0.0 && a.decay.is_finite() && a.decay > 0.0) {
        usage_error("--hold must be >= 0 and --decay > 0 seconds");
    }
    if !(a.fps.is_finite() && a.fps > 0.0) {
        usage_error("--fps must be a positive number");
    }
    if a.redetect == 0 || a.lost_interval == 0 {
        usage_error("--redetect and --lost-interval must be at least 1");
    }
    if a.smoothing_lag > MAX_SMOOTHING_LAG {
        usage_error(&format!(
            "--smoothing-lag must be at most {MAX_SMOOTHING_LAG} frames (frames are held in memory)"
        ));
    }
    let unshear = load_models(&a.model, unshear::Config::video())?;
    let input = open_input(&a)?;
    let fps = match &input {
        Input::Y4m(_, _, f) => f.fps(),
        Input::Frames(_) => a.fps,
    };
    let options = ProcessOptions {
        tracker: TrackerParams {
            redetect_interval: a.redetect,
            lost_interval: a.lost_interval,
            detect_width: a.detect_width,
            ..Default::default()
        },
        filter: FilterParams::default().with_times(a.hold, a.decay, fps),
        smoothing_lag: a.smoothing_lag,
        correct: !a.no_correct,
        k_source: match a.k_source {
            KSourceArg::Filtered => KSource::Filtered,
            KSourceArg::Raw => KSource::Raw,
        },
        interpolation: a.interp.into(),
        network_budget: unshear.config().network_budget,
    };
    let mut processor = VideoProcessor::new(&unshear, options);
    let (mut source, header, protected, made): (Box<dyn FrameSource>, _, _, _) = match input {
        Input::Y4m(s, h, f) => {
            let protected = (!is_stdio(&a.input))
                .then(|| a.input.clone())
                .into_iter()
                .collect::<Vec<_>>();
            (s, Some(h), protected, f)
        }
        Input::Frames(r) => {
            let (width, height) = r.dimensions();
            let made = VideoFormat {
                width,
                height,
                chroma: match a.chroma {
                    ChromaArg::C420 => Chroma::Yuv420,
                    ChromaArg::C422 => Chroma::Yuv422,
                    ChromaArg::C444 => Chroma::Yuv444,
                    ChromaArg::Mono => Chroma::Mono,
                },
                full_range: false,
                frame_rate: frame_rate_fraction(a.fps),
            };
            let protected = r.paths().to_vec();
            (Box::new(r) as Box<dyn FrameSource>, None, protected, made)
        }
    };
    let write_options = WriteOptions {
        overwrite: a.force,
        protected: protected.clone(),
        ..Default::default()
    };

    // Per-frame JSON and progress, on the processing thread.
    let mut json_out: Option<Box<dyn Write>> = match a.json.as_deref() {
        None => None,
        Some(p) if is_stdio(p) => Some(Box::new(BufWriter::new(std::io::stdout()))),
        Some(p) => {
            if protected.iter().any(|i| same_path(i, p)) {
                anyhow::bail!("{}: refusing to write the JSON over an input", p.display());
            }
            if p.exists() && !a.force {
                anyhow::bail!("{}: exists; use --force to replace it", p.display());
            }
            Some(Box::new(BufWriter::new(
                File::create(p).with_context(|| format!("creating {}", p.display()))?,
            )))
        }
    };
    let mut json_error: Option<std::io::Error> = None;
    let mut progress = Progress::new();
    let mut on_frame = |r: &FrameResult| {
        if let Some(out) = json_out.as_mut() {
            if json_error.is_none() {
                if let Err(e) = writeln!(out, "{}", json_line(r)) {
                    json_error = Some(e);
                }
            }
        }
        progress.frame();
    };

    let stats: RunStats = match a.output.as_deref() {
        None => run(source.as_mut(), None, &mut processor, &mut on_frame)?,
        Some(o) if is_stdio(o) => {
            let w = BufWriter::with_capacity(1 << 20, std::io::stdout());
            let mut sink = y4m_sink(w, header.as_deref(), &made)?;
            run(
                source.as_mut(),
                Some(&mut sink),
                &mut processor,
                &mut on_frame,
            )?
        }
        Some(o) if is_y4m_path(o) => {
            let mut stats = None;
            unshear::imageio::write_atomic(o, &write_options, |w| {
                let mut sink = y4m_sink(w, header.as_deref(), &made)?;
                stats = Some(run(
                    source.as_mut(),
                    Some(&mut sink as &mut dyn FrameSink),
                    &mut processor,
                    &mut on_frame,
                )?);
                Ok(())
            })
            .with_context(|| format!("writing {}", o.display()))?;
            stats.context("no run statistics")?
        }
        Some(dir) => {
            let mut sink = FrameFolderWriter::new(dir, &a.frame_format, write_options.clone())?;
            run(
                source.as_mut(),
                Some(&mut sink),
                &mut processor,
                &mut on_frame,
            )
            .with_context(|| format!("writing frames into {}", dir.display()))?
        }
    };
    progress.finish();
    if let Some(out) = json_out.as_mut() {
        if let Err(e) = out.flush() {
            json_error.get_or_insert(e);
        }
    }
    if let Some(e) = json_error {
        if e.kind() != std::io::ErrorKind::BrokenPipe {
            return Err(e).context("writing the JSON lines");
        }
    }
    let fps = stats.frames as f64 / stats.seconds.max(1e-9);
    eprintln!(
        "unshear video: {} frames in {:.2} s ({fps:.1} fps); {} full detections, {} tracked \
         searches, {} estimates rejected by the filter",
        stats.frames,
        stats.seconds,
        stats.tracker.full_detections,
        stats.tracker.local_searches,
        stats.rejected
    );
    Ok(())
}

/// `fps` as a y4m rate fraction (exact for integers, 1/1000 precision otherwise).
fn frame_rate_fraction(fps: f64) -> (u32, u32) {
    if fps.fract() == 0.0 && fps <= f64::from(u32::MAX) {
        (fps as u32, 1)
    } else {
        ((fps * 1000.0).round().min(f64::from(u32::MAX)) as u32, 1000)
    }
}

fn same_path(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(x), Ok(y)) => x == y,
        _ => false,
    }
}

/// `frames, fps` on stderr, redrawn at most twice a second, only when stderr is a terminal.
struct Progress {
    enabled: bool,
    start: Instant,
    last: Instant,
    frames: u64,
}

impl Progress {
    fn new() -> Self {
        let now = Instant::now();
        Self {
            enabled: std::io::stderr().is_terminal(),
            start: now,
            last: now,
            frames: 0,
        }
    }

    fn frame(&mut self) {
        self.frames += 1;
        if self.enabled && self.last.elapsed().as_secs_f64() >= 0.5 {
            self.last = Instant::now();
            let fps = self.frames as f64 / self.start.elapsed().as_secs_f64().max(1e-9);
            eprint!("\runshear video: frame {} ({fps:.1} fps)   ", self.frames);
        }
    }

    fn finish(&self) {
        if self.enabled && self.frames > 0 {
            eprint!("\r{:60}\r", "");
        }
    }
}

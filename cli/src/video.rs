//! `unshear video`: y4m files and pipes, frame folders, and any container FFmpeg reads and
//! writes (through the `ffmpeg` program); per-frame JSON; progress on stderr.
//!
//! `IN` is a y4m file (told by its first bytes, whatever its name), `-` (a y4m stream on stdin),
//! a folder of numbered frames, or any other file, which `ffmpeg` decodes. `OUT` is `-` (y4m on
//! stdout), a path ending in `.y4m`, a path with a video container's extension (`.mp4`,
//! `.mov`, `.mkv`, `.webm`...: `ffmpeg` encodes it, with the input's sound, subtitles, rotation
//! and colour tags), or otherwise a folder that receives `000000.png`, `000001.png`, ...
//! (`--frame-format`). Without `-o` nothing is written (analysis). Files are written under a
//! temporary name beside the output and renamed when complete.

use std::fs::File;
use std::io::{BufReader, BufWriter, IsTerminal, Read, Write};
use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressState, ProgressStyle};
use serde::Serialize;

use crate::args::{CalibrateArgs, ChromaArg, KSourceArg, VideoArgs};
use crate::ffmpeg::{PendingDecoder, PendingEncoder, TempOutput, Tools};
use crate::models::load_models;

use crate::ffmpeg::plan::{
    decode_args, even_size, y4m_target, Capabilities, EncodePlan, EncodeSettings, Probe,
    StreamAction, Timing,
};
use crate::report::{face, r4, JsonFace};
use crate::{create_parent, interrupt, output_key, usage_error};
use unshear::imageio::WriteOptions;
use unshear::video::frames::{frame_gaps, list_frames, FrameFolderReader, FrameFolderWriter};
use unshear::video::y4m::{Y4mReader, Y4mWriter};
use unshear::video::TrackerParams;
use unshear::video::{
    run, Chroma, FrameResult, FrameSink, FrameSource, KSource, ProcessOptions, RunStats,
    ShearSource, VideoFormat, VideoFrame, VideoProcessor,
};
use unshear::video::{Calibration, FilterParams};

/// Two decimals: pixels per frame.
fn r2(v: f64) -> f64 {
    (v * 100.0).round() / 100.0
}

/// The most memory the frames held for the readout's calibration may take.
const CALIBRATION_HOLD_BYTES: u64 = 512 << 20;

/// Largest `--smoothing-lag`: the processor holds that many decoded frames in memory.
const MAX_SMOOTHING_LAG: usize = 250;

/// One frame, as printed by `--json`.
#[derive(Debug, Serialize)]
struct JsonFrame {
    frame: u64,
    k_raw: Option<f64>,
    k: f64,
    k_source: ShearSource,
    readout_fraction: Option<f64>,
    velocity: Option<[f64; 2]>,
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    faces_disagree: bool,
    #[serde(skip_serializing_if = "Option::is_none")]
    blur: Option<f64>,
    faces: Vec<JsonVideoFace>,
}

/// One face of a frame, as printed by `--json`: the stills' fields and its track and motion.
#[derive(Debug, Serialize)]
struct JsonVideoFace {
    #[serde(flatten)]
    face: JsonFace,
    track: u64,
    velocity: Option<[f64; 2]>,
    k_motion: Option<f64>,
}

fn json_line(r: &FrameResult) -> String {
    let line = JsonFrame {
        frame: r.index,
        k_raw: r.k_raw.map(r4),
        k: r4(r.k),
        k_source: r.k_source,
        readout_fraction: r.readout_fraction.map(r4),
        velocity: r.velocity.map(|[x, y]| [r2(x), r2(y)]),
        faces_disagree: r.faces_disagree,
        blur: r.blur.map(r2),
        faces: r
            .faces
            .iter()
            .enumerate()
            .map(|(i, f)| JsonVideoFace {
                face: face(f),
                track: r.tracks.get(i).copied().unwrap_or_default(),
                velocity: r
                    .face_velocities
                    .get(i)
                    .copied()
                    .flatten()
                    .map(|[x, y]| [r2(x), r2(y)]),
                k_motion: r.face_k_motion.get(i).copied().flatten().map(r4),
            })
            .collect(),
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

/// Video container extensions written through ffmpeg (other paths are frame folders).
const CONTAINER_EXTENSIONS: &[&str] = &[
    "mp4", "m4v", "mov", "qt", "mkv", "webm", "avi", "ts", "m2ts", "mts", "mxf", "flv", "ogv",
    "3gp", "3g2", "nut", "mpg", "mpeg", "wmv", "asf",
];

fn is_container_path(p: &Path) -> bool {
    !p.is_dir()
        && p.extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| CONTAINER_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
}

/// Whether the file starts like a y4m stream.
fn starts_as_y4m(p: &Path) -> Result<bool> {
    let mut magic = [0u8; 10];
    let mut f = File::open(p).with_context(|| format!("opening {}", p.display()))?;
    let mut n = 0;
    while n < magic.len() {
        match f.read(&mut magic[n..]) {
            Ok(0) => break,
            Ok(k) => n += k,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e).with_context(|| format!("reading {}", p.display())),
        }
    }
    Ok(&magic[..n] == b"YUV4MPEG2 ")
}

/// The frames of a y4m file, from its size (for the progress bar).
fn y4m_file_frames(p: &Path, header: &[u8], format: &VideoFormat) -> Option<u64> {
    let size = p.metadata().ok()?.len();
    // Each frame: "FRAME\n" (parameters are rare) and its samples.
    let per_frame = format.frame_bytes() + 6;
    Some(size.saturating_sub(header.len() as u64) / per_frame)
}

/// `ffmpeg`, `ffprobe` and what they can do, found when a video file needs them.
struct Ffmpeg {
    tools: Tools,
    caps: Capabilities,
}

/// What the preparation hands back: ffmpeg and what it can do; for a video-file input, its
/// probe and its decoder, already started; for a video-file output, its encoder, already
/// started when its bit depth is known by then (a video-file input).
struct Prepared {
    ff: Ffmpeg,
    input: Option<(Probe, PendingDecoder)>,
    /// How to start the input's decoder again, for a second pass.
    decode: Option<Decode>,
    job: Option<EncodeJob>,
}

/// A video-file input's decoding command.
#[derive(Clone)]
struct Decode {
    probe: Probe,
    args: Vec<std::ffi::OsString>,
    indexed: Option<u64>,
}

impl Ffmpeg {
    /// Finds the programs (`why`: what needs them, for the error without them), asks what
    /// `ffmpeg` can do and probes a video-file input (side by side), then starts its decoder
    /// and the encoder of a video-file output `out`, as the shell starts both ends of a pipe.
    fn prepare(
        a: &VideoArgs,
        why: &str,
        container_in: bool,
        out: Option<&Path>,
    ) -> Result<Prepared> {
        let timeout = (a.ffmpeg_timeout > 0).then(|| Duration::from_secs(a.ffmpeg_timeout));
        let tools = Tools::find(a.ffmpeg.as_deref(), why, timeout)?;
        let (caps, probe) = std::thread::scope(|scope| {
            let probe = container_in.then(|| scope.spawn(|| tools.probe(&a.input)));
            let caps = tools.capabilities();
            let probe = probe.map(|h| {
                h.join()
                    .unwrap_or_else(|_| Err(anyhow::anyhow!("ffprobe panicked")))
            });
            (caps, probe)
        });
        let ff = Self { tools, caps: caps? };
        let Some(probe) = probe.transpose()? else {
            return Ok(Prepared {
                ff,
                input: None,
                decode: None,
                job: None,
            });
        };
        let target = y4m_target(probe.video.pix_fmt.as_deref());
        if target.converts {
            eprintln!(
                "unshear video: note: {} is {}, processed as {} (the nearest layout unshear \
                 reads)",
                a.input.display(),
                probe.video.pix_fmt.as_deref().unwrap_or("?"),
                target.pix_fmt
            );
        }
        let args = decode_args(&a.input, &probe, &target, &ff.caps);
        // Decoded at a constant rate, the frame count may differ from the index's.
        let indexed = match probe.timing() {
            Timing::Constant((n, d)) => {
                let avg = probe
                    .video
                    .avg_frame_rate
                    .map_or(0.0, |(an, ad)| f64::from(an) / f64::from(ad));
                eprintln!(
                    "unshear video: note: {} has a variable frame rate (average {avg:.2} fps): \
                     it is decoded at a constant {:.2} fps, frames repeated where the rate \
                     dropped, so that picture and sound stay in step",
                    a.input.display(),
                    f64::from(n) / f64::from(d)
                );
                None
            }
            _ => probe.video.frames,
        };
        let decoder = PendingDecoder::spawn(&ff.tools, &args, &a.input, indexed)?;
        let job = match out {
            Some(o) => Some(EncodeJob::start(
                a,
                &ff,
                o,
                std::slice::from_ref(&a.input),
                target.bit_depth,
                Some((&a.input, &probe)),
            )?),
            None => None,
        };
        let decode = Some(Decode {
            probe: probe.clone(),
            args,
            indexed,
        });
        Ok(Prepared {
            ff,
            input: Some((probe, decoder)),
            decode,
            job,
        })
    }
}

/// Where frames come from.
struct Opened {
    source: Box<dyn FrameSource>,
    /// The y4m header of a y4m or decoded input (the output repeats it).
    header: Option<Vec<u8>>,
    /// The frames' format (made from the first image for a folder).
    format: VideoFormat,
    /// Files that must not be overwritten.
    protected: Vec<PathBuf>,
    /// Frames to expect, when known.
    expected: Option<u64>,
    /// A container input: its path and probe.
    container: Option<(PathBuf, Probe)>,
}

/// The frames of a first pass, held in memory for the second.
struct HeldFrames(std::vec::IntoIter<VideoFrame>);

impl FrameSource for HeldFrames {
    fn next_frame(&mut self) -> unshear::Result<Option<VideoFrame>> {
        Ok(self.0.next())
    }
}

/// The input read again from the start, for the second of two passes (a file, not a pipe).
fn reopen_input(a: &VideoArgs, ff: Option<&Ffmpeg>, decode: Option<&Decode>) -> Result<Opened> {
    let decoder = match (ff, decode) {
        (Some(ff), Some(d)) => {
            let pending = PendingDecoder::spawn(&ff.tools, &d.args, &a.input, d.indexed)?;
            Some((d.probe.clone(), pending))
        }
        _ => None,
    };
    open_input(a, decoder)
}

/// The input's frames; a video file's probe and decoder from [`Ffmpeg::prepare`].
fn open_input(a: &VideoArgs, decoder: Option<(Probe, PendingDecoder)>) -> Result<Opened> {
    let max = a.model.max_pixels;
    let y4m = |reader: Y4mReader<BufReader<Box<dyn Read + Send>>>,
               protected: Vec<PathBuf>,
               expected: Option<u64>| Opened {
        header: Some(reader.header().to_vec()),
        format: reader.format().clone(),
        source: Box::new(reader),
        protected,
        expected,
        container: None,
    };
    if is_stdio(&a.input) {
        let stdin: Box<dyn Read + Send> = Box::new(std::io::stdin());
        let reader = Y4mReader::new(BufReader::with_capacity(1 << 20, stdin), max)
            .context("reading y4m from stdin")?;
        return Ok(y4m(reader, Vec::new(), None));
    }
    if a.input.is_dir() {
        let paths = list_frames(&a.input)?;
        warn_gaps(&a.input, &paths);
        let reader = FrameFolderReader::new(paths, max)
            .with_context(|| format!("reading the first frame in {}", a.input.display()))?;
        let (width, height) = reader.dimensions();
        return Ok(Opened {
            header: None,
            format: VideoFormat {
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
                bit_depth: 8,
            },
            protected: reader.paths().to_vec(),
            expected: Some(reader.paths().len() as u64),
            source: Box::new(reader),
            container: None,
        });
    }
    if starts_as_y4m(&a.input)? {
        let file =
            File::open(&a.input).with_context(|| format!("opening {}", a.input.display()))?;
        let file: Box<dyn Read + Send> = Box::new(file);
        let reader = Y4mReader::new(BufReader::with_capacity(1 << 20, file), max)
            .with_context(|| format!("reading {}", a.input.display()))?;
        let expected = y4m_file_frames(&a.input, reader.header(), reader.format());
        return Ok(y4m(reader, vec![a.input.clone()], expected));
    }
    // Anything else is a video file for ffmpeg.
    let Some((probe, decoder)) = decoder else {
        bail!("{}: ffmpeg was not set up for it", a.input.display());
    };
    let decoder = decoder.open(max)?;
    Ok(Opened {
        header: Some(decoder.header().to_vec()),
        format: decoder.format().clone(),
        source: Box::new(decoder),
        protected: vec![a.input.clone()],
        expected: probe.expected_frames(),
        container: Some((a.input.clone(), probe)),
    })
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
    video_or_calibrate(a, None).map(|_| ())
}

/// `unshear calibrate`: the clip analysed as `unshear video --no-correct` would, then the
/// readout fraction fitted over every face reading printed. `Ok(false)` when it could not be
/// found (exit code 1).
pub fn calibrate(c: CalibrateArgs) -> Result<bool> {
    use clap::{Args as _, FromArgMatches as _};
    let matches = VideoArgs::augment_args(clap::Command::new("video"))
        .try_get_matches_from(["video", "-"])
        .context("default video settings")?;
    let mut a = VideoArgs::from_arg_matches(&matches).context("default video settings")?;
    a.input = c.input;
    a.fps = c.fps;
    a.ffmpeg = c.ffmpeg;
    a.ffmpeg_timeout = c.ffmpeg_timeout;
    a.model = c.model;
    a.no_correct = true;
    a.calibration_window = 0;
    video_or_calibrate(a, Some(c.json))
}

/// Prints what `unshear calibrate` found; false when the readout could not be found.
fn print_calibration(c: Option<Calibration>, frames: u64, fps: f64, json: bool) -> bool {
    // A fit whose uncertainty is half its value or more says nothing: the faces hardly moved
    // and the motion kept one speed.
    let found = c.filter(|c| {
        c.readout_fraction > 0.0
            && c.readout_fraction <= unshear::video::MAX_READOUT_FRACTION
            && c.uncertainty < 0.5 * c.readout_fraction
    });
    let reason = match (c, found) {
        (_, Some(_)) => None,
        (None, _) => Some(
            "no face was seen moving and the motion never changed speed (a still camera, or \
             a steady pan without faces): the readout cannot be found from this clip",
        ),
        (Some(c), None) if c.uncertainty >= 0.5 * c.readout_fraction.abs() => Some(
            "the faces hardly moved and the motion kept one speed: the readout cannot be \
             found from this clip; try one with a pan that stops, turns or shakes",
        ),
        (Some(_), None) => Some(
            "the faces' shear does not follow their motion as a rolling shutter's would (a \
             readout fraction outside (0, 1.2]): the readout cannot be found from this clip",
        ),
    };
    if json {
        let value = serde_json::json!({
            "readout_fraction": found.map(|c| r4(c.readout_fraction)),
            "readout_ms": found.map(|c| r2(c.readout_ms(fps))),
            "fps": fps,
            "uncertainty": found.map(|c| r4(c.uncertainty)),
            "frames_used": found.map_or(0, |c| c.frames),
            "readings": found.map_or(0, |c| c.samples),
            "tracks": found.map_or(0, |c| c.tracks),
            "motion_pairs": found.map_or(0, |c| c.motion_pairs),
            "frames": frames,
            "reason": reason,
        });
        println!("{value}");
    }
    match (found, reason) {
        (Some(c), _) => {
            if !json {
                let motion = if c.motion_pairs > 0 {
                    format!(" and the motion of {} frame pairs", c.motion_pairs)
                } else {
                    String::new()
                };
                println!(
                    "readout fraction {:.3} +- {:.3} ({:.2} ms at {fps:.3} fps), from {} face \
                     readings in {} frames ({} faces){motion}",
                    c.readout_fraction,
                    c.uncertainty,
                    c.readout_ms(fps),
                    c.samples,
                    c.frames,
                    c.tracks
                );
            }
            true
        }
        (None, reason) => {
            eprintln!("unshear calibrate: {}", reason.unwrap_or("no result"));
            false
        }
    }
}

/// `unshear video`, or with `calibrate` (`Some(json)`) `unshear calibrate`'s analysis.
fn video_or_calibrate(a: VideoArgs, calibrate: Option<bool>) -> Result<bool> {
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
    if a.redetect == Some(0) || a.lost_interval == 0 {
        usage_error("--redetect and --lost-interval must be at least 1");
    }
    if a.smoothing_lag > MAX_SMOOTHING_LAG {
        usage_error(&format!(
            "--smoothing-lag must be at most {MAX_SMOOTHING_LAG} frames (frames are held in memory)"
        ));
    }
    if let (Some(json), Some(out)) = (a.json.as_deref(), a.output.as_deref()) {
        if !is_stdio(json) && !is_stdio(out) && same_target(json, out) {
            usage_error(&format!(
                "--json={} and -o {} name the same file; give the JSON another name",
                json.display(),
                out.display()
            ));
        }
    }
    let output = match a.output.as_deref() {
        None => Output::None,
        Some(o) if is_stdio(o) => Output::Stdout,
        Some(o) if is_y4m_path(o) => Output::Y4mFile(o.to_path_buf()),
        Some(o) if is_container_path(o) => Output::Container(o.to_path_buf()),
        Some(o) => Output::Folder(o.to_path_buf()),
    };
    if let (Output::Folder(dir), Some(json)) = (&output, a.json.as_deref()) {
        let inside = json.parent().is_some_and(|p| {
            let p = if p.as_os_str().is_empty() {
                Path::new(".")
            } else {
                p
            };
            same_target(p, dir)
        });
        if !is_stdio(json) && inside {
            usage_error(&format!(
                "--json={} lies in the frame folder -o {}; write it elsewhere",
                json.display(),
                dir.display()
            ));
        }
    }
    // A video file in or out needs ffmpeg: found, asked what it can do and the input probed
    // while the models load (each start of ffmpeg or ffprobe takes a good part of a second on
    // a busy machine), and before any frame is processed.
    let container_in = !is_stdio(&a.input) && !a.input.is_dir() && !starts_as_y4m(&a.input)?;
    let why = match &output {
        _ if container_in => Some(format!("reading {} (not a y4m file)", a.input.display())),
        Output::Container(o) => Some(format!("writing {}", o.display())),
        _ => None,
    };
    let container_out = match &output {
        Output::Container(o) => Some(o.as_path()),
        _ => None,
    };
    let (models, prepared) = std::thread::scope(|scope| {
        let prepared = why.map(|why| {
            let a = &a;
            scope.spawn(move || Ffmpeg::prepare(a, &why, container_in, container_out))
        });
        let models = load_models(&a.model, unshear::Config::video());
        let prepared = prepared.map(|h| {
            h.join()
                .unwrap_or_else(|_| Err(anyhow::anyhow!("preparing ffmpeg panicked")))
        });
        (models, prepared)
    });
    let unshear = models?;
    let (ffmpeg, decoder, decode, mut job) = match prepared.transpose()? {
        Some(p) => (Some(p.ff), p.input, p.decode, p.job),
        None => (None, None, None, None),
    };
    let input = open_input(&a, decoder)?;
    let Opened {
        mut source,
        header,
        format,
        protected,
        expected,
        container,
    } = input;
    let fps = format.fps();
    let readout_fraction = match (a.readout_fraction, a.readout_ms) {
        (Some(rho), _) => Some(rho),
        (None, Some(ms)) => {
            let rho = ms * fps / 1000.0;
            if unshear::video::check_readout_fraction(rho).is_err() {
                usage_error(&format!(
                    "--readout-ms {ms} at {fps:.3} frames/s is a readout fraction of {rho:.3}, \
                     outside (0, 1.2]: a sensor reads its rows within the frame interval"
                ));
            }
            Some(rho)
        }
        (None, None) => None,
    };
    let deblur = match (a.deblur, a.exposure, a.exposure_ms) {
        (false, _, _) => None,
        (true, Some(e), _) => Some(Some(e)),
        (true, None, Some(ms)) => Some(Some(ms * fps / 1000.0)),
        // Estimated over the clip from the blur itself.
        (true, None, None) => Some(None),
    }
    .map(|exposure| {
        let d = match exposure {
            Some(e) => unshear::video::Deblur::new(e).unwrap_or_else(|_| {
                usage_error(&format!(
                    "an exposure of {e:.3} frame intervals at {fps:.3} frames/s is outside \
                     (0, 1]"
                ))
            }),
            None => unshear::video::Deblur::estimated(),
        };
        unshear::video::Deblur {
            noise_to_signal: a.deblur_noise,
            ..d
        }
    });
    let frame_bytes = format.frame_bytes().max(1);
    let calibration_window = a
        .calibration_window
        .min(usize::try_from(CALIBRATION_HOLD_BYTES / frame_bytes).unwrap_or(usize::MAX));
    let options = ProcessOptions {
        tracker: TrackerParams {
            redetect_interval: a.redetect.unwrap_or(
                TrackerParams::for_detector(unshear.uses_network_detector()).redetect_interval,
            ),
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
        // The frames are decoded as stored; a clip flagged for display turned is analysed
        // turned upright (a phone held upright: read out along the shown columns).
        rotation: container.as_ref().map_or(0, |(_, p)| p.video.rotation),
        readout: unshear::Readout::Rows,
        readout_fraction,
        motion: !a.no_motion,
        vertical: a.vertical,
        region: a.region.into(),
        calibration_window,
        deblur,
        ..ProcessOptions::default()
    };
    let rotation = options.rotation;
    let mut processor = VideoProcessor::new(&unshear, options);
    if let Some(json) = calibrate {
        let mut progress = Progress::new(expected, "unshear calibrate");
        let frames =
            unshear::video::analyse(source.as_mut(), &mut processor, |_| progress.frame())?;
        progress.finish();
        return Ok(print_calibration(
            processor.calibration(),
            frames as u64,
            fps,
            json,
        ));
    }
    // A file is read twice: the readout (or the exposure, when the blur is to be removed
    // and the exposure is not given) found over the whole clip, then every frame corrected
    // with it, the first ones included. A pipe is read once, finding them while correcting.
    let exposure_wanted = deblur.is_some_and(|d| d.exposure.is_none());
    let two_pass = !a.one_pass
        && (readout_fraction.is_none() || exposure_wanted)
        && !a.no_motion
        && rotation == 0
        && !is_stdio(&a.input);
    let write_options = WriteOptions {
        overwrite: a.force,
        protected: protected.clone(),
        ..Default::default()
    };

    // Every refusal before anything is created (the JSON file included).
    check_output(&output, &protected, a.force, &a.frame_format)?;
    // Per-frame JSON and progress, on the processing thread.
    let mut json_tmp: Option<(TempOutput, PathBuf)> = None;
    let mut json_out: Option<Box<dyn Write>> = match a.json.as_deref() {
        None => None,
        Some(p) if is_stdio(p) => Some(Box::new(BufWriter::new(std::io::stdout()))),
        Some(p) => {
            refuse_overwrite(p, &protected, a.force)?;
            // Written beside it and renamed into place at the end, as the video: a run that
            // fails leaves no partial JSON.
            create_parent(p)?;
            let tmp = TempOutput::new(&folder_of(p), "jsonl")?;
            let file = File::options()
                .write(true)
                .open(tmp.path())
                .with_context(|| format!("opening {}", tmp.path().display()))?;
            json_tmp = Some((tmp, p.to_path_buf()));
            Some(Box::new(BufWriter::new(file)))
        }
    };
    let mut json_error: Option<std::io::Error> = None;
    let mut analysed = 0.0;
    if two_pass {
        let mut first = Progress::new(expected, "unshear video: analysing");
        let start = std::time::Instant::now();
        // A video file's frames, when they fit in the calibration's memory budget, are held
        // rather than decoded again (a y4m file or a folder is cheaper to read again than to
        // hold).
        let mut held = container.is_some().then(Vec::new);
        let mut bytes = 0u64;
        unshear::video::analyse(source.as_mut(), &mut processor, |frame| {
            first.frame();
            bytes += frame_bytes;
            match held.as_mut() {
                Some(frames) if bytes <= CALIBRATION_HOLD_BYTES => frames.push(frame),
                _ => held = None,
            }
        })?;
        first.finish();
        analysed = start.elapsed().as_secs_f64();
        source = match held {
            Some(frames) => Box::new(HeldFrames(frames.into_iter())),
            None => reopen_input(&a, ffmpeg.as_ref(), decode.as_ref())?.source,
        };
    }
    let mut progress = Progress::new(expected, "unshear video");
    let mut frames_with_faces = 0u64;
    let mut frames_measured = 0u64;
    let mut on_frame = |r: &FrameResult| {
        if let Some(out) = json_out.as_mut() {
            if json_error.is_none() {
                if let Err(e) = writeln!(out, "{}", json_line(r)) {
                    json_error = Some(e);
                }
            }
        }
        if !r.faces.is_empty() {
            frames_with_faces += 1;
        }
        if r.k_raw.is_some() {
            frames_measured += 1;
        }
        progress.frame();
    };

    let mut pass = |source: &mut dyn FrameSource, sink: Option<&mut dyn FrameSink>| {
        if two_pass {
            unshear::video::replay(source, sink, &mut processor, &mut on_frame)
        } else {
            run(source, sink, &mut processor, &mut on_frame)
        }
    };
    let mut written = None;
    let mut stats: RunStats = match &output {
        Output::None => pass(source.as_mut(), None)?,
        Output::Stdout => {
            let w = BufWriter::with_capacity(1 << 20, std::io::stdout());
            let mut sink = y4m_sink(w, header.as_deref(), &format)?;
            pass(source.as_mut(), Some(&mut sink))?
        }
        Output::Y4mFile(o) => {
            create_parent(o)?;
            let mut stats = None;
            unshear::imageio::write_atomic(o, &write_options, |w| {
                let mut sink = y4m_sink(w, header.as_deref(), &format)?;
                stats = Some(pass(
                    source.as_mut(),
                    Some(&mut sink as &mut dyn FrameSink),
                )?);
                Ok(())
            })
            .map_err(|e| anyhow::anyhow!("writing {}: {}", o.display(), flat_error(&e)))?;
            stats.context("no run statistics")?
        }
        Output::Folder(dir) => {
            let mut sink = FrameFolderWriter::new(dir, &a.frame_format, write_options.clone())?;
            let stats = pass(source.as_mut(), Some(&mut sink))
                .with_context(|| format!("writing frames into {}", dir.display()))?;
            sink.commit()
                .with_context(|| format!("writing frames into {}", dir.display()))?;
            let later = sink.later_frames();
            if later > 0 {
                eprintln!(
                    "unshear video: warning: {later} frames numbered after the last one \
                     written are left in {} from before; the folder reads as a longer clip",
                    dir.display()
                );
            }
            stats
        }
        Output::Container(o) => {
            let ff = ffmpeg.as_ref().context("ffmpeg was not set up")?;
            let job = match job.take() {
                Some(job) => job,
                None => EncodeJob::start(
                    &a,
                    ff,
                    o,
                    &protected,
                    format.bit_depth,
                    container.as_ref().map(|(p, probe)| (p.as_path(), probe)),
                )?,
            };
            let (stats, plan) = job.finish(&a, ff, header.as_deref(), &format, |sink| {
                pass(source.as_mut(), Some(sink))
            })?;
            written = Some((o.clone(), plan));
            stats
        }
    };
    stats.seconds += analysed;
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
    drop(json_out);
    if let Some((tmp, p)) = json_tmp {
        tmp.persist(&p, a.force)
            .with_context(|| format!("writing {}", p.display()))?;
    }
    let speed = stats.frames as f64 / stats.seconds.max(1e-9);
    eprintln!(
        "unshear video: {} frames in {:.2} s ({speed:.1} fps); faces in {frames_with_faces} \
         frames; {} full detections, {} tracked searches, {} estimates rejected by the filter",
        stats.frames,
        stats.seconds,
        stats.tracker.full_detections,
        stats.tracker.local_searches,
        stats.rejected
    );
    eprintln!(
        "unshear video: {}",
        describe_model(
            &stats,
            a.readout_fraction.is_some() || a.readout_ms.is_some(),
            !a.no_motion
        )
    );
    if a.deblur {
        let given = a.exposure.is_some() || a.exposure_ms.is_some();
        match stats.exposure {
            Some(e) => eprintln!(
                "unshear video: motion blur removed with an exposure of {e:.3} of the frame \
                 interval ({:.2} ms){}",
                e / fps * 1000.0,
                if given {
                    ""
                } else {
                    ", estimated from the blur"
                }
            ),
            None => eprintln!(
                "unshear video: motion blur not removed: the exposure could not be estimated \
                 (too few frames moving fast enough show a clear blur; give --exposure)"
            ),
        }
    }
    if let Some((o, plan)) = &written {
        eprintln!("unshear video: wrote {}: {}", o.display(), describe(plan));
    }
    if let Some((_, probe)) = &container {
        let r = probe.video.rotation;
        if r != 0 && !matches!(output, Output::Container(_) | Output::None) {
            eprintln!(
                "unshear video: note: the input is flagged for display rotated by {r} degrees; \
                 y4m and frame folders carry no such flag, so their frames are as stored"
            );
        }
        if r.abs() == 90 {
            eprintln!(
                "unshear video: note: the clip is shown turned by {r} degrees (a phone held \
                 upright): it was read out along the shown picture's columns, so k is the \
                 shown picture's vertical shear, y' = y + k x, undone along the stored rows"
            );
        } else if r != 0 && r != 180 {
            eprintln!(
                "unshear video: note: the clip is flagged for display turned by {r} degrees, \
                 not a quarter or half turn: its frames are analysed as stored"
            );
        }
    }
    Ok(true)
}

/// The summary's line on the rolling-shutter model: where the frames' `k` came from and the
/// readout fraction used, or why motion was not used.
fn describe_model(stats: &RunStats, given: bool, motion: bool) -> String {
    let s = stats.sources;
    let counts = format!(
        "k from motion in {} frames, from faces in {}, none in {}",
        s.motion, s.faces, s.none
    );
    let disagree = if s.disagreements > 0 {
        format!(
            "; in {} motion frames the faces disagreed with the motion beyond their noise",
            s.disagreements
        )
    } else {
        String::new()
    };
    let readout = match (stats.readout_fraction, stats.calibration) {
        _ if !motion => "the faces alone (--no-motion)".to_string(),
        (Some(rho), _) if given => format!("readout fraction {rho:.3} (given)"),
        (Some(rho), Some(c)) => format!(
            "readout fraction {rho:.3} calibrated from {} ({:.3} +- {:.3} over the whole \
             clip, {} face readings, {} frame pairs of changing motion)",
            match (c.samples > 0, c.motion_pairs > 0) {
                (true, true) => "the faces and the motion",
                (false, true) => "the motion",
                _ => "the faces",
            },
            c.readout_fraction,
            c.uncertainty,
            c.samples,
            c.motion_pairs
        ),
        (Some(rho), None) => format!("readout fraction {rho:.3}"),
        (None, None) => "readout fraction not found: no face was seen moving and the motion \
                         never changed speed, so k came from the faces alone (give \
                         --readout-fraction to correct by motion)"
            .to_string(),
        (None, Some(c)) => format!(
            "readout fraction not found to 10% ({:.3} +- {:.3} from {} readings): k came \
             from the faces alone (give --readout-fraction to correct by motion)",
            c.readout_fraction, c.uncertainty, c.samples
        ),
    };
    format!("{readout}; {counts}{disagree}")
}

/// Where frames go.
enum Output {
    None,
    Stdout,
    Y4mFile(PathBuf),
    Folder(PathBuf),
    Container(PathBuf),
}

/// Writing a video file: the checks of the output, the temporary file beside it, the plan,
/// and the encoding `ffmpeg` started.
struct EncodeJob {
    out: PathBuf,
    dir: PathBuf,
    ext: String,
    tmp: TempOutput,
    plan: EncodePlan,
    encoder: PendingEncoder,
}

impl EncodeJob {
    /// Checks `out` (never an input, replaced only with `--force`), creates the temporary file
    /// and starts `ffmpeg` on it, for frames of `bit_depth` from `source`, if a video file.
    fn start(
        a: &VideoArgs,
        ff: &Ffmpeg,
        out: &Path,
        protected: &[PathBuf],
        bit_depth: u32,
        source: Option<(&Path, &Probe)>,
    ) -> Result<Self> {
        if protected.iter().any(|p| same_path(p, out)) {
            bail!("refusing to write {}: it is an input file", out.display());
        }
        if out.exists() && !a.force {
            bail!(
                "refusing to write {}: it exists; use --force to replace it",
                out.display()
            );
        }
        let dir = folder_of(out);
        create_parent(out)?;
        let ext = out
            .extension()
            .and_then(|e| e.to_str())
            .unwrap_or("mp4")
            .to_string();
        let tmp = TempOutput::new(&dir, &ext)?;
        let settings = EncodeSettings {
            codec: a.codec.clone(),
            crf: a.crf,
            preset: a.preset.clone(),
        };
        let plan = EncodePlan::new(tmp.path(), bit_depth, source, &settings, &ff.caps)?;
        let encoder = PendingEncoder::spawn(&ff.tools, &plan.args, out)?;
        Ok(Self {
            out: out.to_path_buf(),
            dir,
            ext,
            tmp,
            plan,
            encoder,
        })
    }

    /// Gives the encoder the y4m header (the input's own, or one made for image frames of
    /// `format`), lets `process` run the clip into it, and renames the file to the output's
    /// name only when everything succeeded (after the remux pass that sets the rotation, for
    /// an older ffmpeg).
    fn finish(
        self,
        a: &VideoArgs,
        ff: &Ffmpeg,
        header: Option<&[u8]>,
        format: &VideoFormat,
        process: impl FnOnce(&mut dyn FrameSink) -> unshear::Result<RunStats>,
    ) -> Result<(RunStats, EncodePlan)> {
        let Self {
            out,
            dir,
            ext,
            tmp,
            plan,
            encoder,
        } = self;
        let header = match header {
            Some(h) => h.to_vec(),
            None => Y4mWriter::new(Vec::new(), format)?.finish()?,
        };
        let pad = even_size(
            plan.codec.as_deref(),
            format.width,
            format.height,
            format.chroma,
        );
        if let Some((w, h)) = pad {
            let encoder_name = plan.codec.as_deref().unwrap_or("ffmpeg's default encoder");
            eprintln!(
                "unshear video: warning: {encoder_name} cannot encode {}x{} {} frames (its \
                 subsampled chroma needs an even width{}); {} is padded to {w}x{h} by repeating \
                 the last {}; --codec ffv1 (lossless) or libvpx-vp9 keeps the size",
                format.width,
                format.height,
                chroma_name(format.chroma),
                if matches!(
                    format.chroma,
                    unshear::video::Chroma::Yuv420 | unshear::video::Chroma::Yuv420CoSited
                ) {
                    " and height"
                } else {
                    ""
                },
                out.display(),
                match (w != format.width, h != format.height) {
                    (true, true) => "column and row",
                    (true, false) => "column",
                    _ => "row",
                }
            );
        }
        let mut encoder = encoder.begin(&header, pad)?;
        let stats = process(&mut encoder).with_context(|| format!("writing {}", out.display()))?;
        drop(encoder);
        let finished = match plan.remux_rotation {
            Some(rotation) => {
                let rotated = TempOutput::new(&dir, &ext)?;
                let args = EncodePlan::remux_args(tmp.path(), rotated.path(), rotation);
                ff.tools
                    .run(&args, &format!("setting the rotation of {}", out.display()))?;
                // Only older FFmpeg (5.1, not 7.0) takes the tag this way: check that it did.
                let got = ff.tools.probe(rotated.path())?.video.rotation;
                if got != rotation {
                    eprintln!(
                        "unshear video: warning: this ffmpeg did not keep the rotation \
                         ({rotation} degrees, the output has {got}); an FFmpeg with \
                         -display_rotation (7.0 has it) sets
                         it directly"
                    );
                }
                rotated
            }
            None => tmp,
        };
        if interrupt::requested() {
            bail!("interrupted");
        }
        finished.persist(&out, a.force)?;
        Ok((stats, plan))
    }
}

/// What an encoding did, for the summary.
fn describe(plan: &EncodePlan) -> String {
    let mut video = match &plan.codec {
        Some(c) => format!("video {c}"),
        None => "video in ffmpeg's default codec".to_string(),
    };
    if let Some(q) = plan.crf {
        video.push_str(&format!(" crf {q}"));
    }
    if let Some(p) = &plan.preset {
        video.push_str(&format!(" preset {p}"));
    }
    let mut parts = vec![video];
    let count = |v: &[(crate::ffmpeg::plan::Stream, StreamAction)], kind: &str| {
        let copied = v.iter().filter(|(_, x)| *x == StreamAction::Copy).count();
        let converted: Vec<String> = v
            .iter()
            .filter_map(|(s, x)| match x {
                StreamAction::Convert(e) => Some(format!("{} to {e}", s.codec)),
                StreamAction::ConvertToDefault => Some(format!("{} to ffmpeg's default", s.codec)),
                _ => None,
            })
            .collect();
        let dropped: Vec<String> = v
            .iter()
            .filter_map(|(s, x)| match x {
                StreamAction::Drop(why) => Some(format!("{} stream {}: {why}", s.codec, s.index)),
                _ => None,
            })
            .collect();
        let mut p = Vec::new();
        if copied > 0 {
            p.push(format!("{copied} {kind} copied"));
        }
        if !converted.is_empty() {
            p.push(format!("{kind} converted ({})", converted.join(", ")));
        }
        if !dropped.is_empty() {
            p.push(format!("{kind} left out ({})", dropped.join(", ")));
        }
        p
    };
    parts.extend(count(&plan.audio, "audio"));
    parts.extend(count(&plan.subtitles, "subtitles"));
    if let Some(r) = plan.rotation_lost {
        parts.push(format!(
            "rotation {r} not kept (the container has no rotation flag)"
        ));
    }
    parts.join("; ")
}

/// `fps` as a y4m rate fraction (exact for integers, 1/1000 precision otherwise).
fn frame_rate_fraction(fps: f64) -> (u32, u32) {
    if fps.fract() == 0.0 && fps <= f64::from(u32::MAX) {
        (fps as u32, 1)
    } else {
        ((fps * 1000.0).round().min(f64::from(u32::MAX)) as u32, 1000)
    }
}

/// Whether `a` and `b` name the same file, existing or not (compared as `correct` compares
/// outputs, [`output_key`]).
fn same_target(a: &Path, b: &Path) -> bool {
    same_path(a, b) || output_key(a) == output_key(b)
}

/// Refuses an output that is an input or exists without `--force`, before anything is
/// written (a frame folder: by its first frame).
fn check_output(output: &Output, protected: &[PathBuf], force: bool, ext: &str) -> Result<()> {
    match output {
        Output::Y4mFile(o) | Output::Container(o) => refuse_overwrite(o, protected, force),
        Output::Folder(dir) => {
            refuse_overwrite(&dir.join(format!("000000.{ext}")), protected, force)
        }
        Output::None | Output::Stdout => Ok(()),
    }
}

/// Refuses to write `file` when it is an input, or exists without `--force`.
fn refuse_overwrite(file: &Path, protected: &[PathBuf], force: bool) -> Result<()> {
    if protected.iter().any(|p| same_path(p, file)) {
        bail!("refusing to write {}: it is an input file", file.display());
    }
    if file.exists() && !force {
        bail!(
            "refusing to write {}: it exists; use --force to replace it",
            file.display()
        );
    }
    Ok(())
}

/// The folder `path` is in (`.` for a bare file name).
fn folder_of(path: &Path) -> PathBuf {
    match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// A library error as one line: its own text, without the causes it already contains, and
/// without a temporary file's name.
fn flat_error(e: &unshear::Error) -> String {
    match e {
        unshear::Error::Io { source, .. } => {
            let text = source.to_string();
            // tempfile appends the temporary file's path, which means nothing to the user.
            text.split(" at path ").next().unwrap_or(&text).to_string()
        }
        other => other.to_string(),
    }
}

/// The name of a chroma layout for messages.
fn chroma_name(c: unshear::video::Chroma) -> &'static str {
    use unshear::video::Chroma;
    match c {
        Chroma::Mono => "grey",
        Chroma::Yuv420 | Chroma::Yuv420CoSited => "4:2:0",
        Chroma::Yuv422 => "4:2:2",
        Chroma::Yuv444 => "4:4:4",
    }
}

/// Warns about each gap in the numbering of a frame folder's files (`000003.png` then
/// `000007.png`): the frames are taken as consecutive all the same.
fn warn_gaps(dir: &Path, paths: &[PathBuf]) {
    const SHOWN: usize = 5;
    let gaps = frame_gaps(paths);
    for (before, after, missing) in gaps.iter().take(SHOWN) {
        eprintln!(
            "unshear video: warning: {}: the numbering skips from {} to {} ({missing} frame{} \
             missing); the frames are taken as consecutive",
            dir.display(),
            before,
            after,
            if *missing == 1 { "" } else { "s" }
        );
    }
    if gaps.len() > SHOWN {
        eprintln!(
            "unshear video: warning: {}: {} more gaps in the numbering",
            dir.display(),
            gaps.len() - SHOWN
        );
    }
}

fn same_path(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(x), Ok(y)) => x == y,
        _ => false,
    }
}

/// A progress bar on stderr, only when stderr is a terminal: frames (of the expected count when
/// known), frames per second and time left.
struct Progress {
    bar: ProgressBar,
}

impl Progress {
    /// A bar (on a terminal) headed by `what`.
    fn new(expected: Option<u64>, what: &str) -> Self {
        if !std::io::stderr().is_terminal() {
            return Self {
                bar: ProgressBar::hidden(),
            };
        }
        let bar = ProgressBar::with_draw_target(expected, ProgressDrawTarget::stderr_with_hz(4));
        let template = if expected.is_some() {
            format!("{what} {{bar:30}} {{pos}}/{{len}} frames, {{fps}}, {{eta}} left")
        } else {
            format!("{what} {{spinner}} {{pos}} frames, {{fps}}")
        };
        if let Ok(style) = ProgressStyle::with_template(&template) {
            bar.set_style(style.with_key(
                "fps",
                |state: &ProgressState, w: &mut dyn std::fmt::Write| {
                    let _ = write!(w, "{:.1} fps", state.per_sec());
                },
            ));
        }
        Self { bar }
    }

    fn frame(&mut self) {
        // The expected count may be an estimate: grow the bar rather than overflow it.
        if self.bar.length().is_some_and(|l| self.bar.position() >= l) {
            self.bar.inc_length(1);
        }
        self.bar.inc(1);
    }

    fn finish(&self) {
        self.bar.finish_and_clear();
    }
}

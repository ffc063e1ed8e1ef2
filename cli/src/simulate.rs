//! `unshear simulate`: a rolling-shutter clip and its truth from photos or development faces
//! (the library's [`unshear::dev::simulate`]).

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::{Args, ValueEnum};

use unshear::dev::dataset::{CaltechWebFaces, FaceDataset};
use unshear::dev::simulate::{
    development_faces, Profile, Scene, ScenePhoto, SimulationParams, Simulator,
    DEVELOPMENT_FACES_SEED, MIN_DEVELOPMENT_EYE_DISTANCE,
};
use unshear::imageio::{self, WriteOptions};
use unshear::video::color::image_to_yuv;
use unshear::video::frames::FrameFolderWriter;
use unshear::video::y4m::Y4mWriter;
use unshear::video::{Chroma, FrameSink, VideoFormat, VideoFrame};

/// The shear at the middle row that sets the peak speed when neither `--speed` nor
/// `--peak-k` is given.
const DEFAULT_PEAK_K: f64 = 0.15;

/// `unshear simulate`.
#[derive(Debug, Args)]
pub struct SimulateArgs {
    /// Photos the camera pans over, scaled to the frame height and joined left to right into a
    /// panorama that wraps around (their faces are not known to the truth; use --caltech).
    #[arg(value_name = "IMAGE", help_heading = "Scene")]
    pub images: Vec<PathBuf>,
    /// Build the panorama from development faces of the Caltech Web Faces set in DIR (photos
    /// with one annotated face, eyes at least 40 px apart once scaled, in a fixed shuffled
    /// order): their eyes are in the truth.
    #[arg(
        long,
        value_name = "DIR",
        help_heading = "Scene",
        conflicts_with = "images"
    )]
    pub caltech: Option<PathBuf>,
    /// How many development faces (photos) to join [default: 3].
    #[arg(long, value_name = "N", help_heading = "Scene",
          value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub faces: Option<u32>,
    /// Skip this many development faces first, so that clips use different faces [default: 0].
    #[arg(long, value_name = "I", help_heading = "Scene")]
    pub first: Option<u32>,

    /// The clip: a .y4m file (4:2:0, limited range), `-` for y4m on stdout, or a folder for
    /// numbered frames (000000.png, ...).
    #[arg(
        short = 'o',
        long = "output",
        value_name = "OUT",
        help_heading = "Output"
    )]
    pub output: PathBuf,
    /// The truth, one JSON line per frame (velocity, k, row offsets, faces; see
    /// docs/video.md).
    #[arg(long, value_name = "FILE", help_heading = "Output")]
    pub truth: Option<PathBuf>,
    /// Image format of the frames written into a folder.
    #[arg(
        long,
        value_name = "EXT",
        default_value = "png",
        help_heading = "Output",
        hide_short_help = true
    )]
    pub frame_format: String,
    /// Replace existing outputs (never an input).
    #[arg(long, help_heading = "Output")]
    pub force: bool,

    /// Frame width, pixels.
    #[arg(
        long,
        value_name = "PX",
        default_value_t = 1280,
        help_heading = "Frame"
    )]
    pub width: u32,
    /// Frame height, pixels.
    #[arg(long, value_name = "PX", default_value_t = 720, help_heading = "Frame")]
    pub height: u32,
    /// Number of frames.
    #[arg(long, value_name = "N", default_value_t = 90, help_heading = "Frame")]
    pub frames: u32,
    /// Frames per second.
    #[arg(
        long,
        value_name = "FPS",
        default_value_t = 30.0,
        help_heading = "Frame"
    )]
    pub fps: f64,

    /// The sensor's readout time over the frame interval, rho: row y of frame n is read at
    /// (n + rho y / H) / fps.
    #[arg(
        long,
        value_name = "RHO",
        default_value_t = 0.8,
        help_heading = "Sensor"
    )]
    pub readout_fraction: f64,
    /// Exposure time of each row, milliseconds (4 is 1/250 s); 0 for no motion blur.
    #[arg(
        long,
        value_name = "MS",
        default_value_t = 4.0,
        help_heading = "Sensor",
        conflicts_with = "exposure"
    )]
    pub exposure_ms: f64,
    /// Exposure as a fraction of the frame interval, instead of --exposure-ms.
    #[arg(long, value_name = "FRACTION", help_heading = "Sensor")]
    pub exposure: Option<f64>,
    /// Sensor noise, standard deviation in grey levels (fresh every frame).
    #[arg(
        long,
        value_name = "SIGMA",
        default_value_t = 2.0,
        help_heading = "Sensor"
    )]
    pub noise: f64,
    /// Seed of the noise and of the shaky motion.
    #[arg(long, value_name = "N", default_value_t = 0, help_heading = "Sensor")]
    pub seed: u64,

    /// How the view moves (or, for walk, a subject in front of a still camera).
    #[arg(long, value_enum, default_value_t = MotionArg::Constant, help_heading = "Motion")]
    pub motion: MotionArg,
    /// Peak horizontal image speed, px/frame (positive: content moves right) [default: the
    /// speed of --peak-k 0.15].
    #[arg(
        long,
        value_name = "PX",
        allow_negative_numbers = true,
        help_heading = "Motion"
    )]
    pub speed: Option<f64>,
    /// Peak shear at the middle row instead of --speed: speed = K * height / rho.
    #[arg(
        long,
        value_name = "K",
        allow_negative_numbers = true,
        conflicts_with = "speed",
        help_heading = "Motion"
    )]
    pub peak_k: Option<f64>,
    /// Vertical motion too (not walk) [default: none].
    #[arg(long, value_enum, value_name = "PROFILE", help_heading = "Motion")]
    pub vertical_motion: Option<MotionArg>,
    /// Peak vertical image speed, px/frame (positive: content moves down) [default: a fifth
    /// of the horizontal speed].
    #[arg(
        long,
        value_name = "PX",
        allow_negative_numbers = true,
        requires = "vertical_motion",
        help_heading = "Motion"
    )]
    pub vertical_speed: Option<f64>,

    /// Refuse photos with more pixels than this (checked before decoding).
    #[arg(long, value_name = "N", default_value_t = imageio::DEFAULT_MAX_PIXELS,
          hide_short_help = true, value_parser = clap::value_parser!(u64).range(1..))]
    pub max_pixels: u64,
}

/// `--motion` and `--vertical-motion`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum MotionArg {
    /// A steady pan.
    Constant,
    /// Full speed, ease to a stop, pause, back the other way (a camera following someone).
    Pause,
    /// A pan whose speed changes within a frame (v sin(2 pi t / 8 frames)).
    Accelerate,
    /// Hand-held shake (0.5-8 Hz) with a slow drift.
    Shaky,
    /// A still camera and a subject (the first face) walking across.
    Walk,
}

impl MotionArg {
    fn profile(self, v: f64, seed: u64) -> Profile {
        match self {
            MotionArg::Constant => Profile::Constant { v },
            MotionArg::Pause => Profile::Pause { v },
            MotionArg::Accelerate => Profile::Accelerate { v },
            MotionArg::Shaky => Profile::Shaky { v, seed },
            MotionArg::Walk => Profile::Walk { v },
        }
    }
}

/// The parameters the options describe (checked: a bad value is a usage error).
fn params(a: &SimulateArgs) -> SimulationParams {
    let exposure = a.exposure.unwrap_or(a.exposure_ms / 1000.0 * a.fps);
    let mut p = SimulationParams {
        width: a.width,
        height: a.height,
        frames: a.frames,
        fps: a.fps,
        readout_fraction: a.readout_fraction,
        exposure,
        motion: Profile::Constant { v: 0.0 },
        vertical: None,
        noise: a.noise,
        seed: a.seed,
    };
    let v = a
        .speed
        .unwrap_or_else(|| p.speed_for_k(a.peak_k.unwrap_or(DEFAULT_PEAK_K)));
    p.motion = a.motion.profile(v, a.seed);
    p.vertical = a.vertical_motion.map(|m| {
        // Its own shake: a seed apart from the horizontal one.
        m.profile(a.vertical_speed.unwrap_or(v / 5.0), a.seed ^ 0x7665_7274)
    });
    if let Err(e) = p.validate() {
        crate::usage_error(&e.to_string());
    }
    if matches!(a.vertical_motion, Some(MotionArg::Walk)) {
        crate::usage_error("--vertical-motion cannot be walk");
    }
    p
}

/// Where the clip goes.
enum Output {
    Stdout,
    Y4m(PathBuf),
    Folder(PathBuf),
}

pub fn simulate(a: SimulateArgs) -> Result<()> {
    let p = params(&a);
    if a.images.is_empty() && a.caltech.is_none() {
        crate::usage_error("give the photos to pan over, or --caltech DIR");
    }
    if a.caltech.is_none() && (a.faces.is_some() || a.first.is_some()) {
        crate::usage_error("--faces and --first choose development faces: give --caltech DIR");
    }
    let output = if a.output.as_os_str() == "-" {
        Output::Stdout
    } else if a
        .output
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("y4m"))
    {
        Output::Y4m(a.output.clone())
    } else {
        Output::Folder(a.output.clone())
    };
    // With vertical motion, a margin above and below keeps the panorama's seam (it wraps
    // vertically too) mostly out of view.
    let scene_height = if p.vertical.is_some() {
        (f64::from(p.height) * 1.15).round() as u32
    } else {
        p.height
    };

    // The scene's photos (the inputs, never written).
    let (photos, faces) = match &a.caltech {
        Some(dir) => {
            let (count, first) = (a.faces.unwrap_or(3) as usize, a.first.unwrap_or(0));
            let all = CaltechWebFaces::new(dir)
                .faces()
                .with_context(|| format!("reading the Caltech faces in {}", dir.display()))?;
            let picked = development_faces(
                all,
                scene_height,
                MIN_DEVELOPMENT_EYE_DISTANCE,
                first as usize,
                count,
                DEVELOPMENT_FACES_SEED,
            )?;
            if picked.is_empty() {
                bail!(
                    "{}: no development faces from number {} on",
                    dir.display(),
                    first
                );
            }
            if picked.len() < count {
                eprintln!(
                    "unshear simulate: warning: only {} development faces from number {} on",
                    picked.len(),
                    first
                );
            }
            (picked.iter().map(|f| f.image.clone()).collect(), picked)
        }
        None => (a.images.clone(), Vec::new()),
    };

    // Every refusal before anything is read or rendered.
    let refuse = |file: &Path| -> Result<()> {
        if photos.iter().any(|p| same_path(p, file)) {
            bail!("refusing to write {}: it is an input file", file.display());
        }
        if file.exists() && !a.force {
            bail!(
                "refusing to write {}: it exists; use --force to replace it",
                file.display()
            );
        }
        Ok(())
    };
    match &output {
        Output::Y4m(o) => refuse(o)?,
        Output::Folder(d) => refuse(&d.join(format!("000000.{}", a.frame_format)))?,
        Output::Stdout => {}
    }
    if let Some(t) = &a.truth {
        refuse(t)?;
        if matches!(&output, Output::Y4m(o) if same_path(o, t) || o == t) {
            bail!("--truth and -o name the same file");
        }
    }

    let scene = if faces.is_empty() {
        let photos = photos
            .iter()
            .map(|path| {
                Ok(ScenePhoto {
                    image: imageio::read_image(path, a.max_pixels)
                        .with_context(|| format!("reading {}", path.display()))?,
                    faces: Vec::new(),
                })
            })
            .collect::<Result<Vec<_>>>()?;
        Scene::from_images(&photos, scene_height)?
    } else {
        Scene::from_annotated(&faces, scene_height, a.max_pixels)?
    };
    let simulator = Simulator::new(scene, p.clone())?;

    let write_options = WriteOptions {
        overwrite: a.force,
        protected: photos.clone(),
        ..Default::default()
    };
    let format = VideoFormat {
        width: p.width,
        height: p.height,
        chroma: Chroma::Yuv420,
        full_range: false,
        frame_rate: frame_rate_fraction(p.fps),
        bit_depth: 8,
    };
    let started = Instant::now();
    let mut truth_lines = String::new();
    let mut render_all = |sink: &mut dyn FnMut(image::RgbImage) -> unshear::Result<()>| {
        for n in 0..p.frames {
            if crate::interrupt::requested() {
                return Err(unshear::Error::Video("interrupted".into()));
            }
            let (frame, truth) = simulator.render(n)?;
            sink(frame)?;
            let line = serde_json::to_string(&truth)
                .map_err(|e| unshear::Error::Video(format!("truth of frame {n}: {e}")))?;
            truth_lines.push_str(&line);
            truth_lines.push('\n');
        }
        Ok(())
    };
    let to_yuv = |frame: image::RgbImage| {
        image_to_yuv(
            &image::DynamicImage::ImageRgb8(frame),
            Chroma::Yuv420,
            false,
        )
    };
    match &output {
        Output::Stdout => {
            let out = std::io::BufWriter::with_capacity(1 << 20, std::io::stdout().lock());
            let mut writer = Y4mWriter::new(out, &format)?;
            render_all(&mut |f| writer.write_frame(&to_yuv(f)))?;
            writer.finish()?.flush().context("writing to stdout")?;
        }
        Output::Y4m(o) => {
            crate::create_parent(o)?;
            imageio::write_atomic(o, &write_options, |w| {
                let mut writer = Y4mWriter::new(w, &format)?;
                render_all(&mut |f| writer.write_frame(&to_yuv(f)))?;
                writer.finish().map(|_| ())
            })
            .with_context(|| format!("writing {}", o.display()))?;
        }
        Output::Folder(dir) => {
            let mut sink = FrameFolderWriter::new(dir, &a.frame_format, write_options.clone())?;
            render_all(&mut |f| sink.write_frame(VideoFrame::Image(f.into())))
                .with_context(|| format!("writing frames into {}", dir.display()))?;
            sink.commit()
                .with_context(|| format!("writing frames into {}", dir.display()))?;
        }
    }
    if let Some(t) = &a.truth {
        crate::create_parent(t)?;
        imageio::write_atomic(t, &write_options, |w| {
            w.write_all(truth_lines.as_bytes())
                .map_err(|source| unshear::Error::Io {
                    path: t.clone(),
                    source,
                })
        })
        .with_context(|| format!("writing {}", t.display()))?;
    }
    let secs = started.elapsed().as_secs_f64();
    eprintln!(
        "unshear simulate: {} frames of {}x{} ({}, peak {:.1} px/frame, rho {}, exposure {:.3}) \
         in {secs:.1} s",
        p.frames,
        p.width,
        p.height,
        match a.motion {
            MotionArg::Constant => "constant",
            MotionArg::Pause => "pause",
            MotionArg::Accelerate => "accelerate",
            MotionArg::Shaky => "shaky",
            MotionArg::Walk => "walk",
        },
        p.motion.peak(),
        p.readout_fraction,
        p.exposure,
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

/// Whether `a` and `b` are the same existing file.
fn same_path(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(x), Ok(y)) => x == y,
        _ => false,
    }
}

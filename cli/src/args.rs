//! Command-line arguments (clap derive). Usage errors exit with code 2 (clap's default).

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand, ValueEnum};

/// Remove rolling-shutter skew (horizontal shear) from photos of people, using the face as the
/// ruler.
#[derive(Debug, Parser)]
#[command(name = "unshear", version, about, long_about = None, max_term_width = 100)]
pub struct Cli {
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Estimate the shear and write corrected images.
    Correct(CorrectArgs),
    /// Estimate the shear of images (files or folders, recursively) without writing any.
    Estimate(EstimateArgs),
    /// Synthesise rolling-shutter shear: x' = x + k (y - pivot).
    Distort(DistortArgs),
    /// Correct a video: a video file (through ffmpeg), a y4m file or pipe (`-`), or a folder of
    /// numbered frames.
    Video(VideoArgs),
    /// Find a camera's readout time from a clip: the faces' shear against their motion.
    Calibrate(CalibrateArgs),
    /// Train the eye filters from an annotated data set (Caltech Web Faces layout).
    Train(TrainArgs),
    /// Measure accuracy on annotated faces sheared synthetically.
    Eval(EvalArgs),
    /// Render a rolling-shutter clip (a moving view over photos, with motion blur) and its truth.
    Simulate(crate::simulate::SimulateArgs),
    /// Serve a local web page and JSON API: drop photos, compare, adjust and download
    /// (docs/serve.md).
    Serve(ServeArgs),
}

/// `unshear serve`.
#[derive(Debug, Args)]
pub struct ServeArgs {
    /// Port to listen on [default: 8080, or a free port when 8080 is taken; 0: a free port].
    #[arg(help_heading = "Server", long, value_name = "PORT")]
    pub port: Option<u16>,
    /// Address to listen on. Anything but a loopback address lets other machines use the
    /// server (a warning is printed).
    #[arg(
        help_heading = "Server",
        long,
        value_name = "ADDR",
        default_value = "127.0.0.1"
    )]
    pub bind: std::net::IpAddr,
    /// Open the page in the default browser once listening.
    #[arg(help_heading = "Server", long)]
    pub open: bool,
    /// Refuse uploads larger than this many bytes (413), checked while the upload is read.
    #[arg(help_heading = "Server", long, value_name = "BYTES", default_value_t = 64 << 20,
          value_parser = clap::value_parser!(u64).range(1..))]
    pub max_upload: u64,
    /// Seconds a request waits for one of the --jobs workers before it is answered 503 (busy)
    /// with a Retry-After header.
    #[arg(
        help_heading = "Server",
        long,
        value_name = "SECS",
        default_value_t = 30.0
    )]
    pub wait: f64,
    /// Faces, limits and threads as for `estimate` (`--jobs`: images worked on at once, and
    /// the worker threads; `--max-pixels`: checked before decoding each upload).
    #[command(flatten)]
    pub model: ModelArgs,
}

/// Models and limits shared by the commands that look at faces.
#[derive(Debug, Clone, Args)]
pub struct ModelArgs {
    /// OpenCV Haar cascade XML to detect faces with [default: built-in frontalface_alt2].
    #[arg(
        help_heading = "Models",
        hide_short_help = true,
        long,
        value_name = "FILE"
    )]
    pub cascade: Option<PathBuf>,
    /// Filter file made by `unshear train` (its own type is used) [default: built-in].
    #[arg(
        help_heading = "Models",
        hide_short_help = true,
        long,
        value_name = "PATH"
    )]
    pub filters: Option<PathBuf>,
    /// Which built-in filter set to use [default: mosse, the built-in default type].
    #[arg(
        help_heading = "Models",
        hide_short_help = true,
        long,
        value_enum,
        value_name = "TYPE",
        conflicts_with = "filters"
    )]
    pub filter_type: Option<FilterTypeArg>,
    /// What locates the eyes, nose and mouth: `network` (the built-in landmark network, which
    /// also reads the shear itself) or `filters` (the paper's correlation filters throughout,
    /// with --filter-type, --shear-model and --refinements) [default: network].
    #[arg(help_heading = "Models", long, value_enum, value_name = "LOCATOR")]
    pub locator: Option<LocatorArg>,
    /// Landmark network file written by `scripts/train_landmarks.py` [default: built-in].
    #[arg(
        help_heading = "Models",
        hide_short_help = true,
        long,
        value_name = "PATH"
    )]
    pub network: Option<PathBuf>,
    /// Refuse images with more pixels than this (checked before decoding).
    #[arg(allow_negative_numbers = true, help_heading = "Input and output", hide_short_help = true, long, value_name = "N", default_value_t = unshear::imageio::DEFAULT_MAX_PIXELS,
          value_parser = clap::value_parser!(u64).range(1..))]
    pub max_pixels: u64,
    /// Refinement passes (at most 10): locate the features again in the face de-sheared by the
    /// last estimate.
    #[arg(
        allow_negative_numbers = true,
        help_heading = "Correction",
        hide_short_help = true,
        long,
        alias = "refine",
        value_name = "N",
        default_value_t = 0
    )]
    pub refinements: usize,
    /// How located points become k: `equation5` (the paper), `shear-roll` (eye line and nose
    /// axis, roll solved exactly), `shear-roll-yaw` (also the mouth axis, yaw extrapolated out)
    /// [default: shear-roll-yaw for stills, equation5 for `video`, where its lower per-frame
    /// noise matters more].
    #[arg(
        help_heading = "Correction",
        hide_short_help = true,
        long,
        value_name = "MODEL"
    )]
    pub shear_model: Option<ShearModelArg>,
    /// Refuse a face's estimate (report `"k": null`, do not correct by it) below this
    /// confidence (0 to 1).
    #[arg(allow_negative_numbers = true, help_heading = "Correction", long, value_name = "C", default_value_t = unshear::config::DEFAULT_MIN_CONFIDENCE)]
    pub min_confidence: f64,
    /// Refuse a face's estimate whose |k| is beyond this (report `"k": null`, `"refused":
    /// "implausible_shear"`): rolling-shutter shears of usable photos stay well below it.
    #[arg(allow_negative_numbers = true, help_heading = "Correction", hide_short_help = true, long, value_name = "K", default_value_t = unshear::config::DEFAULT_MAX_SHEAR)]
    pub max_shear: f64,
    /// Detect in the image as it is only (the paper's single pass): no de-sheared or turned
    /// retries when no face is found.
    #[arg(help_heading = "Face search", hide_short_help = true, long)]
    pub no_shear_search: bool,
    /// Shears whose de-sheared views are searched (with --quick only when the image as it is
    /// gives no face with an accepted estimate), comma-separated [default:
    /// 0.15,-0.15,0.3,-0.3,0.45,-0.45; with --quick 0.3,-0.3,0.5,-0.5, also the default of
    /// --locator filters].
    #[arg(
        help_heading = "Face search",
        hide_short_help = true,
        long,
        value_name = "K,...",
        value_delimiter = ',',
        allow_negative_numbers = true,
        conflicts_with = "no_shear_search"
    )]
    pub shear_hypotheses: Option<Vec<f64>>,
    /// Head rolls (degrees, positive: the head tilted clockwise on screen) whose turned views
    /// are searched, comma-separated [default: 12,-12,25,-25,45,-45; with --quick 12,-12, and
    /// only when no other view found a face].
    #[arg(help_heading = "Face search", hide_short_help = true, 
        long,
        value_name = "DEG,...",
        value_delimiter = ',',
        allow_negative_numbers = true,
        conflicts_with_all = ["no_shear_search", "no_roll_search"]
    )]
    pub roll_hypotheses: Option<Vec<f64>>,
    /// No turned views for rolled heads (the de-sheared views are still searched).
    #[arg(help_heading = "Face search", hide_short_help = true, long)]
    pub no_roll_search: bool,
    /// What makes k (stills): `auto` [default] the faces, with the scene's verticals read and
    /// reported beside them; `combine` combines the two when they agree (the faces decide when
    /// they do not); `scene` as combine, and corrects from the scene alone when no face gives k
    /// (a leaning structure would be "straightened" too); `faces` does not read the scene.
    #[arg(help_heading = "Face search", long, value_enum, value_name = "RULER")]
    pub ruler: Option<RulerArg>,
    /// What finds the faces: `network` (the built-in detector trained on sheared and rolled
    /// faces) or `viola-jones` (the paper's cascade; with --thorough in every view).
    ///
    /// `network`: the face proposal network over an image pyramid, each window judged by the
    /// landmark network, and again over the image de-sheared by the shear the faces measure
    /// when that is 0.1 or more (needs `--locator network`). `viola-jones`: the paper's
    /// cascade on the image as it is, and de-sheared and turned views only when it shows no
    /// trusted face; with --thorough in every view of every image, about 20 times slower than
    /// `network`
    /// (docs/performance.md) [default: network; viola-jones with --locator filters, --quick
    /// or --thorough].
    #[arg(
        help_heading = "Face search",
        long,
        value_enum,
        value_name = "DETECTOR"
    )]
    pub detector: Option<DetectorArg>,
    /// The Viola-Jones search in every de-sheared and turned view of every image, with the
    /// proposal windows added (implies --detector viola-jones): the most thorough and slowest.
    #[arg(help_heading = "Face search", long, conflicts_with = "quick")]
    pub thorough: bool,
    /// The Viola-Jones search in the image as it is, other views only when it shows no trusted
    /// face (the same as --detector viola-jones).
    #[arg(help_heading = "Face search", hide_short_help = true, long)]
    pub quick: bool,
    /// No face proposals: the thorough search takes candidate boxes from the cascade only,
    /// not also from the built-in window classifier trained on sheared faces (docs/how-it-works.md). --quick uses none anyway.
    #[arg(help_heading = "Face search", hide_short_help = true, long)]
    pub no_proposals: bool,
    /// Most crops the landmark network reads per face: fewer is faster and less accurate.
    ///
    /// Each crop is re-centred on the eyes found in the one before with their shear and roll removed (at least 1): fewer is faster, about
    /// one forward pass each, and less accurate (docs/performance.md) [default: 8
    /// for stills, stopping earlier when the estimate settles; 2 for `video`].
    #[arg(allow_negative_numbers = true, help_heading = "Correction", long, value_name = "N", value_parser = clap::value_parser!(u16).range(1..=64))]
    pub max_crops: Option<u16>,
    /// With --quick: search every de-sheared and turned view of every image anyway, not only
    /// when the views before gave no trusted face (the thorough search always does).
    #[arg(
        help_heading = "Face search",
        hide_short_help = true,
        long,
        conflicts_with = "no_shear_search",
        requires = "quick"
    )]
    pub search_every_view: bool,
    /// Also ask the built-in second cascade (OpenCV's frontalface_default) when the main one
    /// finds no face with an accepted estimate: more faces found, but the extra ones are hard
    /// and their estimates often wrong (docs/accuracy.md). Not with --cascade or
    /// --no-shear-search.
    #[arg(help_heading = "Face search", hide_short_help = true, long, conflicts_with_all = ["cascade", "no_shear_search"])]
    pub fallback_cascade: bool,
    /// Smallest face to look for, pixels wide (larger is faster).
    ///
    /// The detector's minimum box width and height, in pixels [default: 40 for the network
    /// detector; for viola-jones the cascade's window, 20 px, as OpenCV; `eval shear`: 1.5
    /// times --min-eye-distance]. Larger is faster: most of the detector's time goes to the
    /// smallest faces, and faces under about 60 px are too small to measure the shear well.
    #[arg(
        allow_negative_numbers = true,
        help_heading = "Face search",
        long,
        value_name = "PX"
    )]
    pub min_face: Option<u32>,
    /// The detector's minimum of merged raw hits for a face (OpenCV's `minNeighbors`): lower
    /// finds more faces and more false ones [default: 3, as OpenCV; the thorough search with
    /// the network asks for at most 1, as the network's face score rejects false boxes].
    #[arg(
        allow_negative_numbers = true,
        help_heading = "Face search",
        hide_short_help = true,
        long,
        value_name = "N"
    )]
    pub min_neighbors: Option<u32>,
    /// The detector's scale step (OpenCV's `scaleFactor`, 1.01 to 2): smaller finds more faces
    /// and takes longer [default: 1.1, as OpenCV].
    #[arg(
        allow_negative_numbers = true,
        help_heading = "Face search",
        hide_short_help = true,
        long,
        value_name = "F"
    )]
    pub scale_factor: Option<f64>,
    /// Worker threads [default: one per core].
    #[arg(allow_negative_numbers = true, help_heading = "Input and output", long, short = 'j', value_name = "N",
          value_parser = clap::value_parser!(u16).range(1..))]
    pub jobs: Option<u16>,
}

/// `--locator` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum LocatorArg {
    /// The landmark network.
    Network,
    /// The correlation filters (the paper's method).
    Filters,
}

impl From<LocatorArg> for unshear::pipeline::Locator {
    fn from(l: LocatorArg) -> Self {
        match l {
            LocatorArg::Network => Self::Network,
            LocatorArg::Filters => Self::Filters,
        }
    }
}

/// `--detector` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum DetectorArg {
    /// The built-in face detector network.
    Network,
    /// The Viola-Jones cascade (the paper's method).
    ViolaJones,
}

impl From<DetectorArg> for unshear::Detector {
    fn from(d: DetectorArg) -> Self {
        match d {
            DetectorArg::Network => Self::Network,
            DetectorArg::ViolaJones => Self::ViolaJones,
        }
    }
}

/// `--ruler` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum RulerArg {
    /// The faces alone.
    Faces,
    /// The faces, the scene's verticals reported beside them.
    Auto,
    /// The faces, combined with the scene's verticals when they agree.
    Combine,
    /// As combine, and the scene alone when no face gives k.
    Scene,
}

impl From<RulerArg> for unshear::Ruler {
    fn from(r: RulerArg) -> Self {
        match r {
            RulerArg::Faces => Self::Faces,
            RulerArg::Auto => Self::Auto,
            RulerArg::Combine => Self::Combine,
            RulerArg::Scene => Self::Scene,
        }
    }
}

/// `--shear-model` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ShearModelArg {
    /// The paper's equation 5.
    Equation5,
    /// Shear and roll from the eye line and the nose axis.
    ShearRoll,
    /// Shear and roll from the nose and mouth axes, yaw extrapolated out.
    ShearRollYaw,
}

impl From<ShearModelArg> for unshear::estimate::ShearModel {
    fn from(m: ShearModelArg) -> Self {
        match m {
            ShearModelArg::Equation5 => Self::Equation5,
            ShearModelArg::ShearRoll => Self::ShearRoll,
            ShearModelArg::ShearRollYaw => Self::ShearRollYaw,
        }
    }
}

/// `unshear estimate`.
#[derive(Debug, Args)]
pub struct EstimateArgs {
    /// Image files or folders (searched recursively for images).
    #[arg(required = true, value_name = "IN")]
    pub inputs: Vec<PathBuf>,
    /// Print one JSON object per input, one per line.
    #[arg(help_heading = "Input and output", long)]
    pub json: bool,
    /// Follow links to folders when walking folders (links to files are always followed).
    #[arg(help_heading = "Input and output", short = 'L', long = "follow")]
    pub follow: bool,
    /// Process only slice I of N of the inputs (0-based; the files sorted by path, cut into N
    /// contiguous slices), so that N processes share a batch with no coordinator. `auto`: I
    /// from $JOB_COMPLETION_INDEX (a Kubernetes Indexed Job), N from $JOB_COMPLETIONS;
    /// `auto/N`: N given.
    #[arg(help_heading = "Input and output", long, value_name = "I/N|auto", value_parser = parse_shard)]
    pub shard: Option<ShardArg>,
    #[command(flatten)]
    pub model: ModelArgs,
}

/// `unshear correct`.
#[derive(Debug, Args)]
pub struct CorrectArgs {
    /// Image files or folders (searched recursively for images).
    #[arg(required = true, value_name = "IN")]
    pub inputs: Vec<PathBuf>,
    /// Output file (one input only) [default: IN with `.unshear` before the extension].
    #[arg(
        help_heading = "Input and output",
        short = 'o',
        long = "output",
        value_name = "OUT",
        conflicts_with = "out_dir"
    )]
    pub output: Option<PathBuf>,
    /// Write outputs into this folder (created if needed), keeping file names and sub-folders.
    #[arg(help_heading = "Input and output", long, value_name = "DIR")]
    pub out_dir: Option<PathBuf>,
    /// Use this shear instead of estimating it.
    #[arg(
        help_heading = "Correction",
        long,
        value_name = "K",
        allow_negative_numbers = true
    )]
    pub k: Option<f64>,
    /// What to correct.
    #[arg(help_heading = "Correction", long, value_enum, default_value_t = RegionArg::Image)]
    pub region: RegionArg,
    /// Output size: the input's, expanded so nothing is cut off, or cropped to valid pixels.
    #[arg(help_heading = "Correction", long, value_enum, default_value_t = CanvasArg::Same)]
    pub canvas: CanvasArg,
    /// Row resampling.
    #[arg(help_heading = "Correction", long, value_enum, default_value_t = InterpArg::Linear)]
    pub interp: InterpArg,
    /// Also remove the motion blur along the rows (whole-image correction): its length is
    /// found from the zeros it leaves in the rows' spectrum, or given by --blur.
    #[arg(help_heading = "Correction", long)]
    pub deblur: bool,
    /// The motion blur's length in pixels, for --deblur (1 to 256).
    #[arg(
        help_heading = "Correction",
        long,
        value_name = "PX",
        requires = "deblur",
        value_parser = blur_px
    )]
    pub blur: Option<f64>,
    /// Also write a PNG showing the face box, eyes, nostrils and estimated face axis (one input).
    #[arg(help_heading = "Input and output", long, value_name = "PNG")]
    pub annotate: Option<PathBuf>,
    /// Print one JSON object per input, one per line.
    #[arg(help_heading = "Input and output", long)]
    pub json: bool,
    /// Replace existing output files (inputs are never overwritten).
    #[arg(help_heading = "Input and output", long)]
    pub force: bool,
    /// Follow links to folders when walking folders (links to files are always followed).
    #[arg(help_heading = "Input and output", short = 'L', long = "follow")]
    pub follow: bool,
    /// Process only slice I of N of the inputs (see `estimate --shard`).
    #[arg(
        help_heading = "Input and output",
        long,
        value_name = "I/N|auto",
        value_parser = parse_shard,
        conflicts_with_all = ["output", "annotate"]
    )]
    pub shard: Option<ShardArg>,
    #[command(flatten)]
    pub model: ModelArgs,
}

/// `unshear distort`.
#[derive(Debug, Args)]
pub struct DistortArgs {
    /// Input image.
    #[arg(value_name = "IN")]
    pub input: PathBuf,
    /// The shear to apply.
    #[arg(long, value_name = "K", allow_negative_numbers = true)]
    pub k: f64,
    /// Output image.
    #[arg(short = 'o', long = "output", value_name = "OUT")]
    pub output: PathBuf,
    /// Pivot row (the row that does not move) [default: the middle row, H/2].
    #[arg(long, value_name = "Y", allow_negative_numbers = true)]
    pub pivot: Option<f64>,
    /// Output size.
    #[arg(long, value_enum, default_value_t = CanvasArg::Same)]
    pub canvas: CanvasArg,
    /// Row resampling.
    #[arg(long, value_enum, default_value_t = InterpArg::Linear)]
    pub interp: InterpArg,
    /// Replace an existing output file.
    #[arg(long)]
    pub force: bool,
    /// Refuse images with more pixels than this.
    #[arg(allow_negative_numbers = true, long, value_name = "N", default_value_t = unshear::imageio::DEFAULT_MAX_PIXELS,
          value_parser = clap::value_parser!(u64).range(1..))]
    pub max_pixels: u64,
}

/// `unshear train`.
#[derive(Debug, Args)]
pub struct TrainArgs {
    /// Data-set folder with `ground_truth.txt` and `images/` (Caltech 10k Web Faces layout).
    #[arg(
        long,
        value_name = "DIR",
        default_value = "../shared/data/caltech-webfaces"
    )]
    pub data: PathBuf,
    /// Which faces to train on.
    #[arg(long, value_enum, value_name = "WHICH", default_value = "unmeasured")]
    pub faces: TrainFacesArg,
    /// Skip faces whose eye distance is below this many pixels.
    #[arg(allow_negative_numbers = true, long, value_name = "PX", default_value_t = unshear::dev::train::MIN_EYE_DISTANCE)]
    pub min_eye_distance: f64,
    /// Train on the faces as they are only, not also on their mirror images (the default adds
    /// them, as the built-in filters were trained).
    #[arg(long)]
    pub no_mirror: bool,
    /// Which filters to synthesise [default: mosse, the built-in default type].
    #[arg(long, value_enum, value_name = "TYPE")]
    pub filter_type: Option<FilterTypeArg>,
    /// Output filter file.
    #[arg(short = 'o', long = "output", value_name = "PATH")]
    pub output: PathBuf,
    /// Replace an existing output file.
    #[arg(long)]
    pub force: bool,
}

/// `unshear eval`.
#[derive(Debug, Args)]
pub struct EvalArgs {
    /// What to evaluate.
    #[command(subcommand)]
    pub what: EvalCommand,
}

/// The evaluations.
#[derive(Debug, Subcommand)]
pub enum EvalCommand {
    /// Shear estimation on annotated faces sheared synthetically, detection included.
    Shear(EvalShearArgs),
    /// Nostril and eye localisation against 68-point markup (dlib's example faces).
    Nostrils(EvalNostrilsArgs),
    /// Rank-1 recognition on undistorted, sheared and corrected probes (the paper's Table I).
    Recognition(EvalRecognitionArgs),
    /// Video on simulated rolling-shutter clips of development faces: k per frame, residual
    /// row offsets and the readout fraction found, against the simulator's truth.
    Video(EvalVideoArgs),
}

/// `unshear eval video`.
#[derive(Debug, Args)]
pub struct EvalVideoArgs {
    /// Data-set folder (Caltech 10k Web Faces layout): the scenes' photos.
    #[arg(
        long,
        value_name = "DIR",
        default_value = "../shared/data/caltech-webfaces"
    )]
    pub data: PathBuf,
    /// Readout fractions to simulate, comma-separated.
    #[arg(long, value_name = "RHO,...", value_delimiter = ',', default_values_t = [0.5, 0.8, 1.0])]
    pub rho: Vec<f64>,
    /// Motions to simulate, comma-separated: constant, pause, accelerate, shaky, walk.
    #[arg(
        long,
        value_name = "MOTION,...",
        value_delimiter = ',',
        default_value = "constant,pause,accelerate,shaky"
    )]
    pub motion: Vec<String>,
    /// Peak shear at the middle row (each clip's peak speed is K * H / rho px per frame).
    #[arg(long, value_name = "K", default_value_t = 0.3)]
    pub peak_k: f64,
    /// Exposure in milliseconds (motion blur of speed x exposure).
    #[arg(long, value_name = "MS", default_value_t = 4.0)]
    pub exposure_ms: f64,
    /// Clips per (motion, readout) setting, each over other development faces.
    #[arg(long, value_name = "N", default_value_t = 2)]
    pub clips: usize,
    /// Photos joined into each clip's panorama.
    #[arg(long, value_name = "N", default_value_t = 6)]
    pub faces_per_clip: usize,
    /// Frames per clip.
    #[arg(long, value_name = "N", default_value_t = 90)]
    pub frames: u32,
    /// Frames at the start of each clip not scored.
    #[arg(long, value_name = "N", default_value_t = 30)]
    pub skip: usize,
    /// Frame width, pixels.
    #[arg(long, value_name = "PX", default_value_t = 1280)]
    pub width: u32,
    /// Frame height, pixels.
    #[arg(long, value_name = "PX", default_value_t = 720)]
    pub height: u32,
    /// Frames per second.
    #[arg(long, value_name = "FPS", default_value_t = 30.0)]
    pub fps: f64,
    /// Sensor noise, grey levels.
    #[arg(long, value_name = "SIGMA", default_value_t = 2.0)]
    pub noise: f64,
    /// Seed of the face choice, the noise and the shake.
    #[arg(long, value_name = "N", default_value_t = 1)]
    pub seed: u64,
    /// How each clip is run, comma-separated: calibrated (the default two passes over a file),
    /// one-pass (as on a pipe), given (the true readout), faces (--no-motion).
    #[arg(
        long,
        value_name = "MODE,...",
        value_delimiter = ',',
        default_value = "calibrated,one-pass,given,faces"
    )]
    pub modes: Vec<String>,
    /// Also write one JSON line per clip and mode to this file.
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
    #[command(flatten)]
    pub model: ModelArgs,
}

/// `unshear eval shear`.
#[derive(Debug, Args)]
pub struct EvalShearArgs {
    /// Data-set folder (Caltech 10k Web Faces layout).
    #[arg(
        long,
        value_name = "DIR",
        default_value = "../shared/data/caltech-webfaces"
    )]
    pub data: PathBuf,
    /// Shears to apply, comma-separated.
    #[arg(long, value_name = "K,...", value_delimiter = ',', allow_negative_numbers = true,
          default_values_t = [0.0, -0.14, 0.14, -0.20, 0.20, -0.33, 0.33, -0.40, 0.40])]
    pub k: Vec<f64>,
    /// Only faces whose eye distance is at least this many pixels.
    #[arg(
        allow_negative_numbers = true,
        long,
        value_name = "PX",
        default_value_t = 40.0
    )]
    pub min_eye_distance: f64,
    /// Which annotated faces to measure.
    #[arg(long, value_enum, value_name = "WHICH", default_value_t = EvalFaces::Measured)]
    pub faces: EvalFaces,
    /// Use at most this many faces (the first, in data-set order).
    #[arg(allow_negative_numbers = true, long, value_name = "N")]
    pub limit: Option<usize>,
    /// Also write every sample as CSV here.
    #[arg(long, value_name = "FILE")]
    pub csv: Option<PathBuf>,
    /// Write samples.csv, samples.json, unmatched.csv (reported faces that match no annotated
    /// face), summary.md and PNG plots into this folder.
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Crop each image to this many nominal face boxes around its annotated faces before
    /// shearing (speed; 0: shear the whole image).
    #[arg(allow_negative_numbers = true, long, value_name = "F", default_value_t = unshear::dev::eval::shear::DEFAULT_CONTEXT)]
    pub context: f64,
    /// Also run each whole photo once with its annotated faces painted over, and count the
    /// photos where a face is still reported and accepted (false faces, or faces the
    /// annotations leave out).
    #[arg(long)]
    pub face_free: bool,
    /// Faces the data set's annotations leave out, checked by eye, in its annotation format
    /// (`assets/eval/webfaces-unannotated.txt` for the Caltech development photos): they are
    /// not evaluated, but are painted over with `--face-free` and count as real faces, not
    /// unmatched detections.
    #[arg(long, value_name = "FILE")]
    pub unannotated: Option<PathBuf>,
    /// Turn each photo by this many degrees (clockwise positive, about its centre) before
    /// shearing it, to measure rolled heads.
    #[arg(
        long,
        value_name = "DEG",
        default_value_t = 0.0,
        allow_negative_numbers = true
    )]
    pub roll: f64,
    /// What the pipeline is given of each sheared photo: `crop`, the rectangle a camera
    /// delivers (only the columns every row covers; faces it cuts are counted apart, not as
    /// missed); `expand`, a canvas widened so nothing is cut, whose empty corners slant by k
    /// (the paper's setting).
    #[arg(long, value_enum, value_name = "CANVAS", default_value_t = EvalCanvasArg::Crop)]
    pub canvas: EvalCanvasArg,
    /// Make each frame as a panning camera would beyond one shear: the pan's speed changing
    /// during the readout (the rows' offsets bend), a 2% vertical drift, motion blur along the
    /// rows, sensor noise and JPEG; each face is scored against the shear at its eyes' row
    /// (the `--camera-*` options set the camera; docs/accuracy.md).
    #[arg(long)]
    pub camera: bool,
    /// With `--camera`: the readout's share of the frame interval.
    #[arg(long, value_name = "RHO", default_value_t = 0.8)]
    pub camera_readout: f64,
    /// With `--camera`: the pan's relative change of speed per frame interval.
    #[arg(
        long,
        value_name = "A",
        default_value_t = 0.5,
        allow_negative_numbers = true
    )]
    pub camera_acceleration: f64,
    /// With `--camera`: the exposure in frame intervals (0.12: 1/250 s at 30 frames/s).
    #[arg(long, value_name = "E", default_value_t = 0.12)]
    pub camera_exposure: f64,
    /// With `--camera`: the sensor noise's standard deviation, grey levels.
    #[arg(long, value_name = "SIGMA", default_value_t = 2.0)]
    pub camera_noise: f64,
    /// With `--camera`: the JPEG quality of each frame (0: none).
    #[arg(long, value_name = "Q", default_value_t = 85)]
    pub camera_jpeg: u8,
    /// Look for a motion blur along each frame's rows and remove it before the pipeline reads
    /// the frame, as `correct --deblur` finds and removes it.
    #[arg(long)]
    pub deblur: bool,
    #[command(flatten)]
    pub model: ModelArgs,
}

/// `eval shear --canvas`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum EvalCanvasArg {
    /// The rectangle a camera delivers: no empty pixel.
    Crop,
    /// Widened so nothing is cut, empty corners and all.
    Expand,
}

/// `unshear eval nostrils`.
#[derive(Debug, Args)]
pub struct EvalNostrilsArgs {
    /// dlib/imglab landmark XML files (68 points per face).
    #[arg(
        long,
        value_name = "XML",
        default_values = [
            "../shared/data/dlib-example-faces/examples/faces/training_with_face_landmarks.xml",
            "../shared/data/dlib-example-faces/examples/faces/testing_with_face_landmarks.xml",
        ]
    )]
    pub xml: Vec<PathBuf>,
    /// Enlarge each image by this factor before detection (the example faces are tiny).
    #[arg(
        allow_negative_numbers = true,
        long,
        value_name = "F",
        default_value_t = 1.0
    )]
    pub upscale: f64,
    #[command(flatten)]
    pub model: ModelArgs,
}

/// `unshear eval recognition`.
#[derive(Debug, Args)]
pub struct EvalRecognitionArgs {
    /// Data-set folder: `identity.txt` + `images/` (CelebA), or `images/subjectNN.cond.*` (Yale).
    #[arg(long, value_name = "DIR", default_value = "../shared/data/yale-faces")]
    pub data: PathBuf,
    /// Shears applied to the probes, comma-separated.
    #[arg(long, value_name = "K,...", value_delimiter = ',', allow_negative_numbers = true,
          default_values_t = [0.14, 0.20, 0.33, 0.40])]
    pub k: Vec<f64>,
    /// Gallery images per identity (the first by file name); the rest are probes.
    #[arg(
        allow_negative_numbers = true,
        long,
        value_name = "N",
        default_value_t = 3
    )]
    pub gallery: usize,
    /// Pool the Gabor magnitudes on a GRID x GRID grid (2: 96 features, the paper's G96).
    #[arg(
        allow_negative_numbers = true,
        long,
        value_name = "GRID",
        default_value_t = 2
    )]
    pub grid: usize,
    #[command(flatten)]
    pub model: ModelArgs,
}

/// `unshear video`.
#[derive(Debug, Args)]
#[command(next_help_heading = "Video")]
pub struct VideoArgs {
    /// Input: a video file (MP4, MOV, MKV, WebM... through ffmpeg), a .y4m file, `-` for a
    /// y4m stream on stdin, or a folder of numbered frames.
    #[arg(value_name = "IN", help_heading = "Arguments")]
    pub input: PathBuf,
    /// Output: a video file (.mp4, .mov, .mkv, .webm...: encoded by ffmpeg, with the input's
    /// sound, subtitles, rotation and colour tags), `-` for y4m on stdout, a .y4m file, or a
    /// folder for numbered frames [default: none, analysis only].
    #[arg(short = 'o', long = "output", value_name = "OUT")]
    pub output: Option<PathBuf>,
    /// The ffmpeg program for video files (ffprobe is looked for beside it) [default: ffmpeg
    /// on PATH].
    #[arg(long, value_name = "PATH")]
    pub ffmpeg: Option<PathBuf>,
    /// Stop, with an error, when ffmpeg or ffprobe keeps unshear waiting this long for a frame,
    /// for room for one, or for its end: a stuck child fails the run instead of holding it
    /// (0: wait forever).
    #[arg(
        allow_negative_numbers = true,
        long,
        value_name = "SECONDS",
        default_value_t = crate::ffmpeg::DEFAULT_TIMEOUT_SECS
    )]
    pub ffmpeg_timeout: u64,
    /// Video encoder of a video-file output, as ffmpeg names it (libx264, libx265,
    /// libvpx-vp9, libsvtav1...) [default: the input's codec where possible, else libx264,
    /// libx265 above 8 bits, libvpx-vp9 for .webm].
    #[arg(long, value_name = "ENCODER")]
    pub codec: Option<String>,
    /// Constant quality of a video-file output (lower is better) [default: 18 for libx264, 20
    /// for libx265, 30 for VP9 and AV1].
    #[arg(allow_negative_numbers = true, long, value_name = "N")]
    pub crf: Option<f64>,
    /// Speed preset of the video encoder, passed to ffmpeg as -preset (libx264 and libx265:
    /// ultrafast ... veryslow; libsvtav1: 0-13) [default: the encoder's, medium for x264 and
    /// x265].
    #[arg(long, value_name = "NAME")]
    pub preset: Option<String>,
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
    /// Full face detection every N frames (faces are tracked in between) [default: 5 with
    /// the network detector, so that a face entering the frame is found within 5 frames; 30
    /// with viola-jones].
    #[arg(allow_negative_numbers = true, long, value_name = "N")]
    pub redetect: Option<u64>,
    /// While no face is tracked, full detection every N frames.
    #[arg(
        allow_negative_numbers = true,
        long,
        value_name = "N",
        default_value_t = 5
    )]
    pub lost_interval: u64,
    /// Full detection on the frame shrunk to at most this width (0: full size; smallest face
    /// found: about 24 * width / PX pixels with the network detector, 20 * width / PX with
    /// viola-jones).
    #[arg(
        allow_negative_numbers = true,
        long,
        value_name = "PX",
        default_value_t = 640
    )]
    pub detect_width: u32,
    /// Smooth k over this many later frames (a fixed-lag smoother): each frame is corrected
    /// once N more frames have been estimated, so output lags input by N frames (0: the causal
    /// filter, no delay).
    #[arg(allow_negative_numbers = true, long, value_name = "N", default_value_t = unshear::video::DEFAULT_SMOOTHING_LAG)]
    pub smoothing_lag: usize,
    /// Without a face, hold the filtered k for this many seconds...
    #[arg(
        allow_negative_numbers = true,
        long,
        value_name = "SECONDS",
        default_value_t = 0.5
    )]
    pub hold: f64,
    /// ...then let it decay to 0 with this time constant.
    #[arg(
        allow_negative_numbers = true,
        long,
        value_name = "SECONDS",
        default_value_t = 1.0
    )]
    pub decay: f64,
    /// Frame rate of a frame folder (y4m streams carry their own).
    #[arg(
        allow_negative_numbers = true,
        long,
        value_name = "FPS",
        default_value_t = 25.0
    )]
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
    /// The camera's readout fraction: its sensor's readout time over the frame interval, in
    /// (0, 1.2] [default: calibrated on the clip from its faces].
    ///
    /// Each frame's shear is then the image motion measured between frames times the line
    /// time, k = RHO * v / H. From a data sheet, or an earlier `unshear calibrate`.
    #[arg(
        help_heading = "Rolling-shutter model",
        long,
        value_name = "RHO",
        value_parser = readout_fraction,
        conflicts_with = "readout_ms"
    )]
    pub readout_fraction: Option<f64>,
    /// The camera's readout time in milliseconds (the readout fraction is MS * fps / 1000).
    #[arg(
        help_heading = "Rolling-shutter model",
        long,
        value_name = "MS",
        value_parser = positive_f64
    )]
    pub readout_ms: Option<f64>,
    /// Take every frame's shear from the faces alone, not from the measured motion.
    #[arg(help_heading = "Rolling-shutter model", long)]
    pub no_motion: bool,
    /// Also undo the vertical stretch of vertical motion (rows resampled).
    #[arg(help_heading = "Rolling-shutter model", long)]
    pub vertical: bool,
    /// `image`: the whole frame (a panning camera); `face`: each face with its own k, from its
    /// own motion once the readout is known (a subject moving in front of a still camera), the
    /// rest untouched.
    #[arg(help_heading = "Rolling-shutter model", long, value_enum, default_value_t = RegionArg::Image)]
    pub region: RegionArg,
    /// Calibrate the readout while correcting, in one pass over the input, even when it is a
    /// file that can be read twice (by default a file is read twice: the readout calibrated
    /// over the whole clip first, then every frame corrected with it).
    #[arg(help_heading = "Rolling-shutter model", long)]
    pub one_pass: bool,
    /// In one pass (a pipe, or --one-pass), while the readout is being calibrated, hold back
    /// up to N frames (in memory) so that they too are corrected from motion once it is known.
    #[arg(
        help_heading = "Rolling-shutter model",
        long,
        value_name = "N",
        default_value_t = unshear::video::DEFAULT_CALIBRATION_WINDOW
    )]
    pub calibration_window: usize,
    /// Remove the motion blur along the rows of the frames corrected from motion: each row is
    /// smeared by its image velocity times the exposure (--exposure, --exposure-ms, or by
    /// default estimated over the clip from the blur itself).
    #[arg(help_heading = "Motion blur", long)]
    pub deblur: bool,
    /// Each row's exposure as a fraction of the frame interval, in (0, 1] (for --deblur).
    #[arg(
        help_heading = "Motion blur",
        long,
        value_name = "FRACTION",
        value_parser = exposure_fraction,
        conflicts_with = "exposure_ms"
    )]
    pub exposure: Option<f64>,
    /// Each row's exposure in milliseconds (for --deblur; 4 is 1/250 s).
    #[arg(
        help_heading = "Motion blur",
        long,
        value_name = "MS",
        value_parser = positive_f64
    )]
    pub exposure_ms: Option<f64>,
    /// The deblurring's noise-to-signal ratio: larger is smoother and rings less, smaller
    /// restores more detail and more noise.
    #[arg(
        help_heading = "Motion blur",
        long,
        value_name = "RATIO",
        value_parser = positive_f64,
        default_value_t = unshear::deblur::DEFAULT_NOISE_TO_SIGNAL
    )]
    pub deblur_noise: f64,
    #[command(flatten)]
    pub model: ModelArgs,
}

fn blur_px(s: &str) -> Result<f64, String> {
    let v: f64 = s.parse().map_err(|e| format!("{e}"))?;
    if (unshear::deblur::MIN_BLUR..=unshear::deblur::MAX_BLUR).contains(&v) {
        Ok(v)
    } else {
        Err(format!(
            "a blur of {v} px is outside [{}, {}]",
            unshear::deblur::MIN_BLUR,
            unshear::deblur::MAX_BLUR
        ))
    }
}

fn exposure_fraction(s: &str) -> Result<f64, String> {
    let v: f64 = s.parse().map_err(|e| format!("{e}"))?;
    unshear::video::Deblur::new(v)
        .map(|_| v)
        .map_err(|e| e.to_string())
}

/// `unshear calibrate`.
#[derive(Debug, Args)]
pub struct CalibrateArgs {
    /// Input: a video file (through ffmpeg), a y4m file, `-` (y4m on stdin), or a folder of
    /// numbered frames.
    #[arg(value_name = "CLIP", help_heading = "Arguments")]
    pub input: PathBuf,
    /// Print the result as one JSON object.
    #[arg(long)]
    pub json: bool,
    /// Frame rate of a frame folder (y4m streams and video files carry their own).
    #[arg(long, value_name = "FPS", default_value_t = 25.0)]
    pub fps: f64,
    /// The FFmpeg program (and the ffprobe beside it) [default: on PATH].
    #[arg(long, value_name = "PATH")]
    pub ffmpeg: Option<PathBuf>,
    /// Longest wait on ffmpeg or ffprobe before it is stopped as stuck (0: no limit).
    #[arg(long, value_name = "SECONDS", default_value_t = crate::ffmpeg::DEFAULT_TIMEOUT_SECS)]
    pub ffmpeg_timeout: u64,
    #[command(flatten)]
    pub model: ModelArgs,
}

/// A readout fraction in (0, 1.2].
fn readout_fraction(s: &str) -> Result<f64, String> {
    let v: f64 = s.parse().map_err(|e| format!("{e}"))?;
    unshear::video::check_readout_fraction(v).map_err(|e| e.to_string())
}

/// A finite number above 0.
fn positive_f64(s: &str) -> Result<f64, String> {
    let v: f64 = s.parse().map_err(|e| format!("{e}"))?;
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(format!("{s} is not a positive number"))
    }
}

/// `eval shear --faces`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum EvalFaces {
    /// The faces the accuracy tables measure: every face with eyes --min-eye-distance apart or
    /// more.
    Measured,
    /// Faces to fit models of the pipeline's estimates on (the confidence models, the filters' yaw
    /// factors): those the landmark network and the filters were never trained on (held out by
    /// the network's trainer, or too small), with eyes --min-eye-distance apart or more, in
    /// photos whose faces all have eyes under 40 px apart (none of which the accuracy tables
    /// measure).
    Unseen,
}

/// `train --faces`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum TrainFacesArg {
    /// The faces the landmark network trains on (as the built-in filters were trained): in
    /// photos whose faces all have eyes under 40 px apart, less those its trainer holds out, so
    /// that no face `eval shear` measures or fits the confidence models on is trained on.
    /// Expects the Caltech set whole.
    Unmeasured,
    /// Every face of the data set.
    All,
}

impl From<TrainFacesArg> for unshear::dev::train::TrainFaces {
    fn from(a: TrainFacesArg) -> Self {
        match a {
            TrainFacesArg::Unmeasured => Self::Unmeasured,
            TrainFacesArg::All => Self::All,
        }
    }
}

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

/// `--filter-type`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum FilterTypeArg {
    /// UMACE (the paper's): whitened average of centred features.
    Umace,
    /// ASEF: average of exact filters mapping each crop to a Gaussian peak at its feature.
    Asef,
    /// MOSSE: least-squares filter mapping all crops to Gaussian peaks at their features.
    Mosse,
}

impl From<FilterTypeArg> for unshear::filters::FilterType {
    fn from(t: FilterTypeArg) -> Self {
        match t {
            FilterTypeArg::Umace => Self::Umace,
            FilterTypeArg::Asef => Self::Asef,
            FilterTypeArg::Mosse => Self::Mosse,
        }
    }
}

/// `--region`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum RegionArg {
    /// The whole image, one shear.
    Image,
    /// Each face region with its own shear.
    Face,
}

/// `--canvas`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum CanvasArg {
    /// The input's size.
    Same,
    /// Large enough that nothing is cut off.
    Expand,
    /// The largest rectangle holding only valid pixels.
    Crop,
}

/// `--interp`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum InterpArg {
    /// Two-tap linear.
    Linear,
    /// Four-tap Catmull-Rom cubic.
    Cubic,
}

impl From<RegionArg> for unshear::pipeline::Region {
    fn from(r: RegionArg) -> Self {
        match r {
            RegionArg::Image => Self::Image,
            RegionArg::Face => Self::Face,
        }
    }
}

impl From<CanvasArg> for unshear::warp::Canvas {
    fn from(c: CanvasArg) -> Self {
        match c {
            CanvasArg::Same => Self::Same,
            CanvasArg::Expand => Self::Expand,
            CanvasArg::Crop => Self::Crop,
        }
    }
}

impl From<InterpArg> for unshear::warp::Interpolation {
    fn from(i: InterpArg) -> Self {
        match i {
            InterpArg::Linear => Self::Linear,
            InterpArg::Cubic => Self::Cubic,
        }
    }
}

/// `--shard`: which slice of the inputs this process handles.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ShardArg {
    /// Slice `index` of `count` (`I/N`).
    Fixed {
        /// 0-based, below `count`.
        index: usize,
        /// At least 1.
        count: usize,
    },
    /// The index from `$JOB_COMPLETION_INDEX`; the count given (`auto/N`) or from
    /// `$JOB_COMPLETIONS` (`auto`).
    Auto {
        /// `N` of `auto/N`.
        count: Option<usize>,
    },
}

/// The variable a Kubernetes Indexed Job sets to each pod's index.
pub const SHARD_INDEX_VAR: &str = "JOB_COMPLETION_INDEX";
/// The variable `--shard auto` reads the number of shards from (set it to the Job's
/// `completions`).
pub const SHARD_COUNT_VAR: &str = "JOB_COMPLETIONS";

fn parse_count(s: &str) -> Result<usize, String> {
    match s.trim().parse::<usize>() {
        Ok(n) if n >= 1 => Ok(n),
        _ => Err(format!(
            "the number of shards must be a whole number from 1, got {s:?}"
        )),
    }
}

fn parse_shard(s: &str) -> Result<ShardArg, String> {
    if s == "auto" {
        return Ok(ShardArg::Auto { count: None });
    }
    let Some((i, n)) = s.split_once('/') else {
        return Err(format!(
            "expected I/N (e.g. 0/4), auto or auto/N, got {s:?}"
        ));
    };
    let count = parse_count(n)?;
    if i == "auto" {
        return Ok(ShardArg::Auto { count: Some(count) });
    }
    let index = parse_index(i, count)?;
    Ok(ShardArg::Fixed { index, count })
}

fn parse_index(i: &str, count: usize) -> Result<usize, String> {
    match i.trim().parse::<usize>() {
        Ok(index) if index < count => Ok(index),
        _ => Err(format!(
            "the shard index must be a whole number from 0 to {}, got {i:?}",
            count - 1
        )),
    }
}

impl ShardArg {
    /// `(index, count)`, reading the environment (through `var`) for `auto`.
    pub fn resolve(self, var: impl Fn(&str) -> Option<String>) -> Result<(usize, usize), String> {
        let (index, count) = match self {
            ShardArg::Fixed { index, count } => return Ok((index, count)),
            ShardArg::Auto { count } => (var(SHARD_INDEX_VAR), count),
        };
        let count = match count {
            Some(n) => n,
            None => {
                let n = var(SHARD_COUNT_VAR).ok_or_else(|| {
                    format!("--shard auto needs ${SHARD_COUNT_VAR} (or use --shard auto/N)")
                })?;
                parse_count(&n).map_err(|e| format!("${SHARD_COUNT_VAR}: {e}"))?
            }
        };
        let index = index.ok_or_else(|| format!("--shard auto needs ${SHARD_INDEX_VAR}"))?;
        let index = parse_index(&index, count).map_err(|e| format!("${SHARD_INDEX_VAR}: {e}"))?;
        Ok((index, count))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The `--filter-type` help names the default type; it must be the library's.
    #[test]
    fn filter_type_help_names_the_library_default() {
        let named = FilterTypeArg::Mosse;
        assert_eq!(
            unshear::filters::FilterType::from(named),
            unshear::filters::FilterType::DEFAULT
        );
    }

    /// The hypotheses' help names the library's defaults (the help text is static, so it must
    /// be kept in step by hand).
    #[test]
    fn hypotheses_help_names_the_library_defaults() {
        use clap::CommandFactory;
        let help = Cli::command()
            .find_subcommand_mut("estimate")
            .expect("the estimate subcommand")
            .render_long_help()
            .to_string()
            .split_whitespace()
            .collect::<Vec<_>>()
            .join(" ");
        let shown = |values: &[f64]| {
            let shown: Vec<String> = values.iter().map(|v| v.to_string()).collect();
            shown.join(",")
        };
        for expected in [
            format!(
                "[default: {}; with --quick {},",
                shown(&unshear::pipeline::THOROUGH_SHEAR_HYPOTHESES),
                shown(&unshear::pipeline::DEFAULT_SHEAR_HYPOTHESES)
            ),
            format!(
                "[default: {}; with --quick {},",
                shown(&unshear::pipeline::THOROUGH_ROLL_HYPOTHESES),
                shown(&unshear::pipeline::DEFAULT_ROLL_HYPOTHESES)
            ),
        ] {
            assert!(help.contains(&expected), "{expected} not in: {help}");
        }
    }

    #[test]
    fn shard_forms_parse_and_resolve() {
        let env = |pairs: &'static [(&'static str, &'static str)]| {
            move |name: &str| {
                pairs
                    .iter()
                    .find(|(k, _)| *k == name)
                    .map(|(_, v)| v.to_string())
            }
        };
        let none = env(&[]);
        assert_eq!(
            parse_shard("2/4"),
            Ok(ShardArg::Fixed { index: 2, count: 4 })
        );
        assert_eq!(parse_shard("2/4").and_then(|s| s.resolve(none)), Ok((2, 4)));
        assert_eq!(parse_shard("auto"), Ok(ShardArg::Auto { count: None }));
        assert_eq!(parse_shard("auto/3"), Ok(ShardArg::Auto { count: Some(3) }));
        for bad in ["4/4", "-1/4", "1/0", "1", "a/b", "1/4/5", "", "auto/0"] {
            assert!(parse_shard(bad).is_err(), "{bad:?} accepted");
        }
        let k8s = env(&[("JOB_COMPLETION_INDEX", "1"), ("JOB_COMPLETIONS", "3")]);
        assert_eq!(ShardArg::Auto { count: None }.resolve(k8s), Ok((1, 3)));
        assert_eq!(ShardArg::Auto { count: Some(5) }.resolve(k8s), Ok((1, 5)));
        assert!(ShardArg::Auto { count: None }.resolve(none).is_err());
        assert!(ShardArg::Auto { count: Some(2) }.resolve(none).is_err());
        let out_of_range = env(&[("JOB_COMPLETION_INDEX", "3"), ("JOB_COMPLETIONS", "3")]);
        assert!(ShardArg::Auto { count: None }
            .resolve(out_of_range)
            .is_err());
    }
}

//! Containers (MP4, MOV, MKV, WebM...) through the `ffmpeg` and `ffprobe` programs: what they
//! are asked to do, and what `ffprobe` answers. Nothing here starts a process ([`super`] does).
//!
//! * **Probe**: [`probe_args`] asks `ffprobe` for JSON about the input's streams; [`Probe::parse`]
//!   reads the video stream (size, pixel format, frame count and rate, rotation, colour tags)
//!   and the audio and subtitle streams to carry over.
//! * **Decode**: [`decode_args`] turns the first video stream into a y4m pipe at its own bit
//!   depth ([`y4m_target`]), every decoded frame exactly once (`-fps_mode passthrough`) or, for
//!   a clip whose rate really varies, at a constant rate ([`Probe::timing`]), in its
//!   stored orientation (`-noautorotate`: rolling shutter shears along the sensor's rows, which
//!   are the stored rows), stopping with an error at a corrupt packet (`-xerror`).
//! * **Encode**: [`EncodePlan::new`] writes the corrected y4m pipe into a container with the
//!   source's audio and subtitle streams copied (or converted where the container cannot hold
//!   them), its global metadata and chapters, its rotation and colour tags, a default codec for
//!   the container ([`default_codec`]) and quality ([`default_crf`]).
//!
//! An `ffmpeg` without `-display_rotation` (5.1 has none; 7.0 has it) cannot set the rotation of
//! a stream it encodes (only `-metadata
//! rotate=` on a stream copy does); the plan then asks for a second, stream-copy pass
//! ([`EncodePlan::remux_args`]).

use std::collections::BTreeSet;
use std::ffi::OsString;
use std::path::Path;

use serde::Deserialize;

use unshear::{Error, Result};

fn video_err(msg: impl Into<String>) -> Error {
    Error::Video(msg.into())
}

/// What the installed `ffmpeg` can do, from `ffmpeg -h long` and `ffmpeg -encoders`.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Capabilities {
    /// `-fps_mode` is known (5.1 and later); otherwise the older `-vsync`.
    pub fps_mode: bool,
    /// `-display_rotation` is known (7.0 has it, 5.1 not): the rotation is set in the encoding
    /// pass.
    pub display_rotation: bool,
    /// Names of the encoders built in (`libx264`, `aac`...).
    pub encoders: BTreeSet<String>,
}

impl Capabilities {
    /// Reads the output of `ffmpeg -hide_banner -h long` and `ffmpeg -hide_banner -encoders`.
    pub fn parse(help: &str, encoders: &str) -> Self {
        let has_option = |name: &str| help.lines().any(|l| l.starts_with(name));
        // Encoder lines: " V....D libx264   description"; the legend lines have "=".
        let encoders = encoders
            .lines()
            .filter_map(|l| {
                let mut words = l.split_whitespace();
                let flags = words.next()?;
                let name = words.next()?;
                let is_entry = flags.len() == 6
                    && flags.starts_with(['V', 'A', 'S'])
                    && name != "="
                    && !flags.contains('=');
                is_entry.then(|| name.to_string())
            })
            .collect();
        Self {
            fps_mode: has_option("-fps_mode"),
            display_rotation: has_option("-display_rotation"),
            encoders,
        }
    }

    /// Whether `name` is an encoder of this `ffmpeg` (true when the list is unknown).
    pub fn has_encoder(&self, name: &str) -> bool {
        self.encoders.is_empty() || self.encoders.contains(name)
    }
}

/// One audio or subtitle stream of the input.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Stream {
    /// Index among all the input's streams (`-map 0:INDEX`).
    pub index: u32,
    /// Codec name as `ffprobe` gives it (`aac`, `mov_text`, `subrip`...).
    pub codec: String,
}

/// Colour tags of the video stream, as `ffprobe` names them (`None` when unknown).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ColorTags {
    /// `tv` (limited) or `pc` (full).
    pub range: Option<String>,
    /// Matrix (`bt709`, `bt2020nc`...).
    pub space: Option<String>,
    /// Transfer (`bt709`, `smpte2084` for PQ, `arib-std-b67` for HLG...).
    pub transfer: Option<String>,
    /// Primaries (`bt709`, `bt2020`...).
    pub primaries: Option<String>,
    /// Chroma siting (`left`, `center`, `topleft`...).
    pub chroma_location: Option<String>,
}

/// The video stream that is corrected.
#[derive(Debug, Clone, PartialEq)]
pub struct VideoStream {
    /// Index among all the input's streams.
    pub index: u32,
    /// Codec name (`h264`, `hevc`...).
    pub codec: String,
    /// Stored width and height (before any rotation for display).
    pub width: u32,
    /// Stored height.
    pub height: u32,
    /// Pixel format (`yuv420p`, `yuv420p10le`...).
    pub pix_fmt: Option<String>,
    /// Frame count from the container's index (`nb_frames`), when it has one.
    pub frames: Option<u64>,
    /// Average frame rate (frames over duration), as a fraction.
    pub avg_frame_rate: Option<(u32, u32)>,
    /// The stream's nominal rate (FFmpeg's guess of the rate all timestamps fit), as a
    /// fraction.
    pub r_frame_rate: Option<(u32, u32)>,
    /// Duration in seconds.
    pub duration: Option<f64>,
    /// Seconds from the container's start (its earliest stream's) to this stream's first
    /// frame: 0.5 for a clip whose picture starts half a second after its sound (TS files,
    /// recorders, edits). The decoder's frames start at the picture, so the encoder's pipe is
    /// shifted by this much to keep them in step with the sound.
    pub start_offset: f64,
    /// Counter-clockwise rotation for display, degrees, in `(-180, 180]` (0 without one): the
    /// display matrix's, else the `rotate` tag's.
    pub rotation: i32,
    /// Colour tags.
    pub color: ColorTags,
}

/// What `ffprobe` says about an input.
#[derive(Debug, Clone, PartialEq)]
pub struct Probe {
    /// Container name(s) (`mov,mp4,m4a,3gp,3g2,mj2`, `matroska,webm`...).
    pub format_name: String,
    /// Container duration in seconds.
    pub duration: Option<f64>,
    /// The first video stream that is not a cover picture.
    pub video: VideoStream,
    /// Audio streams, in order.
    pub audio: Vec<Stream>,
    /// Subtitle streams, in order.
    pub subtitles: Vec<Stream>,
}

#[derive(Deserialize)]
struct RawProbe {
    #[serde(default)]
    streams: Vec<RawStream>,
    format: Option<RawFormat>,
}

#[derive(Deserialize)]
struct RawFormat {
    format_name: Option<String>,
    duration: Option<String>,
    start_time: Option<String>,
}

#[derive(Deserialize, Default)]
struct RawDisposition {
    #[serde(default)]
    attached_pic: u8,
}

#[derive(Deserialize)]
struct RawSideData {
    side_data_type: Option<String>,
    rotation: Option<f64>,
}

#[derive(Deserialize)]
struct RawStream {
    index: u32,
    codec_type: Option<String>,
    codec_name: Option<String>,
    width: Option<u32>,
    height: Option<u32>,
    pix_fmt: Option<String>,
    nb_frames: Option<String>,
    start_time: Option<String>,
    avg_frame_rate: Option<String>,
    r_frame_rate: Option<String>,
    duration: Option<String>,
    color_range: Option<String>,
    color_space: Option<String>,
    color_transfer: Option<String>,
    color_primaries: Option<String>,
    chroma_location: Option<String>,
    #[serde(default)]
    disposition: Option<RawDisposition>,
    #[serde(default)]
    tags: std::collections::BTreeMap<String, String>,
    #[serde(default)]
    side_data_list: Vec<RawSideData>,
}

/// `"30000/1001"` as a fraction; `None` for `0/0` and other degenerate rates.
fn parse_rate(s: &str) -> Option<(u32, u32)> {
    let (n, d) = s.split_once('/')?;
    let (n, d) = (n.trim().parse().ok()?, d.trim().parse().ok()?);
    (n > 0 && d > 0).then_some((n, d))
}

/// A tag value, without FFmpeg's placeholders for "not known".
fn known(v: Option<String>) -> Option<String> {
    v.filter(|s| !s.is_empty() && s != "unknown" && s != "reserved" && s != "unspecified")
}

/// An angle in degrees brought to `(-180, 180]` and rounded to whole degrees.
pub fn normalize_rotation(degrees: f64) -> i32 {
    if !degrees.is_finite() {
        return 0;
    }
    let r = (degrees.round() as i64).rem_euclid(360) as i32;
    if r > 180 {
        r - 360
    } else {
        r
    }
}

impl Probe {
    /// Reads `ffprobe -print_format json -show_format -show_streams` output.
    ///
    /// # Errors
    /// [`Error::Video`] when the JSON is malformed or the input has no video stream.
    pub fn parse(json: &[u8]) -> Result<Self> {
        let raw: RawProbe = serde_json::from_slice(json)
            .map_err(|e| video_err(format!("unreadable ffprobe output: {e}")))?;
        let kind = |s: &RawStream, k: &str| s.codec_type.as_deref() == Some(k);
        let stream = |s: &RawStream| Stream {
            index: s.index,
            codec: s.codec_name.clone().unwrap_or_default(),
        };
        let audio = raw
            .streams
            .iter()
            .filter(|s| kind(s, "audio"))
            .map(stream)
            .collect();
        let subtitles = raw
            .streams
            .iter()
            .filter(|s| kind(s, "subtitle"))
            .map(stream)
            .collect();
        let v = raw
            .streams
            .into_iter()
            .find(|s| {
                kind(s, "video") && s.disposition.as_ref().is_none_or(|d| d.attached_pic == 0)
            })
            .ok_or_else(|| video_err("the input has no video stream"))?;
        let (width, height) = match (v.width, v.height) {
            (Some(w), Some(h)) if w > 0 && h > 0 => (w, h),
            _ => return Err(video_err("the video stream has no frame size")),
        };
        let matrix = v
            .side_data_list
            .iter()
            .filter(|d| d.side_data_type.as_deref() == Some("Display Matrix"))
            .find_map(|d| d.rotation);
        // The old `rotate` tag holds the same counter-clockwise angle as ffprobe's rotation of
        // the display matrix (checked with FFmpeg 5.1: tag 270 reads back as -90).
        let tag = v
            .tags
            .get("rotate")
            .and_then(|t| t.trim().parse::<f64>().ok());
        let rotation = normalize_rotation(matrix.or(tag).unwrap_or(0.0));
        let format = raw.format;
        let seconds = |t: Option<&String>| t.and_then(|t| t.parse::<f64>().ok());
        let container_start = seconds(format.as_ref().and_then(|f| f.start_time.as_ref()));
        let start_offset = match (seconds(v.start_time.as_ref()), container_start) {
            (Some(v), Some(c)) if (v - c).is_finite() => (v - c).max(0.0),
            _ => 0.0,
        };
        Ok(Self {
            format_name: format
                .as_ref()
                .and_then(|f| f.format_name.clone())
                .unwrap_or_default(),
            duration: format.and_then(|f| f.duration).and_then(|d| d.parse().ok()),
            video: VideoStream {
                index: v.index,
                codec: v.codec_name.unwrap_or_default(),
                width,
                height,
                pix_fmt: known(v.pix_fmt),
                frames: v.nb_frames.and_then(|n| n.parse().ok()).filter(|&n| n > 0),
                avg_frame_rate: v.avg_frame_rate.as_deref().and_then(parse_rate),
                r_frame_rate: v.r_frame_rate.as_deref().and_then(parse_rate),
                duration: v.duration.and_then(|d| d.parse().ok()),
                start_offset,
                rotation,
                color: ColorTags {
                    range: known(v.color_range),
                    space: known(v.color_space),
                    transfer: known(v.color_transfer),
                    primaries: known(v.color_primaries),
                    chroma_location: known(v.chroma_location),
                },
            },
            audio,
            subtitles,
        })
    }

    /// The number of frames to expect: the container's count, else (and for a clip decoded
    /// at a constant rate) duration times rate (for a progress bar; the real count may
    /// differ).
    pub fn expected_frames(&self) -> Option<u64> {
        let v = &self.video;
        let from_duration = |rate: (u32, u32)| {
            let seconds = v.duration.or(self.duration)?;
            let frames = (seconds * as_f64(rate)).round();
            (frames.is_finite() && frames >= 1.0).then_some(frames as u64)
        };
        match self.timing() {
            Timing::Constant(rate) => from_duration(rate).or(v.frames),
            Timing::Passthrough(rate) => v.frames.or_else(|| from_duration(rate)),
            Timing::Unknown => v.frames,
        }
    }
}

/// How decoded frames are timed in the y4m pipe, which has one rate for all frames.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Timing {
    /// Every decoded frame once, the output at this rate (the average): for clips whose rate
    /// is steady, so that the frame count is kept exactly and timing moves by jitter only.
    Passthrough((u32, u32)),
    /// Frames repeated or dropped by the decoder to this constant rate (the nominal one), for
    /// clips whose rate really varies (a phone slowing down in low light), so that picture and
    /// sound stay in step.
    Constant((u32, u32)),
    /// No usable rate is known: every frame once, at the y4m stream's own rate.
    Unknown,
}

impl Timing {
    /// The rate of the y4m pipe, when known.
    pub fn rate(self) -> Option<(u32, u32)> {
        match self {
            Timing::Passthrough(r) | Timing::Constant(r) => Some(r),
            Timing::Unknown => None,
        }
    }
}

fn as_f64((n, d): (u32, u32)) -> f64 {
    f64::from(n) / f64::from(d)
}

impl Probe {
    /// How to time the frames: [`Timing::Passthrough`] when the average rate is within 0.5% of
    /// the nominal one (or no nominal rate is known), [`Timing::Constant`] at the nominal rate
    /// otherwise, or at the average when the nominal rate is implausible (more than twice the
    /// average, or above 240).
    pub fn timing(&self) -> Timing {
        let v = &self.video;
        match (v.avg_frame_rate, v.r_frame_rate) {
            (Some(avg), Some(nominal)) => {
                let (a, r) = (as_f64(avg), as_f64(nominal));
                if (a - r).abs() <= 0.005 * r {
                    Timing::Passthrough(avg)
                } else if r > 2.0 * a || r > 240.0 {
                    Timing::Constant(avg)
                } else {
                    Timing::Constant(nominal)
                }
            }
            (Some(avg), None) => Timing::Passthrough(avg),
            (None, Some(nominal)) if as_f64(nominal) <= 240.0 => Timing::Passthrough(nominal),
            _ => Timing::Unknown,
        }
    }
}

/// `ffprobe`'s arguments for [`Probe::parse`].
pub fn probe_args(input: &Path) -> Vec<OsString> {
    let mut args: Vec<OsString> = [
        "-v",
        "error",
        "-print_format",
        "json",
        "-show_format",
        "-show_streams",
    ]
    .map(OsString::from)
    .to_vec();
    args.push(input.as_os_str().to_owned());
    args
}

/// The y4m layout a decoded stream is piped in.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Y4mTarget {
    /// FFmpeg pixel format asked for (`yuv420p`, `yuvj420p`, `yuv420p10le`...).
    pub pix_fmt: String,
    /// Bits per sample of that format.
    pub bit_depth: u32,
    /// Whether the source's samples do not fit it unchanged (more than 12 bits, or a chroma
    /// layout y4m lacks): the conversion then loses or resamples something.
    pub converts: bool,
}

/// The y4m layout for a source pixel format: the same one when y4m and this crate support it
/// (full range stays `yuvj*`, so nothing is rescaled), otherwise the nearest at no lower depth
/// (10 or 12 bits; 16-bit sources are cut to 12), 4:4:4 for RGB sources.
pub fn y4m_target(pix_fmt: Option<&str>) -> Y4mTarget {
    const DIRECT: [(&str, u32); 14] = [
        ("yuv420p", 8),
        ("yuvj420p", 8),
        ("yuv422p", 8),
        ("yuvj422p", 8),
        ("yuv444p", 8),
        ("yuvj444p", 8),
        ("gray", 8),
        ("yuv420p10le", 10),
        ("yuv422p10le", 10),
        ("yuv444p10le", 10),
        ("yuv420p12le", 12),
        ("yuv422p12le", 12),
        ("yuv444p12le", 12),
        ("gray12le", 12),
    ];
    let name = pix_fmt.unwrap_or("yuv420p");
    if let Some(&(n, depth)) = DIRECT.iter().find(|(n, _)| *n == name) {
        return Y4mTarget {
            pix_fmt: n.to_string(),
            bit_depth: depth,
            converts: false,
        };
    }
    // The depth: the number before the endianness (`yuv420p10le`, `gray12be`), or the
    // semi-planar and packed formats' own names (`p010le`, `rgb48le`); otherwise 8 (`nv12`).
    let depth = if let Some(d) = name
        .strip_prefix('p')
        .filter(|_| name.starts_with("p01") || name.starts_with("p21") || name.starts_with("p41"))
    {
        d.get(1..3)
            .and_then(|d| d.parse::<u32>().ok())
            .unwrap_or(10)
    } else if ["rgb48", "bgr48", "rgba64", "bgra64"]
        .iter()
        .any(|p| name.starts_with(p))
    {
        16
    } else if name.starts_with("y210") {
        10
    } else {
        let stem = name
            .strip_suffix("le")
            .or_else(|| name.strip_suffix("be"))
            .unwrap_or("");
        let digits = &stem[stem.trim_end_matches(|c: char| c.is_ascii_digit()).len()..];
        digits
            .parse::<u32>()
            .ok()
            .filter(|d| (9..=16).contains(d))
            .unwrap_or(8)
    };
    let rgb = [
        "rgb", "bgr", "gbr", "argb", "abgr", "0rgb", "0bgr", "x2rgb", "x2bgr",
    ]
    .iter()
    .any(|p| name.starts_with(p));
    let layout = if name.starts_with("gray") || name.starts_with("ya") {
        "gray"
    } else if rgb || name.contains("444") || name.contains("411") || name.contains("410") {
        "444"
    } else if name.contains("422")
        || name.contains("440")
        || name.starts_with("yuyv")
        || name.starts_with("uyvy")
        || name.starts_with("yvyu")
        || name.starts_with("nv16")
        || name.starts_with("nv20")
        || name.starts_with("y210")
        || name.starts_with("p21")
    {
        "422"
    } else {
        "420"
    };
    let (pix_fmt, bit_depth) = match (layout, depth) {
        ("gray", d) if d <= 8 => ("gray".to_string(), 8),
        ("gray", _) => ("gray12le".to_string(), 12),
        (l, d) if d <= 8 => (format!("yuv{l}p"), 8),
        (l, d) if d <= 10 => (format!("yuv{l}p10le"), 10),
        (l, _) => (format!("yuv{l}p12le"), 12),
    };
    let converts = depth > 12
        || rgb
        || ["411", "410", "440"].iter().any(|l| name.contains(l))
        || (layout == "gray" && depth > 8 && depth != 12);
    Y4mTarget {
        pix_fmt,
        bit_depth,
        converts,
    }
}

/// The start of every `ffmpeg` command line: no banner, no keyboard, errors only.
fn quiet() -> Vec<OsString> {
    ["-hide_banner", "-nostdin", "-loglevel", "error"]
        .map(OsString::from)
        .to_vec()
}

fn push(args: &mut Vec<OsString>, items: &[&str]) {
    args.extend(items.iter().map(OsString::from));
}

/// `ffmpeg`'s arguments to decode `input`'s video stream into a y4m stream on stdout (see the
/// module docs).
pub fn decode_args(
    input: &Path,
    probe: &Probe,
    target: &Y4mTarget,
    caps: &Capabilities,
) -> Vec<OsString> {
    let mut args = quiet();
    push(&mut args, &["-xerror", "-noautorotate", "-i"]);
    args.push(input.as_os_str().to_owned());
    let map = format!("0:{}", probe.video.index);
    push(&mut args, &["-map", &map, "-an", "-sn", "-dn"]);
    let mode = if caps.fps_mode { "-fps_mode" } else { "-vsync" };
    match probe.timing() {
        Timing::Constant((n, d)) => push(&mut args, &[mode, "cfr", "-r", &format!("{n}/{d}")]),
        _ => push(&mut args, &[mode, "passthrough"]),
    }
    push(
        &mut args,
        &[
            "-pix_fmt",
            &target.pix_fmt,
            "-strict",
            "-1",
            "-f",
            "yuv4mpegpipe",
            "-",
        ],
    );
    args
}

/// A container, told by the output's extension.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Container {
    /// `.mp4`, `.m4v`.
    Mp4,
    /// `.mov` (QuickTime).
    Mov,
    /// `.mkv` (Matroska).
    Mkv,
    /// `.webm`.
    WebM,
    /// `.ts`, `.m2ts`, `.mts` (MPEG transport stream: broadcast, AVCHD cameras).
    Ts,
    /// `.m4v`, `.3gp`, `.3g2`: MP4's relatives for players and phones, whose muxers take
    /// H.264 and AAC but little else.
    Mobile,
    /// Any other extension: FFmpeg's own defaults for it.
    Other,
}

impl Container {
    /// The container of a file name (case-insensitive extension).
    pub fn of(path: &Path) -> Self {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .unwrap_or_default()
            .to_ascii_lowercase();
        match ext.as_str() {
            "mp4" => Self::Mp4,
            "mov" | "qt" => Self::Mov,
            "mkv" => Self::Mkv,
            "webm" => Self::WebM,
            "ts" | "m2ts" | "mts" => Self::Ts,
            "m4v" | "3gp" | "3g2" => Self::Mobile,
            _ => Self::Other,
        }
    }

    /// Whether the container stores a display rotation (the MP4 family does).
    pub fn keeps_rotation(self) -> bool {
        self.is_mp4_family()
    }

    /// MP4, MOV and their relatives (`.m4v`, `.3gp`): ISO media files, written by FFmpeg's
    /// MOV muxers (display matrix, `mov_text` subtitles, `hvc1` tags).
    fn is_mp4_family(self) -> bool {
        matches!(self, Self::Mp4 | Self::Mov | Self::Mobile)
    }

    /// Whether it can hold video coded as `codec` (an `ffprobe` codec name), as FFmpeg 5.1's
    /// muxers write it (its MOV muxer refuses VP9 and AV1: "only supported in MP4"). Other
    /// containers get FFmpeg's default codec for them, which they are sure to hold.
    fn takes_video(self, codec: &str) -> bool {
        match self {
            Self::Mp4 => matches!(codec, "h264" | "hevc" | "av1" | "vp9" | "mpeg4"),
            Self::Mov => matches!(codec, "h264" | "hevc" | "prores" | "mpeg4" | "mjpeg"),
            Self::WebM => matches!(codec, "vp8" | "vp9" | "av1"),
            Self::Ts => matches!(codec, "h264" | "hevc" | "mpeg2video"),
            Self::Mobile => codec == "h264",
            Self::Mkv => true,
            Self::Other => false,
        }
    }
}

/// The encoders for a codec, best first.
fn encoders_for(codec: &str) -> &'static [&'static str] {
    match codec {
        "h264" => &["libx264"],
        "hevc" => &["libx265"],
        "vp9" => &["libvpx-vp9"],
        "vp8" => &["libvpx"],
        "av1" => &["libsvtav1", "libaom-av1"],
        "prores" => &["prores_ks"],
        "mpeg4" => &["mpeg4"],
        "mjpeg" => &["mjpeg"],
        "mpeg2video" => &["mpeg2video"],
        // Lossless codecs: re-encoded losslessly, as they came.
        "ffv1" => &["ffv1"],
        "utvideo" => &["utvideo"],
        "huffyuv" => &["huffyuv"],
        "ffvhuff" => &["ffvhuff"],
        "magicyuv" => &["magicyuv"],
        _ => &[],
    }
}

/// Encoders known to take frames of any size in every chroma layout (checked with FFmpeg 5.1
/// on 641x361 4:2:0). The others (`libx264`, `libx265`, `libsvtav1`, `utvideo`, `huffyuv`,
/// `ffvhuff`, hardware encoders, and FFmpeg's unnamed default) are taken to need an even
/// width for 4:2:0 and 4:2:2 and an even height for 4:2:0.
const ANY_SIZE_ENCODERS: &[&str] = &[
    "ffv1",
    "libvpx",
    "libvpx-vp9",
    "libaom-av1",
    "mpeg4",
    "mpeg2video",
    "prores_ks",
    "prores",
    "mjpeg",
    "magicyuv",
    "rawvideo",
];

/// The size `encoder` (`None`: FFmpeg's default for the container) is given frames of
/// `width` x `height` in `chroma` at: `None` when it takes that size as it is; otherwise the
/// width (4:2:0, 4:2:2) and height (4:2:0) rounded up to even, which encoders of subsampled
/// chroma such as `libx264` need (their chroma planes cover two luma columns and rows). The
/// chroma planes already cover the padded size (y4m rounds their size up); the luma plane is
/// padded by repeating its last column and row ([`pad_luma`]).
pub fn even_size(
    encoder: Option<&str>,
    width: u32,
    height: u32,
    chroma: unshear::video::Chroma,
) -> Option<(u32, u32)> {
    if encoder.is_some_and(|e| ANY_SIZE_ENCODERS.contains(&e)) {
        return None;
    }
    let (hs, vs) = chroma.subsampling();
    let even = |v: u32, sub: u32| if sub == 2 { v + v % 2 } else { v };
    let size = (even(width, hs), even(height, vs));
    (size != (width, height)).then_some(size)
}

/// `frame` with its luma plane grown to `width` x `height` by repeating its last column and
/// row (see [`even_size`]); the chroma planes are kept as they are.
pub fn pad_luma<T: unshear::video::YuvSample>(
    frame: &mut unshear::video::YuvFrame<T>,
    width: u32,
    height: u32,
) {
    let (w, h) = frame.y.dimensions();
    if (w, h) == (width, height) || w == 0 || h == 0 {
        return;
    }
    let y = &frame.y;
    let padded = unshear::video::Plane::from_fn(width, height, |x, r| {
        *y.get_pixel(x.min(w - 1), r.min(h - 1))
    });
    frame.y = padded;
}

/// A y4m header line with its `W` and `H` fields set to `width` and `height`.
pub fn resize_header(header: &[u8], width: u32, height: u32) -> Vec<u8> {
    let body = header.strip_suffix(b"\n").unwrap_or(header);
    let fields: Vec<Vec<u8>> = body
        .split(|&b| b == b' ')
        .enumerate()
        .map(|(i, f)| match f.first() {
            Some(b'W') if i > 0 => format!("W{width}").into_bytes(),
            Some(b'H') if i > 0 => format!("H{height}").into_bytes(),
            _ => f.to_vec(),
        })
        .collect();
    let mut out = fields.join(&b' ');
    out.push(b'\n');
    out
}

/// The video encoder used when `--codec` is not given: the source's own codec where this
/// `ffmpeg` encodes it and the container holds it; otherwise H.264 (`libx264`) for 8-bit and
/// H.265 (`libx265`) above 8 bits in MP4, MOV and MKV, VP9 in WebM; `None` for other
/// containers (FFmpeg's default for them).
pub fn default_codec(
    container: Container,
    source_codec: Option<&str>,
    bit_depth: u32,
    caps: &Capabilities,
) -> Option<String> {
    if let Some(codec) = source_codec.filter(|c| container.takes_video(c)) {
        if let Some(e) = encoders_for(codec).iter().find(|e| caps.has_encoder(e)) {
            return Some((*e).to_string());
        }
    }
    let wanted: &[&str] = match container {
        Container::Mp4 | Container::Mov | Container::Mkv if bit_depth > 8 => {
            &["libx265", "libx264"]
        }
        Container::Mp4 | Container::Mov | Container::Mkv => &["libx264", "libx265"],
        Container::Mobile => &["libx264"],
        Container::WebM => &["libvpx-vp9", "libsvtav1", "libaom-av1"],
        Container::Ts | Container::Other => &[],
    };
    wanted
        .iter()
        .find(|e| caps.has_encoder(e))
        .map(|e| (*e).to_string())
}

/// The default constant-quality setting of an encoder (x264 18 and x265 20, well below their own
/// defaults of 23 and 28 because the output stands in for the original; 30 for VP9 and AV1),
/// `None` for encoders without one.
pub fn default_crf(encoder: &str) -> Option<f64> {
    match encoder {
        "libx264" => Some(18.0),
        "libx265" => Some(20.0),
        "libvpx-vp9" | "libsvtav1" | "libaom-av1" => Some(30.0),
        _ => None,
    }
}

/// What happens to one audio or subtitle stream of the source.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum StreamAction {
    /// Copied as it is.
    Copy,
    /// Re-encoded with this encoder (the container cannot hold the source's codec).
    Convert(String),
    /// Re-encoded with FFmpeg's default encoder for the container (one unshear does not know
    /// the codecs of).
    ConvertToDefault,
    /// Left out (the container holds nothing like it), with the reason.
    Drop(String),
}

fn audio_action(container: Container, codec: &str) -> StreamAction {
    if codec.is_empty() || codec == "none" {
        // A codec FFmpeg does not know cannot be muxed, copied or converted.
        return StreamAction::Drop("ffmpeg does not know its codec".into());
    }
    let copy = match container {
        Container::Mp4 => matches!(
            codec,
            "aac" | "mp3" | "ac3" | "eac3" | "alac" | "opus" | "mp2"
        ),
        // FFmpeg 5.1's MOV muxer refuses Opus ("only supported in MP4").
        Container::Mov => {
            matches!(codec, "aac" | "mp3" | "ac3" | "eac3" | "alac" | "mp2")
                || codec.starts_with("pcm_")
        }
        Container::WebM => matches!(codec, "opus" | "vorbis"),
        Container::Ts => matches!(codec, "aac" | "mp3" | "mp2" | "ac3" | "eac3" | "opus"),
        Container::Mobile => codec == "aac",
        Container::Mkv => true,
        Container::Other => false,
    };
    match (copy, container) {
        (true, _) => StreamAction::Copy,
        (false, Container::WebM) => StreamAction::Convert("libopus".into()),
        (false, Container::Ts | Container::Other) => StreamAction::ConvertToDefault,
        (false, _) => StreamAction::Convert("aac".into()),
    }
}

fn subtitle_action(container: Container, codec: &str) -> StreamAction {
    let text = matches!(
        codec,
        "subrip" | "srt" | "ass" | "ssa" | "webvtt" | "mov_text" | "text"
    );
    let drop = || StreamAction::Drop(format!("{container:?} cannot hold {codec} subtitles"));
    match container {
        c if c.is_mp4_family() && codec == "mov_text" => StreamAction::Copy,
        c if c.is_mp4_family() && text => StreamAction::Convert("mov_text".into()),
        Container::WebM if codec == "webvtt" => StreamAction::Copy,
        Container::WebM if text => StreamAction::Convert("webvtt".into()),
        Container::Mkv if codec == "mov_text" => StreamAction::Convert("srt".into()),
        Container::Mkv => StreamAction::Copy,
        _ => drop(),
    }
}

/// Settings of the encoding pass that the user may give.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct EncodeSettings {
    /// The video encoder (`--codec`); [`default_codec`] otherwise.
    pub codec: Option<String>,
    /// Constant quality (`--crf`); [`default_crf`] otherwise.
    pub crf: Option<f64>,
    /// The encoder's speed preset (`--preset`: `veryfast`, `slow`... for x264 and x265, a
    /// number for SVT-AV1), passed as `-preset`; the encoder's default otherwise.
    pub preset: Option<String>,
}

/// The encoding pass: the corrected y4m pipe (stdin) and the source's other streams into a
/// container file.
#[derive(Debug, Clone, PartialEq)]
pub struct EncodePlan {
    /// `ffmpeg`'s arguments.
    pub args: Vec<OsString>,
    /// The video encoder (`None`: FFmpeg's default for the container).
    pub codec: Option<String>,
    /// The constant quality passed, if any.
    pub crf: Option<f64>,
    /// The speed preset passed, if any.
    pub preset: Option<String>,
    /// Each source audio stream and what happens to it.
    pub audio: Vec<(Stream, StreamAction)>,
    /// Each source subtitle stream and what happens to it.
    pub subtitles: Vec<(Stream, StreamAction)>,
    /// The rotation still to be set by a stream-copy pass ([`Self::remux_args`]), for an
    /// `ffmpeg` without `-display_rotation`.
    pub remux_rotation: Option<i32>,
    /// The source's rotation that this container cannot store.
    pub rotation_lost: Option<i32>,
}

impl EncodePlan {
    /// The plan for writing `output` (its extension decides the container) from a y4m stream
    /// of `bit_depth` on stdin and, when the frames came from a container, that `source` file
    /// and its probe.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for a `--crf` that is not a finite number `>= 0`.
    pub fn new(
        output: &Path,
        bit_depth: u32,
        source: Option<(&Path, &Probe)>,
        settings: &EncodeSettings,
        caps: &Capabilities,
    ) -> Result<Self> {
        if let Some(crf) = settings.crf {
            if !(crf.is_finite() && crf >= 0.0) {
                return Err(Error::InvalidArgument(format!(
                    "constant quality {crf}: a number >= 0 is needed"
                )));
            }
        }
        let container = Container::of(output);
        let probe = source.map(|(_, p)| p);
        let codec = settings.codec.clone().or_else(|| {
            default_codec(
                container,
                probe.map(|p| p.video.codec.as_str()),
                bit_depth,
                caps,
            )
        });
        let crf = settings
            .crf
            .or_else(|| codec.as_deref().and_then(default_crf));
        let rotation = probe.map_or(0, |p| p.video.rotation);
        let keeps_rotation = rotation != 0 && container.keeps_rotation();

        let mut args = quiet();
        args.push("-y".into());
        // The pipe: its rotation set here when this ffmpeg can (autorotation off, or it would
        // turn the pixels instead), its rate the one the decoder was given (`Probe::timing`),
        // so that the duration holds when a source was piped frame by frame.
        if keeps_rotation && caps.display_rotation {
            push(
                &mut args,
                &["-noautorotate", "-display_rotation", &rotation.to_string()],
            );
        }
        if let Some((n, d)) = probe.and_then(|p| p.timing().rate()) {
            push(&mut args, &["-r", &format!("{n}/{d}")]);
        }
        push(&mut args, &["-f", "yuv4mpegpipe", "-i", "-"]);
        if let Some((path, _)) = source {
            args.push("-i".into());
            args.push(path.as_os_str().to_owned());
        }
        push(&mut args, &["-map", "0:v:0"]);

        let mut audio = Vec::new();
        let mut subtitles = Vec::new();
        // Output stream numbers per type, for per-stream codec options.
        let (mut na, mut ns) = (0usize, 0usize);
        if let Some(p) = probe {
            for s in &p.audio {
                let action = audio_action(container, &s.codec);
                if map_stream(&mut args, 'a', na, s, &action) {
                    na += 1;
                }
                audio.push((s.clone(), action));
            }
            for s in &p.subtitles {
                let action = subtitle_action(container, &s.codec);
                if map_stream(&mut args, 's', ns, s, &action) {
                    ns += 1;
                }
                subtitles.push((s.clone(), action));
            }
            // Global metadata (creation time, location...) and chapters of the source, not of
            // the pipe.
            push(&mut args, &["-map_metadata", "1", "-map_chapters", "1"]);
        }

        // A picture that starts after the sound: the pipe's frames start at 0, so they are
        // moved to the picture's place, to within a frame (the encoder's time base is the
        // frame rate's; `-itsoffset` would be lost to the pipe's `-r`). Frames decoded at a
        // constant rate need none: the decoder filled the gap with copies of the first frame.
        if let Some(p) = probe.filter(|p| !matches!(p.timing(), Timing::Constant(_))) {
            if p.video.start_offset >= MIN_START_OFFSET {
                let shift = format!("setpts=PTS+{:.6}/TB", p.video.start_offset);
                push(&mut args, &["-filter:v", &shift]);
            }
        }
        if let Some(c) = &codec {
            push(&mut args, &["-c:v", c]);
            if let Some(q) = crf {
                push(&mut args, &["-crf", &format_number(q)]);
                if matches!(c.as_str(), "libvpx-vp9" | "libaom-av1") {
                    // Constant quality for these needs the bitrate cap off.
                    push(&mut args, &["-b:v", "0"]);
                }
            }
            if let Some(p) = &settings.preset {
                push(&mut args, &["-preset", p]);
            }
            match c.as_str() {
                // x265 prints its settings on stderr whatever FFmpeg's log level.
                "libx265" => push(&mut args, &["-x265-params", "log-level=error"]),
                "libaom-av1" => push(&mut args, &["-cpu-used", "6", "-row-mt", "1"]),
                _ => {}
            }
            // Apple's players want HEVC tagged hvc1 in MP4 and MOV.
            if c == "libx265" && container.is_mp4_family() {
                push(&mut args, &["-tag:v", "hvc1"]);
            }
        }
        if let Some(p) = probe {
            let c = &p.video.color;
            for (option, value) in [
                ("-color_range", &c.range),
                ("-colorspace", &c.space),
                ("-color_trc", &c.transfer),
                ("-color_primaries", &c.primaries),
                ("-chroma_sample_location", &c.chroma_location),
            ] {
                // An RGB source's matrix (`gbr`) does not describe the YUV frames it was
                // converted to, and the encoders' option refuses it.
                let rgb = option == "-colorspace" && value.as_deref() == Some("gbr");
                if let Some(v) = value.as_ref().filter(|_| !rgb) {
                    push(&mut args, &[option, v]);
                }
            }
        }
        args.push(output.as_os_str().to_owned());
        Ok(Self {
            args,
            codec,
            crf,
            preset: settings.preset.clone(),
            audio,
            subtitles,
            remux_rotation: (keeps_rotation && !caps.display_rotation).then_some(rotation),
            rotation_lost: (rotation != 0 && !container.keeps_rotation()).then_some(rotation),
        })
    }

    /// `ffmpeg`'s arguments for the stream-copy pass that sets [`Self::remux_rotation`]:
    /// every stream of `encoded` copied into `output`, the video stream tagged with the
    /// rotation (which the MP4 muxer writes as the display matrix).
    pub fn remux_args(encoded: &Path, output: &Path, rotation: i32) -> Vec<OsString> {
        let mut args = quiet();
        args.push("-y".into());
        args.push("-i".into());
        args.push(encoded.as_os_str().to_owned());
        push(
            &mut args,
            &[
                "-map",
                "0",
                "-c",
                "copy",
                "-metadata:s:v:0",
                &format!("rotate={}", rotation.rem_euclid(360)),
            ],
        );
        args.push(output.as_os_str().to_owned());
        args
    }
}

/// Adds to `args` the mapping of the source's stream `s` (input 1) as output stream `n` of
/// its `kind` (`a`, `s`) with `action`'s codec; `false` when the action leaves it out.
fn map_stream(
    args: &mut Vec<OsString>,
    kind: char,
    n: usize,
    s: &Stream,
    action: &StreamAction,
) -> bool {
    let codec = match action {
        StreamAction::Copy => Some("copy"),
        StreamAction::Convert(e) => Some(e.as_str()),
        StreamAction::ConvertToDefault => None,
        StreamAction::Drop(_) => return false,
    };
    push(args, &["-map", &format!("1:{}", s.index)]);
    if let Some(codec) = codec {
        push(args, &[&format!("-c:{kind}:{n}"), codec]);
    }
    true
}

/// The smallest start offset ([`VideoStream::start_offset`]) the encoder is given, seconds:
/// below a millisecond it is the containers' rounding, not a picture starting late.
const MIN_START_OFFSET: f64 = 1e-3;

/// A number without a needless fraction (`18`, `20.5`).
fn format_number(v: f64) -> String {
    if v.fract() == 0.0 && v.abs() < 1e9 {
        format!("{}", v as i64)
    } else {
        format!("{v}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const PROBE: &str = r#"{
        "streams": [
            {"index": 0, "codec_type": "video", "codec_name": "hevc", "width": 1920,
             "height": 1080, "pix_fmt": "yuv420p10le", "nb_frames": "300",
             "avg_frame_rate": "30000/1001", "r_frame_rate": "30000/1001",
             "duration": "10.01", "color_range": "tv",
             "color_space": "bt2020nc", "color_transfer": "arib-std-b67",
             "color_primaries": "bt2020", "chroma_location": "left",
             "tags": {"rotate": "90"},
             "side_data_list": [{"side_data_type": "Display Matrix", "rotation": -90}]},
            {"index": 1, "codec_type": "audio", "codec_name": "aac"},
            {"index": 2, "codec_type": "data", "codec_name": "none"},
            {"index": 6, "codec_type": "audio"},
            {"index": 3, "codec_type": "subtitle", "codec_name": "subrip"},
            {"index": 4, "codec_type": "subtitle", "codec_name": "hdmv_pgs_subtitle"},
            {"index": 5, "codec_type": "video", "codec_name": "mjpeg", "width": 64,
             "height": 64, "disposition": {"attached_pic": 1}}
        ],
        "format": {"format_name": "mov,mp4,m4a,3gp,3g2,mj2", "duration": "10.05"}
    }"#;

    fn caps(display_rotation: bool) -> Capabilities {
        Capabilities {
            fps_mode: true,
            display_rotation,
            encoders: [
                "libx264",
                "libx265",
                "libvpx-vp9",
                "aac",
                "libopus",
                "mov_text",
            ]
            .map(String::from)
            .into(),
        }
    }

    fn strings(args: &[OsString]) -> Vec<String> {
        args.iter()
            .map(|a| a.to_string_lossy().into_owned())
            .collect()
    }

    #[test]
    fn probe_reads_a_phone_clip() {
        let p = Probe::parse(PROBE.as_bytes()).expect("valid JSON");
        assert_eq!(p.video.index, 0);
        assert_eq!((p.video.width, p.video.height), (1920, 1080));
        assert_eq!(
            p.video.rotation, -90,
            "the display matrix wins over the tag"
        );
        assert_eq!(p.video.frames, Some(300));
        assert_eq!(p.expected_frames(), Some(300));
        assert_eq!(p.video.avg_frame_rate, Some((30000, 1001)));
        assert_eq!(p.video.color.transfer.as_deref(), Some("arib-std-b67"));
        assert_eq!(
            p.audio,
            [
                Stream {
                    index: 1,
                    codec: "aac".into()
                },
                Stream {
                    index: 6,
                    codec: String::new()
                }
            ]
        );
        assert_eq!(p.subtitles.len(), 2);
        assert!(Probe::parse(b"{\"streams\": []}").is_err());
        assert!(Probe::parse(b"not json").is_err());
        // Without nb_frames (Matroska): duration times rate.
        let mkv = PROBE.replace("\"nb_frames\": \"300\",", "");
        let p = Probe::parse(mkv.as_bytes()).expect("valid JSON");
        assert_eq!(p.expected_frames(), Some(300));
    }

    #[test]
    fn a_picture_starting_after_the_sound_is_moved_to_its_place() {
        let late = PROBE
            .replace(
                "\"duration\": \"10.01\"",
                "\"duration\": \"10.01\", \"start_time\": \"1.723\"",
            )
            .replace(
                "\"duration\": \"10.05\"",
                "\"duration\": \"10.05\", \"start_time\": \"1.4\"",
            );
        let p = Probe::parse(late.as_bytes()).expect("valid JSON");
        assert!((p.video.start_offset - 0.323).abs() < 1e-9);
        let args = |p: &Probe, source: bool| {
            let plan = EncodePlan::new(
                Path::new("o.mp4"),
                10,
                source.then_some((Path::new("in.mp4"), p)),
                &EncodeSettings::default(),
                &caps(true),
            )
            .expect("plan");
            strings(&plan.args).join(" ")
        };
        assert!(args(&p, true).contains("-filter:v setpts=PTS+0.323000/TB"));
        // Nothing to keep in step with without the source's streams; nothing to move when the
        // picture starts first, or at a constant rate (the decoder filled the gap).
        let first = Probe::parse(PROBE.as_bytes()).expect("valid JSON");
        assert_eq!(first.video.start_offset, 0.0);
        assert!(!args(&first, true).contains("setpts"));
        let variable = late.replace(
            "\"avg_frame_rate\": \"30000/1001\"",
            "\"avg_frame_rate\": \"20/1\"",
        );
        let p = Probe::parse(variable.as_bytes()).expect("valid JSON");
        assert!(matches!(p.timing(), Timing::Constant(_)));
        assert!(!args(&p, true).contains("setpts"));
    }

    #[test]
    fn an_rgb_sources_matrix_is_not_passed_on() {
        let rgb = PROBE.replace("\"bt2020nc\"", "\"gbr\"");
        let p = Probe::parse(rgb.as_bytes()).expect("valid JSON");
        let plan = EncodePlan::new(
            Path::new("o.mkv"),
            8,
            Some((Path::new("in.mkv"), &p)),
            &EncodeSettings::default(),
            &caps(true),
        )
        .expect("plan");
        let a = strings(&plan.args).join(" ");
        assert!(!a.contains("-colorspace"), "{a}");
        assert!(
            a.contains("-color_trc arib-std-b67"),
            "the other tags stay: {a}"
        );
    }

    #[test]
    fn steady_clips_pass_through_and_variable_ones_get_a_constant_rate() {
        let probe = |avg: &str, r: &str| {
            let json = PROBE.replace(
                "\"30000/1001\", \"r_frame_rate\": \"30000/1001\"",
                &format!("\"{avg}\", \"r_frame_rate\": \"{r}\""),
            );
            Probe::parse(json.as_bytes()).expect("valid JSON")
        };
        assert_eq!(
            probe("30000/1001", "30000/1001").timing(),
            Timing::Passthrough((30000, 1001))
        );
        // Jitter around the nominal rate: passed through at the average.
        assert_eq!(
            probe("2990/100", "30/1").timing(),
            Timing::Passthrough((2990, 100))
        );
        // A phone slowing down in low light: repeated frames at the nominal rate.
        let slow = probe("2430/100", "30/1");
        assert_eq!(slow.timing(), Timing::Constant((30, 1)));
        assert_eq!(slow.expected_frames(), Some(300), "10.01 s at 30 fps");
        let caps = caps(true);
        let t = y4m_target(slow.video.pix_fmt.as_deref());
        let a = strings(&decode_args(Path::new("in.mov"), &slow, &t, &caps)).join(" ");
        assert!(a.contains("-fps_mode cfr -r 30/1"), "{a}");
        let plan = EncodePlan::new(
            Path::new("o.mp4"),
            10,
            Some((Path::new("in.mov"), &slow)),
            &EncodeSettings::default(),
            &caps,
        )
        .expect("plan");
        assert!(strings(&plan.args)
            .join(" ")
            .contains("-r 30/1 -f yuv4mpegpipe"));
        // An implausible nominal rate: the average.
        assert_eq!(
            probe("2430/100", "90000/1").timing(),
            Timing::Constant((2430, 100))
        );
        assert_eq!(probe("0/0", "0/0").timing(), Timing::Unknown);
    }

    #[test]
    fn rotation_is_normalized() {
        assert_eq!(normalize_rotation(270.0), -90);
        assert_eq!(normalize_rotation(-90.0), -90);
        assert_eq!(normalize_rotation(-180.0), 180);
        assert_eq!(normalize_rotation(90.4), 90);
        assert_eq!(normalize_rotation(f64::NAN), 0);
    }

    #[test]
    fn audio_is_copied_only_where_the_muxer_takes_it() {
        use StreamAction::{Convert, ConvertToDefault, Copy};
        let a = audio_action;
        assert_eq!(a(Container::Mp4, "opus"), Copy);
        assert_eq!(a(Container::Mov, "opus"), Convert("aac".into()));
        assert_eq!(a(Container::Mov, "pcm_s16le"), Copy);
        assert_eq!(a(Container::Mobile, "mp3"), Convert("aac".into()));
        assert_eq!(a(Container::Ts, "ac3"), Copy);
        assert_eq!(a(Container::Ts, "flac"), ConvertToDefault);
        assert_eq!(a(Container::Other, "aac"), ConvertToDefault);
        assert_eq!(a(Container::WebM, "aac"), Convert("libopus".into()));
        assert_eq!(a(Container::Mkv, "flac"), Copy);
    }

    #[test]
    fn y4m_targets_keep_depth_and_range() {
        let t = |p: &str| {
            let t = y4m_target(Some(p));
            (t.pix_fmt, t.bit_depth, t.converts)
        };
        assert_eq!(t("yuv420p"), ("yuv420p".into(), 8, false));
        assert_eq!(t("yuvj420p"), ("yuvj420p".into(), 8, false));
        assert_eq!(t("yuv420p10le"), ("yuv420p10le".into(), 10, false));
        assert_eq!(t("p010le"), ("yuv420p10le".into(), 10, false));
        assert_eq!(t("yuv422p10be"), ("yuv422p10le".into(), 10, false));
        assert_eq!(t("nv12"), ("yuv420p".into(), 8, false));
        assert_eq!(t("yuv420p16le"), ("yuv420p12le".into(), 12, true));
        assert_eq!(t("rgb24"), ("yuv444p".into(), 8, true));
        assert_eq!(t("gray10le"), ("gray12le".into(), 12, true));
        assert_eq!(t("yuva444p10le"), ("yuv444p10le".into(), 10, false));
        assert_eq!(y4m_target(None).pix_fmt, "yuv420p");
    }

    #[test]
    fn capabilities_from_help_and_encoder_list() {
        let help = "-vsync              set video sync method\n-fps_mode  set framerate mode\n";
        let encoders = " V..... = Video\n A..... = Audio\n ------\n V....D libx264              libx264 H.264\n A..... aac                  AAC\n";
        let c = Capabilities::parse(help, encoders);
        assert!(c.fps_mode && !c.display_rotation);
        assert_eq!(c.encoders, ["aac", "libx264"].map(String::from).into());
        assert!(c.has_encoder("libx264") && !c.has_encoder("libx265"));
    }

    #[test]
    fn default_codecs() {
        let c = caps(true);
        let d = |cont, src, depth| default_codec(cont, src, depth, &c);
        assert_eq!(
            d(Container::Mp4, Some("h264"), 8).as_deref(),
            Some("libx264")
        );
        assert_eq!(
            d(Container::Mp4, Some("hevc"), 10).as_deref(),
            Some("libx265")
        );
        assert_eq!(d(Container::Mp4, None, 10).as_deref(), Some("libx265"));
        assert_eq!(
            d(Container::Mov, Some("prores"), 10).as_deref(),
            Some("libx265")
        );
        assert_eq!(
            d(Container::WebM, Some("h264"), 8).as_deref(),
            Some("libvpx-vp9")
        );
        assert_eq!(
            d(Container::Mkv, Some("vp9"), 8).as_deref(),
            Some("libvpx-vp9")
        );
        assert_eq!(d(Container::Other, Some("mpeg2video"), 8), None);
        // Codecs a container's muxer refuses are not kept: VP9 and AV1 in MOV (FFmpeg 5.1),
        // anything in containers unshear does not know (FFmpeg's default for them).
        let mut c = caps(true);
        c.encoders.extend(["libsvtav1", "mpeg4"].map(String::from));
        let d = |cont, src| default_codec(cont, Some(src), 8, &c);
        assert_eq!(d(Container::Mov, "vp9").as_deref(), Some("libx264"));
        assert_eq!(d(Container::Mov, "av1").as_deref(), Some("libx264"));
        assert_eq!(d(Container::Other, "h264"), None);
        assert_eq!(d(Container::Ts, "h264").as_deref(), Some("libx264"));
        assert_eq!(d(Container::Mobile, "mpeg4").as_deref(), Some("libx264"));
        assert_eq!(Container::of(Path::new("clip.MTS")), Container::Ts);
        assert_eq!(Container::of(Path::new("clip.3gp")), Container::Mobile);
        assert_eq!(Container::of(Path::new("a/B.MP4")), Container::Mp4);
        assert_eq!(default_crf("libx264"), Some(18.0));
    }

    #[test]
    fn lossless_sources_keep_their_codec() {
        let mut c = caps(true);
        c.encoders
            .extend(["ffv1", "utvideo", "ffvhuff"].map(String::from));
        let d = |src| default_codec(Container::Mkv, Some(src), 8, &c);
        assert_eq!(d("ffv1").as_deref(), Some("ffv1"));
        assert_eq!(d("utvideo").as_deref(), Some("utvideo"));
        assert_eq!(d("ffvhuff").as_deref(), Some("ffvhuff"));
        assert_eq!(
            default_codec(Container::Mkv, Some("ffv1"), 10, &c).as_deref(),
            Some("ffv1")
        );
        // MP4 cannot hold FFV1: the usual fallback.
        assert_eq!(
            default_codec(Container::Mp4, Some("ffv1"), 8, &c).as_deref(),
            Some("libx264")
        );
        assert_eq!(default_crf("ffv1"), None);
    }

    #[test]
    fn odd_sizes_are_padded_to_even_for_subsampling_encoders() {
        use unshear::video::{Chroma, Plane, VideoFormat, YuvFrame};
        let e = |enc, w, h, c| even_size(enc, w, h, c);
        assert_eq!(
            e(Some("libx264"), 641, 361, Chroma::Yuv420),
            Some((642, 362))
        );
        assert_eq!(
            e(Some("libx264"), 641, 361, Chroma::Yuv422),
            Some((642, 361))
        );
        assert_eq!(e(Some("libx264"), 641, 361, Chroma::Yuv444), None);
        assert_eq!(e(Some("libx264"), 640, 360, Chroma::Yuv420), None);
        assert_eq!(e(Some("ffv1"), 641, 361, Chroma::Yuv420), None);
        assert_eq!(e(None, 641, 360, Chroma::Yuv420), Some((642, 360)));
        let header = b"YUV4MPEG2 W641 H361 F25:1 Ip A1:1 C420jpeg XYSCSS=420JPEG\n";
        assert_eq!(
            resize_header(header, 642, 362),
            b"YUV4MPEG2 W642 H362 F25:1 Ip A1:1 C420jpeg XYSCSS=420JPEG\n".to_vec()
        );
        let format = VideoFormat {
            width: 3,
            height: 3,
            chroma: Chroma::Yuv420,
            full_range: false,
            frame_rate: (25, 1),
            bit_depth: 10,
        };
        let mut f: YuvFrame<u16> = YuvFrame::blank(&format);
        f.y = Plane::from_fn(3, 3, |x, y| image::Luma([(10 * y + x) as u16]));
        pad_luma(&mut f, 4, 4);
        assert_eq!(f.y.dimensions(), (4, 4));
        assert_eq!(f.u.dimensions(), (2, 2));
        let row = |r: u32| (0..4).map(|x| f.y.get_pixel(x, r)[0]).collect::<Vec<_>>();
        assert_eq!(row(0), [0, 1, 2, 2]);
        assert_eq!(row(2), [20, 21, 22, 22]);
        assert_eq!(row(3), [20, 21, 22, 22]);
    }

    #[test]
    fn encode_plan_copies_streams_and_tags() {
        let p = Probe::parse(PROBE.as_bytes()).expect("valid JSON");
        let src = Path::new("in.mov");
        let plan = EncodePlan::new(
            Path::new("out.mp4"),
            10,
            Some((src, &p)),
            &EncodeSettings::default(),
            &caps(true),
        )
        .expect("plan");
        let a = strings(&plan.args).join(" ");
        assert_eq!(plan.codec.as_deref(), Some("libx265"));
        assert!(
            a.contains(
                "-noautorotate -display_rotation -90 -r 30000/1001 -f yuv4mpegpipe -i - -i in.mov"
            ),
            "{a}"
        );
        assert!(
            a.contains("-map 0:v:0 -map 1:1 -c:a:0 copy -map 1:3 -c:s:0 mov_text"),
            "{a}"
        );
        assert!(
            !a.contains("1:4"),
            "bitmap subtitles cannot go into MP4: {a}"
        );
        assert!(a.contains("-c:v libx265 -crf 20"), "{a}");
        assert!(a.contains("-tag:v hvc1"), "{a}");
        assert!(a.contains("-color_trc arib-std-b67") && a.contains("-colorspace bt2020nc"));
        assert!(a.ends_with("out.mp4"));
        assert_eq!(plan.remux_rotation, None);
        assert!(matches!(plan.subtitles[1].1, StreamAction::Drop(_)));

        // An older ffmpeg: no rotation in the encoding pass, a remux for it.
        let old = EncodePlan::new(
            Path::new("out.mp4"),
            10,
            Some((src, &p)),
            &EncodeSettings {
                codec: Some("libx264".into()),
                crf: Some(23.5),
                preset: Some("veryfast".into()),
            },
            &caps(false),
        )
        .expect("plan");
        let a = strings(&old.args).join(" ");
        assert!(!a.contains("display_rotation"), "{a}");
        assert!(a.contains("-c:v libx264 -crf 23.5 -preset veryfast"), "{a}");
        assert_eq!(old.remux_rotation, Some(-90));
        let r = strings(&EncodePlan::remux_args(
            Path::new("t.mp4"),
            Path::new("o.mp4"),
            -90,
        ));
        assert!(r
            .join(" ")
            .contains("-map 0 -c copy -metadata:s:v:0 rotate=270 o.mp4"));

        // WebM: Opus audio, no rotation, WebVTT subtitles.
        let webm = EncodePlan::new(
            Path::new("out.webm"),
            10,
            Some((src, &p)),
            &EncodeSettings::default(),
            &caps(true),
        )
        .expect("plan");
        let a = strings(&webm.args).join(" ");
        assert!(
            a.contains("-c:a:0 libopus") && a.contains("-c:s:0 webvtt"),
            "{a}"
        );
        assert!(a.contains("-c:v libvpx-vp9 -crf 30 -b:v 0"), "{a}");
        assert_eq!(webm.rotation_lost, Some(-90));
        assert!(!a.contains("display_rotation"));

        // A y4m source: no second input.
        let bare = EncodePlan::new(
            Path::new("out.mkv"),
            10,
            None,
            &EncodeSettings::default(),
            &caps(true),
        )
        .expect("plan");
        let a = strings(&bare.args).join(" ");
        assert_eq!(a.matches("-i ").count(), 1, "{a}");
        assert!(EncodePlan::new(
            Path::new("o.mp4"),
            10,
            None,
            &EncodeSettings {
                crf: Some(f64::NAN),
                ..Default::default()
            },
            &caps(true)
        )
        .is_err());
    }

    #[test]
    fn decode_args_keep_every_frame_unrotated() {
        let p = Probe::parse(PROBE.as_bytes()).expect("valid JSON");
        let t = y4m_target(p.video.pix_fmt.as_deref());
        let a = strings(&decode_args(Path::new("in.mov"), &p, &t, &caps(true))).join(" ");
        assert!(
            a.contains("-xerror -noautorotate -i in.mov -map 0:0"),
            "{a}"
        );
        assert!(
            a.contains("-fps_mode passthrough -pix_fmt yuv420p10le -strict -1 -f yuv4mpegpipe -")
        );
        let old = Capabilities {
            fps_mode: false,
            ..caps(false)
        };
        let a = strings(&decode_args(Path::new("in.mov"), &p, &t, &old)).join(" ");
        assert!(a.contains("-vsync passthrough"), "{a}");
    }
}

//! `unshear video` on video files through the `ffmpeg` program: a short H.264 MP4 with an AAC
//! sound track and a rotation flag, made by ffmpeg from a sheared fixture face, comes out with
//! its sound, frame count, duration and rotation and the face's shear measured on every frame;
//! a 10-bit HEVC clip and a 10-bit y4m stay 10-bit; a truncated file, a failing encoder, an
//! ffmpeg killed half-way and Ctrl-C leave no output; a missing ffmpeg is a clear error; an
//! odd-size 4:2:0 stream is padded for H.264 and kept for FFV1; an FFV1 input stays FFV1;
//! missing output folders are created. Tests that need ffmpeg print a note and pass when it is
//! not installed.

mod common;

#[cfg(unix)]
use std::io::BufReader;
use std::path::{Path, PathBuf};
#[cfg(unix)]
use std::process::{Child, ChildStdout};
use std::process::{Command, Output, Stdio};

use image::{imageops, DynamicImage, GrayImage, Luma};
use unshear::video::y4m::{Y4mReader, Y4mWriter};
use unshear::video::{Chroma, VideoFormat, VideoFrame, YuvFrame};
use unshear::warp::{apply_shear, Canvas, Interpolation};
use unshear::Shear;

const W: u32 = 320;
const H: u32 = 240;
const FRAMES: usize = 20;
/// The shear every frame of the clip was taken with.
const K: f64 = 0.25;

/// Whether `ffmpeg` and `ffprobe` run; otherwise notes the skip (past the harness's capture).
fn have_ffmpeg(test: &str) -> bool {
    let runs = |p: &str| {
        Command::new(p)
            .arg("-version")
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status()
            .is_ok_and(|s| s.success())
    };
    let ok = runs("ffmpeg") && runs("ffprobe");
    if !ok {
        note_skip(
            test,
            "ffmpeg/ffprobe not found on PATH (apt-get install ffmpeg)",
        );
    }
    ok
}

/// Writes "skipped `test`: `why`" to stderr directly, past the harness's capture.
fn note_skip(test: &str, why: &str) {
    let note = format!("skipped {test}: {why}\n");
    let _ = std::io::Write::write_all(&mut std::io::stderr(), note.as_bytes());
}

/// A temp dir for `test` if ffmpeg, ffprobe and ffmpeg's `encoder` are there; else notes the skip.
fn ffmpeg_test_dir(encoder: &str, test: &str) -> Option<tempfile::TempDir> {
    (have_ffmpeg(test) && has_encoder(encoder, test))
        .then(|| tempfile::tempdir().expect("temp dir"))
}

/// Whether this ffmpeg has `encoder`; otherwise notes the skip.
fn has_encoder(encoder: &str, test: &str) -> bool {
    let out = Command::new("ffmpeg")
        .args(["-hide_banner", "-encoders"])
        .output()
        .expect("ffmpeg -encoders");
    let listed = String::from_utf8_lossy(&out.stdout)
        .lines()
        .any(|l| l.split_whitespace().nth(1) == Some(encoder));
    if !listed {
        note_skip(test, &format!("this ffmpeg has no {encoder} encoder"));
    }
    listed
}

/// A fixture face on a grey 320x240 canvas, sheared by `K`, with a little noise per frame.
fn frames() -> Vec<GrayImage> {
    scenes().iter().map(|scene| shear_rows(scene, K)).collect()
}

/// `img` sheared by `k` along its rows about its middle row.
fn shear_rows(img: &GrayImage, k: f64) -> GrayImage {
    let (frame, _) = apply_shear(
        &DynamicImage::ImageLuma8(img.clone()),
        Shear::about_middle(k, img.height()),
        Interpolation::Linear,
        Canvas::Same,
    );
    frame.to_luma8()
}

/// The frames a phone held upright stores: each scene turned 90 degrees clockwise (the sensor's
/// rows are the shown picture's columns), sheared by `K` along those stored rows. Shown turned
/// back (rotation flag 90), the face is upright and sheared vertically by `-K`.
fn portrait_frames() -> Vec<GrayImage> {
    scenes()
        .iter()
        .map(|scene| shear_rows(&imageops::rotate90(scene), K))
        .collect()
}

/// The fixture face moving on a grey 320x240 canvas, upright and unsheared.
fn scenes() -> Vec<GrayImage> {
    let face = unshear::imageio::read_image(
        &common::fixture("subject01.normal.jpeg"),
        unshear::imageio::DEFAULT_MAX_PIXELS,
    )
    .expect("fixture")
    .to_luma8();
    let face = imageops::resize(&face, 240, 182, imageops::FilterType::Triangle);
    (0..FRAMES)
        .map(|t| {
            let mut scene = GrayImage::from_pixel(W, H, Luma([110]));
            imageops::overlay(&mut scene, &face, 40 + t as i64, 30);
            scene
        })
        .collect()
}

fn format(bit_depth: u32) -> VideoFormat {
    VideoFormat {
        width: W,
        height: H,
        chroma: Chroma::Yuv420,
        full_range: false,
        frame_rate: (25, 1),
        bit_depth,
    }
}

/// The frames as an 8-bit y4m stream (limited range, neutral chroma).
fn y4m8(frames: &[GrayImage]) -> Vec<u8> {
    let (width, height) = frames[0].dimensions();
    let format = VideoFormat {
        width,
        height,
        ..format(8)
    };
    let mut w = Y4mWriter::new(Vec::new(), &format).expect("header");
    for y in frames {
        let mut f = YuvFrame::blank(&format);
        f.y = GrayImage::from_fn(width, height, |x, yy| {
            Luma([16 + (u16::from(y.get_pixel(x, yy)[0]) * 219 / 255) as u8])
        });
        w.write_frame(&f).expect("frame");
    }
    w.finish().expect("flush")
}

/// The frames as a 10-bit y4m stream whose luma uses all 10 bits (not 8-bit values times 4).
fn y4m10(frames: &[GrayImage]) -> Vec<u8> {
    let mut w = Y4mWriter::new(Vec::new(), &format(10)).expect("header");
    for y in frames {
        let mut f: YuvFrame<u16> = YuvFrame::blank(&format(10));
        f.y = unshear::video::Plane::from_fn(W, H, |x, yy| {
            Luma([64 + (u32::from(y.get_pixel(x, yy)[0]) * 876 / 255) as u16 + (x % 3) as u16])
        });
        w.write_frame16(&f).expect("frame");
    }
    w.finish().expect("flush")
}

/// Runs ffmpeg with `args`, panicking with its message on failure.
fn ffmpeg(args: &[&str], stdin: Option<&[u8]>) {
    let mut child = Command::new("ffmpeg")
        .args(["-hide_banner", "-loglevel", "error", "-y"])
        .args(args)
        .stdin(if stdin.is_some() {
            Stdio::piped()
        } else {
            Stdio::null()
        })
        .stderr(Stdio::piped())
        .spawn()
        .expect("ffmpeg");
    if let Some(bytes) = stdin {
        use std::io::Write;
        child
            .stdin
            .take()
            .expect("stdin")
            .write_all(bytes)
            .expect("pipe to ffmpeg");
    }
    let out = child.wait_with_output().expect("ffmpeg ran");
    assert!(
        out.status.success(),
        "ffmpeg {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The ffmpeg arguments that read lavfi's generated `source` as an input.
fn lavfi(source: &str) -> [&str; 4] {
    ["-f", "lavfi", "-i", source]
}

/// Encodes the lavfi `sources` with output `options` to `out`: ultrafast H.264, AAC if `sound`.
fn lavfi_clip(out: &Path, sources: &[&str], options: &[&str], sound: bool) {
    let mut args = Vec::new();
    for source in sources {
        args.extend(lavfi(source));
    }
    args.extend(options);
    args.extend(["-c:v", "libx264", "-preset", "ultrafast"]);
    if sound {
        args.extend(["-c:a", "aac"]);
    }
    args.push(path(out));
    ffmpeg(&args, None);
}

/// `y4m` encoded to an H.264 file `out`, without sound.
fn h264_from(y4m: &Path, out: &Path) {
    ffmpeg(
        &[
            "-i",
            path(y4m),
            "-c:v",
            "libx264",
            "-preset",
            "ultrafast",
            path(out),
        ],
        None,
    );
}

/// A short H.264 + AAC MP4 as a phone held upright records it ([`portrait_frames`]), flagged
/// for display rotated by 90 degrees (by `-display_rotation` where this ffmpeg has it, as 7.0
/// does, else by the `rotate` tag of a stream copy, which only older versions honour).
fn make_mp4(dir: &Path) -> PathBuf {
    let y4m = dir.join("clip.y4m");
    std::fs::write(&y4m, y4m8(&portrait_frames())).expect("write y4m");
    let help = Command::new("ffmpeg")
        .args(["-hide_banner", "-h", "long"])
        .output()
        .expect("ffmpeg -h");
    let display_rotation = String::from_utf8_lossy(&help.stdout).contains("-display_rotation");
    let plain = dir.join("plain.mp4");
    let clip = dir.join("clip.mp4");
    let mut args = vec![];
    if display_rotation {
        args.extend(["-noautorotate", "-display_rotation", "90"]);
    }
    args.extend(["-i", path(&y4m)]);
    args.extend(lavfi("sine=frequency=440:sample_rate=48000:duration=0.8"));
    args.extend([
        "-map",
        "0:v",
        "-map",
        "1:a",
        "-c:v",
        "libx264",
        "-preset",
        "veryfast",
        "-crf",
        "12",
        "-c:a",
        "aac",
        path(if display_rotation { &clip } else { &plain }),
    ]);
    ffmpeg(&args, None);
    if !display_rotation {
        ffmpeg(
            &[
                "-i",
                path(&plain),
                "-map",
                "0",
                "-c",
                "copy",
                "-metadata:s:v:0",
                "rotate=90",
                path(&clip),
            ],
            None,
        );
    }
    clip
}

fn path(p: &Path) -> &str {
    p.to_str().expect("UTF-8 temp path")
}

/// `ffprobe`'s streams of a file.
fn streams(file: &Path) -> Vec<serde_json::Value> {
    let out = Command::new("ffprobe")
        .args(["-v", "error", "-print_format", "json", "-show_streams"])
        .arg(file)
        .output()
        .expect("ffprobe");
    assert!(out.status.success(), "ffprobe {}", file.display());
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON");
    v["streams"].as_array().cloned().unwrap_or_default()
}

fn stream<'a>(streams: &'a [serde_json::Value], kind: &str) -> &'a serde_json::Value {
    streams
        .iter()
        .find(|s| s["codec_type"] == kind)
        .unwrap_or_else(|| panic!("no {kind} stream in {streams:?}"))
}

fn number(v: &serde_json::Value) -> f64 {
    v.as_str()
        .and_then(|s| s.parse().ok())
        .or_else(|| v.as_f64())
        .unwrap_or_else(|| panic!("not a number: {v}"))
}

fn rotation(s: &serde_json::Value) -> f64 {
    s["side_data_list"]
        .as_array()
        .and_then(|l| l.iter().find_map(|d| d["rotation"].as_f64()))
        .unwrap_or(0.0)
}

fn unshear_cmd() -> Command {
    Command::new(env!("CARGO_BIN_EXE_unshear"))
}

/// `unshear video <input> -o <out>`, ready for more arguments.
fn video_cmd(input: &Path, out: &Path) -> Command {
    let mut cmd = unshear_cmd();
    cmd.arg("video").arg(input).arg("-o").arg(out);
    cmd
}

/// Runs `cmd` to its end and asserts that it succeeded, showing its stderr if not.
fn run_ok(cmd: &mut Command) -> Output {
    let run = cmd.output().expect("unshear");
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    run
}

/// Starts `unshear video <input> -o <out> --json` and reads its first JSON line (frames flow).
#[cfg(unix)]
fn start_json(input: &Path, out: &Path) -> (Child, BufReader<ChildStdout>, String) {
    common::spawn_and_read_first_line(video_cmd(input, out).arg("--json"))
}

/// Sends `signal` (such as `-INT`) to process `pid` with kill(1), asserting that it went.
#[cfg(unix)]
fn kill(signal: &str, pid: u32) {
    let killed = Command::new("kill")
        .args([signal, &pid.to_string()])
        .status()
        .expect("kill");
    assert!(killed.success());
}

/// Files this tool leaves while writing (`.unshear-*`).
fn temporaries(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .expect("list")
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(".unshear-"))
        .collect()
}

/// Asserts that a failed run (`what`) left neither `out` nor a temporary file in `dir`.
fn assert_nothing_left(dir: &Path, out: &Path, what: &str) {
    assert!(!out.exists(), "{what}: no output under the final name");
    assert_eq!(temporaries(dir), Vec::<String>::new());
}

/// The per-frame `k` of a `--json` file.
fn ks(json: &Path) -> Vec<Option<f64>> {
    let text = std::fs::read(json).expect("JSON lines");
    common::json_lines(&text)
        .iter()
        .map(|l| l["k_raw"].as_f64())
        .collect()
}

/// Asserts that a face was found in every frame and measured within 0.06 of the shear `K`.
fn assert_sheared_by_k(ks: &[Option<f64>]) {
    assert_sheared_by(ks, K);
}

/// Asserts that a face was found in every frame and measured within 0.06 of `expected`.
fn assert_sheared_by(ks: &[Option<f64>], expected: f64) {
    for (i, k) in ks.iter().enumerate() {
        let k = k.unwrap_or_else(|| panic!("no face in frame {i}"));
        assert!(
            (k - expected).abs() < 0.06,
            "frame {i}: k {k}, sheared by {expected}"
        );
    }
}

#[test]
fn mp4_in_mp4_out_keeps_sound_frames_duration_and_rotation() {
    let Some(dir) = ffmpeg_test_dir("libx264", "mp4_in_mp4_out") else {
        return;
    };
    let clip = make_mp4(dir.path());
    let out = dir.path().join("fixed.mp4");
    let json = dir.path().join("frames.jsonl");
    let run = run_ok(video_cmd(&clip, &out).arg(format!("--json={}", json.display())));
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(stderr.contains("1 audio copied"), "{stderr}");

    let (src, dst) = (streams(&clip), streams(&out));
    let (sv, dv) = (stream(&src, "video"), stream(&dst, "video"));
    assert_eq!(dv["codec_name"], "h264", "the input's codec by default");
    assert_eq!(stream(&dst, "audio")["codec_name"], "aac");
    assert_eq!(
        number(&sv["nb_frames"]),
        number(&dv["nb_frames"]),
        "frame count"
    );
    assert_eq!(number(&dv["nb_frames"]), FRAMES as f64);
    let (d_in, d_out) = (number(&sv["duration"]), number(&dv["duration"]));
    assert!((d_in - d_out).abs() < 0.041, "duration {d_in} -> {d_out}");
    let audio_in = number(&stream(&src, "audio")["duration"]);
    let audio_out = number(&stream(&dst, "audio")["duration"]);
    assert!((audio_in - audio_out).abs() < 1e-3, "audio copied whole");
    assert_eq!(rotation(sv), 90.0, "the test clip is flagged");
    assert_eq!(rotation(dv), rotation(sv), "rotation kept");
    assert_eq!(
        (dv["width"].as_u64(), dv["height"].as_u64()),
        (Some(240), Some(320)),
        "stored as the phone stored it"
    );
    assert!(stderr.contains("vertical shear"), "{stderr}");

    // The face's shear, measured on every frame: shown turned upright, the stored rows'
    // shear K is the shown picture's vertical shear -K.
    let ks = ks(&json);
    assert_eq!(ks.len(), FRAMES);
    assert_sheared_by(&ks, -K);
    // The output is corrected: its frames read near 0 (and it is still a face).
    let again = dir.path().join("again.jsonl");
    run_ok(
        unshear_cmd()
            .arg("video")
            .arg(&out)
            .arg(format!("--json={}", again.display())),
    );
    let residual: Vec<f64> = crate::ks(&again).into_iter().flatten().collect();
    assert!(
        residual.len() >= FRAMES - 2,
        "faces still found: {residual:?}"
    );
    let mean = residual.iter().sum::<f64>() / residual.len() as f64;
    assert!(mean.abs() < 0.06, "corrected clip reads k {mean}");
    assert!(temporaries(dir.path()).is_empty());
}

/// A picture that starts half a second after its sound (as in TS recordings and edits) still
/// starts half a second after it, to within a frame (the encoder's time base is the frame
/// rate's), with every frame once.
#[test]
fn a_picture_starting_after_the_sound_stays_in_step() {
    let Some(dir) = ffmpeg_test_dir("libx264", "picture_after_sound") else {
        return;
    };
    let y4m = dir.path().join("clip.y4m");
    std::fs::write(&y4m, y4m8(&frames())).expect("write y4m");
    let plain = dir.path().join("plain.mp4");
    h264_from(&y4m, &plain);
    // The picture copied half a second late beside new sound (an encode would fill the gap).
    let clip = dir.path().join("late.mp4");
    let mut args = vec!["-itsoffset", "0.5", "-i", path(&plain)];
    args.extend(lavfi("sine=frequency=440:sample_rate=48000:duration=1.5"));
    args.extend([
        "-map",
        "0:v",
        "-map",
        "1:a",
        "-c:v",
        "copy",
        "-c:a",
        "aac",
        path(&clip),
    ]);
    ffmpeg(&args, None);
    let late = |file: &Path| {
        let s = streams(file);
        number(&stream(&s, "video")["start_time"]) - number(&stream(&s, "audio")["start_time"])
    };
    let before = late(&clip);
    assert!(
        (before - 0.5).abs() < 0.05,
        "test clip: picture {before} s late"
    );
    for ext in ["mp4", "mkv"] {
        let out = dir.path().join(format!("fixed.{ext}"));
        run_ok(&mut video_cmd(&clip, &out));
        let after = late(&out);
        assert!(
            (after - before).abs() <= 1.0 / 25.0 + 1e-3,
            "{ext}: picture {before} s late before, {after} s after"
        );
        let v = streams(&out);
        let frames = Command::new("ffprobe")
            .args(["-v", "error", "-count_frames", "-select_streams", "v"])
            .args(["-show_entries", "stream=nb_read_frames", "-of", "csv=p=0"])
            .arg(&out)
            .output()
            .expect("ffprobe");
        let count: usize = String::from_utf8_lossy(&frames.stdout)
            .trim()
            .parse()
            .expect("count");
        assert_eq!(count, FRAMES, "{ext}: every frame once ({v:?})");
    }
}

#[test]
fn ten_bit_hevc_stays_ten_bit() {
    let Some(dir) = ffmpeg_test_dir("libx265", "ten_bit_hevc") else {
        return;
    };
    let clip = dir.path().join("hdr.mp4");
    // 10-bit HLG in BT.2020, as phones record HDR.
    ffmpeg(
        &[
            "-f",
            "yuv4mpegpipe",
            "-i",
            "-",
            "-c:v",
            "libx265",
            "-preset",
            "ultrafast",
            "-x265-params",
            "log-level=error",
            "-color_primaries",
            "bt2020",
            "-color_trc",
            "arib-std-b67",
            "-colorspace",
            "bt2020nc",
            path(&clip),
        ],
        Some(&y4m10(&frames()[..10])),
    );
    let out = dir.path().join("fixed.mp4");
    let json = dir.path().join("frames.jsonl");
    let run = run_ok(
        video_cmd(&clip, &out)
            .arg(format!("--json={}", json.display()))
            .args(["--preset", "ultrafast"]),
    );
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(
        stderr.contains("libx265 crf 20 preset ultrafast"),
        "{stderr}"
    );
    let dst = streams(&out);
    let v = stream(&dst, "video");
    assert_eq!(v["codec_name"], "hevc");
    assert_eq!(v["pix_fmt"], "yuv420p10le");
    assert_eq!(v["color_transfer"], "arib-std-b67");
    assert_eq!(v["color_primaries"], "bt2020");
    assert_eq!(number(&v["nb_frames"]), 10.0);
    assert_sheared_by_k(&ks(&json));
    // The output's samples use the two low bits: it was not cut to 8 bits on the way.
    let decoded = Command::new("ffmpeg")
        .args(["-hide_banner", "-loglevel", "error", "-i"])
        .arg(&out)
        .args(["-frames:v", "1", "-strict", "-1", "-f", "yuv4mpegpipe", "-"])
        .output()
        .expect("decode");
    let mut r = Y4mReader::new(decoded.stdout.as_slice(), 1 << 20).expect("10-bit y4m");
    assert_eq!(r.format().bit_depth, 10);
    let Some(VideoFrame::Yuv16(f)) = r.read_video_frame().expect("frame") else {
        panic!("a 10-bit frame")
    };
    let odd = f.y.pixels().filter(|p| p[0] % 4 != 0).count();
    assert!(
        odd > f.y.len() / 4,
        "only {odd} of {} samples off the 8-bit grid",
        f.y.len()
    );
}

/// 10-bit y4m in, 10-bit y4m out: no ffmpeg involved.
#[test]
fn ten_bit_y4m_is_corrected_at_its_depth() {
    let dir = tempfile::tempdir().expect("temp dir");
    let input = dir.path().join("in.y4m");
    let frames = frames();
    std::fs::write(&input, y4m10(&frames[..8])).expect("write");
    let out = dir.path().join("out.y4m");
    let run = run_ok(video_cmd(&input, &out).arg("--json").env("PATH", ""));
    let lines = common::json_lines(&run.stdout);
    assert_eq!(lines.len(), 8);
    let bytes = std::fs::read(&out).expect("output");
    let mut r = Y4mReader::new(bytes.as_slice(), 1 << 20).expect("y4m");
    assert!(String::from_utf8_lossy(r.header()).contains("C420p10"));
    let mut n = 0;
    while let Some(f) = r.read_video_frame().expect("frame") {
        let VideoFrame::Yuv16(f) = f else {
            panic!("10-bit frames")
        };
        let k = lines[n]["k"].as_f64().expect("k");
        assert!((k - K).abs() < 0.06, "frame {n}: k {k}");
        assert!(f.y.pixels().all(|p| p[0] <= 1023));
        n += 1;
    }
    assert_eq!(n, 8);
}

#[test]
fn truncated_input_and_failing_encoder_leave_no_output() {
    let Some(dir) = ffmpeg_test_dir("libx264", "truncated_input") else {
        return;
    };
    let clip = make_mp4(dir.path());
    // Media data at the end, the index first: the cut file opens and breaks mid-stream.
    let faststart = dir.path().join("faststart.mp4");
    ffmpeg(
        &[
            "-i",
            path(&clip),
            "-c",
            "copy",
            "-movflags",
            "+faststart",
            path(&faststart),
        ],
        None,
    );
    let bytes = std::fs::read(&faststart).expect("read");
    let cut = dir.path().join("cut.mp4");
    std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).expect("write");
    // The index at the end: the cut file does not open.
    let bytes = std::fs::read(&clip).expect("read");
    let headless = dir.path().join("headless.mp4");
    std::fs::write(&headless, &bytes[..bytes.len() / 2]).expect("write");
    for (input, extra) in [
        (&cut, None),
        (&headless, None),
        (&clip, Some("nosuchcodec")),
    ] {
        let out = dir.path().join("out.mp4");
        let mut cmd = video_cmd(input, &out);
        if let Some(codec) = extra {
            cmd.args(["--codec", codec]);
        }
        let run = cmd.output().expect("unshear");
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert!(!run.status.success(), "{}: {stderr}", input.display());
        assert!(
            stderr.contains("ffmpeg") || stderr.contains("ffprobe"),
            "{stderr}"
        );
        assert_nothing_left(dir.path(), &out, &input.display().to_string());
    }
}

#[test]
fn missing_ffmpeg_is_a_clear_error_and_y4m_still_works() {
    let dir = tempfile::tempdir().expect("temp dir");
    let clip = dir.path().join("clip.mp4");
    std::fs::write(&clip, b"\0\0\0\x18ftypmp42 not really a video").expect("write");
    let run = video_cmd(&clip, &dir.path().join("out.mp4"))
        .env("PATH", "")
        .output()
        .expect("unshear");
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(!run.status.success());
    assert!(
        stderr.contains("ffmpeg was not found on PATH")
            && stderr.contains("apt-get install ffmpeg"),
        "{stderr}"
    );
    assert!(stderr.contains("y4m files and pipes"), "{stderr}");
    let run = unshear_cmd()
        .arg("video")
        .arg(&clip)
        .args(["--ffmpeg", "/nonexistent/ffmpeg"])
        .output()
        .expect("unshear");
    assert!(String::from_utf8_lossy(&run.stderr).contains("--ffmpeg /nonexistent/ffmpeg"));
    // y4m in and out needs no ffmpeg.
    let y4m = dir.path().join("in.y4m");
    std::fs::write(&y4m, y4m8(&frames()[..3])).expect("write");
    run_ok(video_cmd(&y4m, &dir.path().join("out.y4m")).env("PATH", ""));
}

/// Ctrl-C while encoding: exit 130, no output, no temporary file, no ffmpeg left running.
#[cfg(unix)]
#[test]
fn interrupt_ends_ffmpeg_and_leaves_nothing() {
    let Some(dir) = ffmpeg_test_dir("libx264", "interrupt_ends_ffmpeg") else {
        return;
    };
    // A longer clip (10 s), so that the run is still going when the signal comes.
    let clip = dir.path().join("long.mp4");
    lavfi_clip(
        &clip,
        &[
            "testsrc2=size=320x240:rate=25",
            "sine=frequency=440:sample_rate=48000",
        ],
        &["-t", "10"],
        true,
    );
    let out = dir.path().join("out.mp4");
    // The first JSON line: the handler is installed and both ffmpeg children run.
    let (child, _stdout, first) = start_json(&clip, &out);
    assert!(first.contains("\"frame\":0"), "{first}");
    kill("-INT", child.id());
    let output = child.wait_with_output().expect("wait");
    assert_eq!(
        output.status.code(),
        Some(130),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    assert_nothing_left(dir.path(), &out, "interrupted");
    // No process still has the clip or the temporary file on its command line.
    let left = processes_with(&dir.path().to_string_lossy(), "ffmpeg");
    assert!(left.is_empty(), "still running: {left:?}");
}

/// The processes whose command line holds `needle` and `marker` (none where there is no /proc).
#[cfg(unix)]
fn processes_with(needle: &str, marker: &str) -> Vec<(u32, String)> {
    let mut found = Vec::new();
    if let Ok(procs) = std::fs::read_dir("/proc") {
        for p in procs.filter_map(|e| e.ok()) {
            let Some(pid) = p.file_name().to_str().and_then(|n| n.parse::<u32>().ok()) else {
                continue;
            };
            if let Ok(cmdline) = std::fs::read(p.path().join("cmdline")) {
                let cmdline = String::from_utf8_lossy(&cmdline).replace('\0', " ");
                if cmdline.contains(needle) && cmdline.contains(marker) {
                    found.push((pid, cmdline));
                }
            }
        }
    }
    found
}

/// An ffmpeg that dies half-way (the decoder, then the encoder, killed once frames flow): a
/// clear error naming it, exit 1, no output, no temporary file, the other ffmpeg ended too.
#[cfg(target_os = "linux")]
#[test]
fn ffmpeg_dying_half_way_leaves_nothing() {
    let Some(dir) = ffmpeg_test_dir("libx264", "ffmpeg_dying_half_way") else {
        return;
    };
    let clip = dir.path().join("long.mp4");
    lavfi_clip(
        &clip,
        &["testsrc2=size=320x240:rate=25"],
        &["-t", "10"],
        false,
    );
    let needle = dir.path().to_string_lossy().into_owned();
    // The decoder's command line has -xerror; the encoder's reads the pipe ("-i -").
    for (victim, marker, says) in [
        ("decoder", "-xerror", "decoding"),
        ("encoder", "yuv4mpegpipe -i -", "encoding"),
    ] {
        let out = dir.path().join("out.mp4");
        // In one pass, so that the decoder is still running when frames come out (in two
        // passes a short clip's frames are held from the first, whose decoder has ended).
        let (child, mut stdout, _) = common::spawn_and_read_first_line(
            video_cmd(&clip, &out).args(["--json", "--one-pass"]),
        );
        let targets = processes_with(&needle, marker);
        assert_eq!(targets.len(), 1, "{victim}: {targets:?}");
        kill("-KILL", targets[0].0);
        std::io::copy(&mut stdout, &mut std::io::sink()).expect("drain");
        let output = child.wait_with_output().expect("wait");
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.code(), Some(1), "{victim}: {stderr}");
        assert!(
            stderr.contains(&format!("ffmpeg failed {says}"))
                || stderr.contains(&format!("ffmpeg {says}")),
            "{victim}: {stderr}"
        );
        assert_nothing_left(dir.path(), &out, victim);
        let left: Vec<_> = processes_with(&needle, "ffmpeg")
            .into_iter()
            .filter(|(_, c)| !c.contains("kill"))
            .collect();
        assert!(left.is_empty(), "{victim}: still running: {left:?}");
    }
}

/// A clip whose rate drops (1 s at 30 fps, then 1 s at 10 fps) comes out at a constant 30 fps
/// with frames repeated, so that its picture keeps its timing against the sound (spread evenly
/// at the 22.6 fps average, the frame at 1 s would show at 1.3 s).
#[test]
fn variable_frame_rate_keeps_picture_and_sound_in_step() {
    let Some(dir) = ffmpeg_test_dir("libx264", "variable_frame_rate") else {
        return;
    };
    let clip = dir.path().join("vfr.mp4");
    lavfi_clip(
        &clip,
        &[
            "testsrc2=size=320x240:rate=30:duration=1",
            "testsrc2=size=320x240:rate=10:duration=1",
            "sine=frequency=440:sample_rate=48000:duration=2",
        ],
        &[
            "-filter_complex",
            "[0:v][1:v]concat=n=2:v=1:a=0[v]",
            "-map",
            "[v]",
            "-map",
            "2:a",
            "-fps_mode",
            "vfr",
        ],
        true,
    );
    let out = dir.path().join("out.mp4");
    let run = run_ok(&mut video_cmd(&clip, &out));
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(stderr.contains("variable frame rate"), "{stderr}");
    let (src, dst) = (streams(&clip), streams(&out));
    let v = stream(&dst, "video");
    assert_eq!(v["avg_frame_rate"], "30/1");
    let frames = number(&v["nb_frames"]);
    let seconds = number(&v["duration"]);
    assert!(
        (frames / 30.0 - seconds).abs() < 0.05,
        "{frames} frames, {seconds} s"
    );
    // The picture spans the clip: 1 s at 30 fps plus 1 s of 10 frames, about 1.8-1.9 s (the
    // evenly spread average rate would give the same span, but with the picture late in its
    // first half; the constant rate is what keeps each frame at its time).
    let source = number(&stream(&src, "video")["duration"]);
    assert!(
        seconds >= source - 0.05 && seconds <= 2.0,
        "{seconds} s against {source} s"
    );
    assert!(
        frames > 50.0,
        "frames repeated where the rate dropped: {frames}"
    );
}

/// A grey gradient y4m of an odd size (65x49, 4:2:0, 3 frames): its last column and row differ
/// from their neighbours, so a padding that repeats them can be told from one that does not.
fn odd_y4m() -> Vec<u8> {
    let format = VideoFormat {
        width: 65,
        height: 49,
        ..format(8)
    };
    let mut w = Y4mWriter::new(Vec::new(), &format).expect("header");
    for _ in 0..3 {
        let mut f = YuvFrame::blank(&format);
        f.y = GrayImage::from_fn(65, 49, |x, y| Luma([(16 + 3 * x + y) as u8]));
        w.write_frame(&f).expect("frame");
    }
    w.finish().expect("flush")
}

/// `(codec, width, height)` of a file's video stream.
fn video_size(file: &Path) -> (String, f64, f64) {
    let s = streams(file);
    let v = stream(&s, "video");
    (
        v["codec_name"].as_str().unwrap_or("").to_string(),
        v["width"].as_f64().unwrap_or(0.0),
        v["height"].as_f64().unwrap_or(0.0),
    )
}

/// An odd-size 4:2:0 stream into H.264 (which needs an even size): padded by one column and
/// row that repeat the edge, with a warning; into FFV1 the size is kept.
#[test]
fn odd_size_420_is_padded_for_x264_and_kept_for_ffv1() {
    let Some(dir) = ffmpeg_test_dir(
        "libx264",
        "odd_size_420_is_padded_for_x264_and_kept_for_ffv1",
    ) else {
        return;
    };
    let input = dir.path().join("odd.y4m");
    std::fs::write(&input, odd_y4m()).expect("write y4m");
    let out = dir.path().join("odd.mp4");
    let run = run_ok(video_cmd(&input, &out).arg("--no-correct"));
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(
        stderr.contains("padded to 66x50 by repeating the last column and row"),
        "{stderr}"
    );
    assert_eq!(video_size(&out), ("h264".into(), 66.0, 50.0));
    // The added column and row repeat the last ones (within x264's rounding at CRF 18).
    let raw = dir.path().join("odd.gray");
    ffmpeg(
        &[
            "-i",
            path(&out),
            "-frames:v",
            "1",
            "-f",
            "rawvideo",
            "-pix_fmt",
            "gray",
            path(&raw),
        ],
        None,
    );
    let luma = std::fs::read(&raw).expect("raw frame");
    let at = |x: usize, y: usize| i32::from(luma[y * 66 + x]);
    for y in [0, 20, 48] {
        assert!(
            (at(65, y) - at(64, y)).abs() <= 3,
            "row {y}: {} {}",
            at(64, y),
            at(65, y)
        );
    }
    for x in [0, 30, 64] {
        assert!((at(x, 49) - at(x, 48)).abs() <= 3, "column {x}");
    }
    assert_temporaries_gone(dir.path());
    if has_encoder(
        "ffv1",
        "odd_size_420_is_padded_for_x264_and_kept_for_ffv1 (ffv1)",
    ) {
        let out = dir.path().join("odd.mkv");
        let run = run_ok(video_cmd(&input, &out).args(["--no-correct", "--codec", "ffv1"]));
        assert!(!String::from_utf8_lossy(&run.stderr).contains("padded"));
        assert_eq!(video_size(&out), ("ffv1".into(), 65.0, 49.0));
    }
}

fn assert_temporaries_gone(dir: &Path) {
    assert_eq!(temporaries(dir), Vec::<String>::new());
}

/// An FFV1 input is written as FFV1 (lossless, as it came) by default, not re-encoded with
/// libx264; its odd size is kept.
#[test]
fn ffv1_input_keeps_its_codec() {
    let Some(dir) = ffmpeg_test_dir("ffv1", "ffv1_input_keeps_its_codec") else {
        return;
    };
    let y4m = dir.path().join("odd.y4m");
    std::fs::write(&y4m, odd_y4m()).expect("write y4m");
    let input = dir.path().join("odd420.mkv");
    ffmpeg(&["-i", path(&y4m), "-c:v", "ffv1", path(&input)], None);
    let out = dir.path().join("out.mkv");
    let run = run_ok(video_cmd(&input, &out).arg("--no-correct"));
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(stderr.contains("video ffv1"), "{stderr}");
    assert_eq!(video_size(&out), ("ffv1".into(), 65.0, 49.0));
}

/// `-o` into folders that do not exist yet: they are created, for a video file as for y4m.
#[test]
fn missing_output_folders_are_created() {
    let Some(dir) = ffmpeg_test_dir("libx264", "missing_output_folders_are_created") else {
        return;
    };
    let input = dir.path().join("in.y4m");
    std::fs::write(&input, y4m8(&frames()[..3])).expect("write y4m");
    let out = dir.path().join("nd/x/out.mp4");
    run_ok(video_cmd(&input, &out).arg("--no-correct"));
    assert_eq!(video_size(&out).0, "h264");
    assert_temporaries_gone(&dir.path().join("nd/x"));
}

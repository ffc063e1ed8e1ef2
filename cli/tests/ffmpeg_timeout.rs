//! `--ffmpeg-timeout`: an `ffprobe` that never answers, a decoder that never sends a frame and
//! an encoder that never reads one each fail the run with a message naming the stall, instead
//! of holding it for ever, and leave no output. The programs are stand-in shell scripts (Unix
//! only), so these tests need no FFmpeg.

#![cfg(unix)]

use std::os::unix::fs::PermissionsExt;
use std::path::Path;
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use image::GrayImage;
use unshear::video::y4m::Y4mWriter;
use unshear::video::{Chroma, VideoFormat, YuvFrame};

/// What the stand-in ffprobe prints: one 64x48 H.264 stream at 25 fps.
const PROBE: &str = r#"{"streams": [{"index": 0, "codec_type": "video", "codec_name": "h264",
"width": 64, "height": 48, "pix_fmt": "yuv420p", "avg_frame_rate": "25/1",
"r_frame_rate": "25/1", "nb_frames": "3"}], "format": {"format_name": "mov,mp4,m4a,3gp,3g2,mj2",
"duration": "0.12"}}"#;

/// Writes an executable `/bin/sh` script.
fn script(path: &Path, body: &str) {
    std::fs::write(path, format!("#!/bin/sh\n{body}\n")).expect("write script");
    std::fs::set_permissions(path, std::fs::Permissions::from_mode(0o755)).expect("chmod");
}

/// Stand-ins in `dir`: `ffmpeg` answers the option and encoder listings at once and runs
/// `decode` or `encode` (shell commands) for the two pipes; `ffprobe` runs `probe`.
fn stand_ins(dir: &Path, probe: &str, decode: &str, encode: &str) {
    script(&dir.join("ffprobe"), probe);
    let ffmpeg = format!(
        r#"case "$*" in
  *-encoders*) echo " V....D libx264   H.264"; exit 0 ;;
  *"-h long"*) exit 0 ;;
  *"yuv4mpegpipe -i -"*) {encode} ;;
  *) {decode} ;;
esac"#
    );
    script(&dir.join("ffmpeg"), &ffmpeg);
}

/// A 40-frame 64x48 y4m stream (185 KB, more than a pipe holds).
fn y4m(path: &Path) {
    let format = VideoFormat {
        width: 64,
        height: 48,
        chroma: Chroma::Yuv420,
        full_range: false,
        frame_rate: (25, 1),
        bit_depth: 8,
    };
    let mut w = Y4mWriter::new(Vec::new(), &format).expect("header");
    for i in 0..40u8 {
        let mut f = YuvFrame::blank(&format);
        f.y = GrayImage::from_pixel(64, 48, image::Luma([40 + 4 * i]));
        w.write_frame(&f).expect("frame");
    }
    std::fs::write(path, w.finish().expect("flush")).expect("write y4m");
}

/// Runs `unshear video in.mp4 [-o out.mp4] --ffmpeg-timeout 1` with the stand-ins of `dir`;
/// fails the test if the run is still going after a minute (the stand-ins sleep 120 s).
fn run(dir: &Path, output: bool) -> (Output, Duration) {
    let input = dir.join("in.mp4");
    std::fs::write(&input, b"not read: the stand-ins play ffmpeg").expect("input");
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_unshear"));
    cmd.arg("video").arg(&input);
    if output {
        cmd.arg("-o").arg(dir.join("out.mp4"));
    }
    cmd.arg("--ffmpeg")
        .arg(dir.join("ffmpeg"))
        .args(["--ffmpeg-timeout", "1"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped());
    let start = Instant::now();
    let mut child = cmd.spawn().expect("unshear");
    while child.try_wait().expect("wait").is_none() {
        if start.elapsed() > Duration::from_secs(60) {
            let _ = child.kill();
            panic!("unshear video still waiting on a stuck ffmpeg after 60 s");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    (child.wait_with_output().expect("output"), start.elapsed())
}

/// Asserts a failed run whose message names the stalled step, and no output left behind.
fn assert_stalled(dir: &Path, (out, took): (Output, Duration), step: &str) {
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains(&format!("ffmpeg made no progress {step}"))
            && stderr.contains("--ffmpeg-timeout"),
        "{stderr}"
    );
    // Stopped by the timeout, not by the stand-in's own end after 120 s.
    assert!(took < Duration::from_secs(60), "{took:?}");
    let left: Vec<String> = std::fs::read_dir(dir)
        .expect("list")
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("out") || n.starts_with(".unshear-"))
        .collect();
    assert!(left.is_empty(), "{left:?}");
}

#[test]
fn a_probe_that_never_answers_is_stopped() {
    let dir = tempfile::tempdir().expect("temp dir");
    stand_ins(
        dir.path(),
        "exec sleep 120",
        "exec sleep 120",
        "exec sleep 120",
    );
    assert_stalled(dir.path(), run(dir.path(), true), "probing");
}

#[test]
fn a_decoder_that_never_sends_a_frame_is_stopped() {
    let dir = tempfile::tempdir().expect("temp dir");
    let probe = format!("cat <<'EOF'\n{PROBE}\nEOF");
    stand_ins(dir.path(), &probe, "exec sleep 120", "exec sleep 120");
    assert_stalled(dir.path(), run(dir.path(), false), "decoding");
}

#[test]
fn an_encoder_that_never_reads_is_stopped() {
    let dir = tempfile::tempdir().expect("temp dir");
    let frames = dir.path().join("frames.y4m");
    y4m(&frames);
    let probe = format!("cat <<'EOF'\n{PROBE}\nEOF");
    // The decoder sends its frames; the encoder neither reads them nor ends, so its pipe
    // fills (a pipe holds 64 KB) or its end is awaited for ever.
    let decode = format!("exec cat '{}'", frames.display());
    stand_ins(dir.path(), &probe, &decode, "exec sleep 120");
    assert_stalled(dir.path(), run(dir.path(), true), "encoding");
}

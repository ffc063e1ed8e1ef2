//! `unshear simulate`: a small clip from the Yale fixtures, its y4m frames and its truth lines,
//! frame folders, refusals and usage errors.

mod common;

use assert_cmd::Command;
use common::fixture;
use unshear::video::y4m::Y4mReader;

fn unshear() -> Command {
    Command::cargo_bin("unshear").expect("binary built")
}

const SMALL: [&str; 8] = [
    "--width", "320", "--height", "240", "--frames", "12", "--seed", "3",
];

/// 12 frames of 320x240 (y4m, 4:2:0, 30 fps) from two fixtures, with an accelerating pan and
/// blur; 12 truth lines whose k is rho * vx / H at the middle row, whose 240 row offsets are 0
/// at the middle row, and whose `accelerate` velocity is V sin(2 pi t / 8).
#[test]
fn simulate_writes_a_y4m_clip_and_its_truth() {
    let dir = tempfile::tempdir().unwrap();
    let clip = dir.path().join("clip.y4m");
    let truth = dir.path().join("truth.jsonl");
    unshear()
        .arg("simulate")
        .arg(fixture("subject01.normal.jpeg"))
        .arg(fixture("subject03.normal.jpeg"))
        .args(SMALL)
        .args([
            "--motion",
            "accelerate",
            "--speed",
            "40",
            "--readout-fraction",
            "0.9",
        ])
        .arg("-o")
        .arg(&clip)
        .arg("--truth")
        .arg(&truth)
        .assert()
        .success();

    let mut reader = Y4mReader::new(std::fs::File::open(&clip).unwrap(), u64::MAX).unwrap();
    let format = reader.format().clone();
    assert_eq!((format.width, format.height), (320, 240));
    assert_eq!(format.frame_rate, (30, 1));
    let mut frames = 0;
    while reader.read_frame().unwrap().is_some() {
        frames += 1;
    }
    assert_eq!(frames, 12);

    let lines = common::json_lines(&std::fs::read(&truth).unwrap());
    assert_eq!(lines.len(), 12);
    for (n, l) in lines.iter().enumerate() {
        assert_eq!(l["frame"], n as u64);
        assert_eq!(l["motion"], "accelerate");
        assert_eq!(l["readout_fraction"], 0.9);
        assert_eq!(l["fps"], 30.0);
        // 4 ms at 30 fps.
        assert!((l["exposure"].as_f64().unwrap() - 0.12).abs() < 1e-12);
        let t = l["time"].as_f64().unwrap();
        assert!((t - (n as f64 + 0.45)).abs() < 1e-12);
        let vx = l["velocity"][0].as_f64().unwrap();
        assert!((vx - 40.0 * (std::f64::consts::TAU * t / 8.0).sin()).abs() < 1e-9);
        let k = l["k"].as_f64().unwrap();
        assert!((k - 0.9 * vx / 240.0).abs() < 1e-12);
        let rows = l["row_offsets"].as_array().unwrap();
        assert_eq!(rows.len(), 240);
        assert_eq!(rows[120].as_f64().unwrap(), 0.0);
        assert!(l.get("row_offsets_y").is_none());
        assert!(
            l["faces"].as_array().unwrap().is_empty(),
            "plain photos have no known faces"
        );
    }

    // Never over an existing output without --force; with it, replaced.
    let again = || {
        let mut c = unshear();
        c.arg("simulate")
            .arg(fixture("subject01.normal.jpeg"))
            .args(SMALL)
            .arg("-o")
            .arg(&clip)
            .arg("--truth")
            .arg(&truth);
        c
    };
    again()
        .assert()
        .code(1)
        .stderr(predicates::str::contains("use --force"));
    again().arg("--force").assert().success();
    // Never over an input, even with --force.
    unshear()
        .arg("simulate")
        .arg(fixture("subject01.normal.jpeg"))
        .args(SMALL)
        .arg("-o")
        .arg(dir.path().join("c2.y4m"))
        .arg("--truth")
        .arg(fixture("subject01.normal.jpeg"))
        .arg("--force")
        .assert()
        .code(1)
        .stderr(predicates::str::contains("input file"));
}

/// A folder of numbered PNG frames, with vertical motion (row_offsets_y in the truth).
#[test]
fn simulate_writes_a_frame_folder() {
    let dir = tempfile::tempdir().unwrap();
    let frames = dir.path().join("frames");
    let truth = dir.path().join("t.jsonl");
    unshear()
        .arg("simulate")
        .arg(fixture("subject14.normal.jpeg"))
        .args(["--width", "160", "--height", "120", "--frames", "3"])
        .args([
            "--motion",
            "shaky",
            "--peak-k",
            "0.2",
            "--vertical-motion",
            "pause",
        ])
        .arg("-o")
        .arg(&frames)
        .arg("--truth")
        .arg(&truth)
        .assert()
        .success();
    for n in 0..3 {
        let img = image::open(frames.join(format!("00000{n}.png"))).unwrap();
        assert_eq!((img.width(), img.height()), (160, 120));
    }
    assert!(!frames.join("000003.png").exists());
    let lines = common::json_lines(&std::fs::read(&truth).unwrap());
    assert_eq!(lines.len(), 3);
    assert_eq!(lines[0]["row_offsets_y"].as_array().unwrap().len(), 120);
}

/// Out-of-range values are usage errors (exit 2), before anything is written.
#[test]
fn simulate_refuses_bad_values_as_usage_errors() {
    let dir = tempfile::tempdir().unwrap();
    let clip = dir.path().join("c.y4m");
    for bad in [
        &["--readout-fraction", "1.5"][..],
        &["--readout-fraction", "0"],
        &["--exposure", "2"],
        &["--speed", "nan"],
        &["--noise", "-1"],
        &["--width", "0"],
        &["--vertical-motion", "walk"],
        &["--speed", "3", "--peak-k", "0.1"],
        &["--faces", "2"],
    ] {
        unshear()
            .arg("simulate")
            .arg(fixture("subject01.normal.jpeg"))
            .args(bad)
            .arg("-o")
            .arg(&clip)
            .assert()
            .code(2);
        assert!(!clip.exists(), "{bad:?}");
    }
    // Neither photos nor --caltech.
    unshear()
        .args(["simulate", "-o"])
        .arg(&clip)
        .assert()
        .code(2);
}

//! `correct --deblur`: a still's motion blur along its rows found from the zeros it leaves in
//! their spectrum (or given with `--blur`) and removed before the shear is undone.

mod common;

use std::path::{Path, PathBuf};

use assert_cmd::Command;
use image::RgbImage;

fn unshear() -> Command {
    Command::cargo_bin("unshear").expect("binary built")
}

fn example() -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/..")).join("assets/example/face-k0.30.png")
}

/// The example (a face sheared by 0.30) with each row averaged over `length` pixels (a box
/// centred on each pixel, the edges repeated), as a pan during the exposure smears it.
fn blurred(dir: &Path, length: u32) -> PathBuf {
    let img = image::open(example()).expect("example").to_rgb8();
    let (w, h) = img.dimensions();
    let half = i64::from(length / 2);
    let out = RgbImage::from_fn(w, h, |x, y| {
        let mut sum = [0u32; 3];
        for j in -half..=half {
            let xs = (i64::from(x) + j).clamp(0, i64::from(w) - 1) as u32;
            for (s, v) in sum.iter_mut().zip(img.get_pixel(xs, y).0) {
                *s += u32::from(v);
            }
        }
        let n = 2 * half as u32 + 1;
        image::Rgb(sum.map(|s| ((s + n / 2) / n) as u8))
    });
    let path = dir.join(format!("blur{length}.png"));
    out.save(&path).expect("written");
    path
}

/// Mean absolute difference of two images' inner parts (the edges take the warp's fill).
fn difference(a: &Path, b: &Path) -> f64 {
    let (a, b) = (
        image::open(a).expect("a").to_rgb8(),
        image::open(b).expect("b").to_rgb8(),
    );
    let (w, h) = a.dimensions();
    let mut sum = 0.0;
    let mut n = 0.0;
    for y in 20..h - 20 {
        for x in 40..w - 40 {
            for (p, q) in a.get_pixel(x, y).0.iter().zip(b.get_pixel(x, y).0) {
                sum += (f64::from(*p) - f64::from(q)).abs();
                n += 1.0;
            }
        }
    }
    sum / n
}

#[test]
fn a_stills_motion_blur_is_found_and_removed() {
    let dir = tempfile::tempdir().expect("temp dir");
    let reference = dir.path().join("ref.png");
    unshear()
        .args(["correct", "--k", "0.316", "-o"])
        .arg(&reference)
        .arg(example())
        .assert()
        .success();
    for length in [7, 15] {
        let input = blurred(dir.path(), length);
        let plain = dir.path().join(format!("plain{length}.png"));
        unshear()
            .args(["correct", "--k", "0.316", "-o"])
            .arg(&plain)
            .arg(&input)
            .assert()
            .success();
        let sharp = dir.path().join(format!("sharp{length}.png"));
        let out = unshear()
            .args(["correct", "--deblur", "--json", "-o"])
            .arg(&sharp)
            .arg(&input)
            .assert()
            .success();
        let line = &common::json_lines(&out.get_output().stdout)[0];
        let blur = line["blur"].as_f64().expect("blur found");
        assert!((blur - f64::from(length)).abs() <= 0.5, "{length}: {blur}");
        let k = line["k"].as_f64().expect("k");
        // Read within 0.03 of the sharp example's 0.3175 (measured: 0.317 at 7 px, 0.342 at
        // 15 px, a seventh of the face's width).
        assert!((k - 0.3175).abs() < 0.03, "{k}");
        // Corrected by the same k, the deblurred picture is nearer the unblurred one (measured:
        // +3 to +4 dB PSNR on this face, docs/cli.md).
        let given = dir.path().join(format!("given{length}.png"));
        unshear()
            .args(["correct", "--k", "0.316", "--deblur", "-o"])
            .arg(&given)
            .arg(&input)
            .assert()
            .success();
        let (before, after) = (
            difference(&plain, &reference),
            difference(&given, &reference),
        );
        assert!(after < 0.8 * before, "{length}: {before:.2} -> {after:.2}");
    }
    // The sharp example shows no blur: nothing is removed, and the JSON says nothing of it.
    let out = unshear()
        .args(["correct", "--deblur", "--json", "-o"])
        .arg(dir.path().join("example.png"))
        .arg(example())
        .assert()
        .success();
    assert!(common::json_lines(&out.get_output().stdout)[0]
        .get("blur")
        .is_none());
}

#[test]
fn a_given_blur_is_checked() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("out.png");
    for bad in [
        vec!["--blur", "10"],
        vec!["--deblur", "--blur", "0.5"],
        vec!["--deblur", "--blur", "300"],
    ] {
        unshear()
            .arg("correct")
            .args(&bad)
            .arg("-o")
            .arg(&out)
            .arg(example())
            .assert()
            .code(2);
    }
    let json = unshear()
        .args(["correct", "--deblur", "--blur", "12", "--json", "-o"])
        .arg(&out)
        .arg(example())
        .assert()
        .success();
    let line = &common::json_lines(&json.get_output().stdout)[0];
    assert_eq!(line["blur"].as_f64(), Some(12.0));
}

//! Where `correct` writes: the output folder is not read back, outputs that collide are refused,
//! names that are not UTF-8 keep their bytes, inputs that are not files need `-o`; and the
//! messages and usage errors around them.

mod common;

use common::{fixture, json_lines};

use std::path::Path;

use assert_cmd::Command;

fn unshear() -> Command {
    Command::cargo_bin("unshear").expect("binary built")
}

fn copy(from: &str, to: &Path) {
    if let Some(parent) = to.parent() {
        std::fs::create_dir_all(parent).expect("mkdir");
    }
    std::fs::copy(fixture(from), to).expect("copy");
}

fn stderr_of(out: &std::process::Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// An `--out-dir` inside the folder corrected is not walked: a second run refreshes the
/// outputs instead of correcting the corrections into `fixed/fixed/`.
#[test]
fn out_dir_inside_an_input_folder_is_not_read_back() {
    let dir = tempfile::tempdir().expect("temp");
    let shoot = dir.path().join("shoot");
    copy("subject01.normal.jpeg", &shoot.join("a.jpeg"));
    let fixed = shoot.join("fixed");
    for force in [false, true] {
        let mut cmd = unshear();
        cmd.arg("correct")
            .arg(&shoot)
            .arg("--out-dir")
            .arg(&fixed)
            .arg("--json");
        if force {
            cmd.arg("--force");
        }
        let out = cmd.assert().success().get_output().clone();
        assert_eq!(json_lines(&out.stdout).len(), 1, "{}", stderr_of(&out));
    }
    assert!(fixed.join("a.jpeg").is_file());
    assert!(
        !fixed.join("fixed").exists(),
        "the output folder was read back"
    );
}

/// Two inputs with one output: the first in input order wins, the later one fails naming both
/// (exit 1), with or without --force; the same file given twice is processed once.
#[test]
fn colliding_outputs_fail_the_later_input() {
    let dir = tempfile::tempdir().expect("temp");
    let (x, y) = (dir.path().join("x"), dir.path().join("y"));
    copy("subject01.normal.jpeg", &x.join("a.jpeg"));
    copy("subject03.normal.jpeg", &y.join("a.jpeg"));
    let col = dir.path().join("col");
    for (force, inputs) in [
        (false, [x.join("a.jpeg"), y.join("a.jpeg")]),
        (true, [x.clone(), y.clone()]),
    ] {
        let mut cmd = unshear();
        cmd.arg("correct")
            .args(&inputs)
            .arg("--out-dir")
            .arg(&col)
            .arg("--json");
        if force {
            cmd.arg("--force");
        }
        let out = cmd.assert().code(1).get_output().clone();
        let lines = json_lines(&out.stdout);
        assert_eq!(lines.len(), 2);
        assert!(lines[0].get("error").is_none(), "the first input wins");
        let error = lines[1]["error"].as_str().expect("the second fails");
        assert!(
            error.contains(&x.join("a.jpeg").display().to_string()),
            "{error}"
        );
        let stderr = stderr_of(&out);
        assert!(
            stderr.contains(&y.join("a.jpeg").display().to_string()),
            "{stderr}"
        );
    }
    // The corrected x, not y: both are kept at the input's size, so compare with x's own run.
    let alone = dir.path().join("alone.jpeg");
    unshear()
        .arg("correct")
        .arg(x.join("a.jpeg"))
        .arg("-o")
        .arg(&alone)
        .assert()
        .success();
    assert_eq!(
        std::fs::read(col.join("a.jpeg")).expect("read"),
        std::fs::read(&alone).expect("read")
    );

    // The same file twice (two spellings): one input.
    let twice = unshear()
        .current_dir(&x)
        .args(["correct", "a.jpeg", "./a.jpeg", "--json", "--out-dir", "tw"])
        .assert()
        .success()
        .get_output()
        .clone();
    assert_eq!(json_lines(&twice.stdout).len(), 1);
}

/// The annotation and the corrected image at one path is a usage error, and nothing is written.
#[test]
fn annotate_at_the_output_path_is_a_usage_error() {
    let dir = tempfile::tempdir().expect("temp");
    let z = dir.path().join("z.png");
    let out = unshear()
        .arg("correct")
        .arg(fixture("subject01.normal.jpeg"))
        .arg("--annotate")
        .arg(&z)
        .arg("-o")
        .arg(dir.path().join(".").join("z.png"))
        .arg("--force")
        .assert()
        .code(2)
        .get_output()
        .clone();
    assert!(stderr_of(&out).contains("--annotate"));
    assert!(!z.exists());
}

/// Names that are not UTF-8 keep their bytes in the output name, so two such inputs do not
/// share an output.
#[cfg(target_os = "linux")]
#[test]
fn non_utf8_names_keep_their_bytes() {
    use std::ffi::OsStr;
    use std::os::unix::ffi::OsStrExt;
    let dir = tempfile::tempdir().expect("temp");
    let name = |bytes: &[u8]| dir.path().join(OsStr::from_bytes(bytes));
    for b in [b"a\xff.jpeg", b"a\xfe.jpeg"] {
        copy("subject01.normal.jpeg", &name(b));
    }
    unshear()
        .arg("correct")
        .arg(name(b"a\xff.jpeg"))
        .arg(name(b"a\xfe.jpeg"))
        .assert()
        .success();
    assert!(name(b"a\xff.unshear.jpeg").is_file());
    assert!(name(b"a\xfe.unshear.jpeg").is_file());
    // A folder run skips those outputs too (their stems end in `.unshear` as bytes): two
    // inputs, not four, and no `.unshear.unshear` file.
    let out = unshear()
        .arg("correct")
        .arg(dir.path())
        .arg("--json")
        .arg("--force")
        .assert()
        .success()
        .get_output()
        .clone();
    assert_eq!(json_lines(&out.stdout).len(), 2, "{}", stderr_of(&out));
    assert!(!name(b"a\xff.unshear.unshear.jpeg").exists());
}

/// An input whose name has no extension, or one that is only read (`.pbm`), or a pipe, gets a
/// PNG output, with or without `--out-dir`, instead of failing for its output's format.
#[cfg(target_os = "linux")]
#[test]
fn inputs_without_a_written_extension_get_png_outputs() {
    let dir = tempfile::tempdir().expect("temp");
    let noext = dir.path().join("in").join("noext");
    copy("subject01.normal.jpeg", &noext);
    let face = image::open(fixture("subject01.normal.jpeg")).expect("open");
    let pbm = dir.path().join("in").join("face.pbm");
    face.to_luma8().save(&pbm).expect("pbm");
    for input in [&noext, &pbm] {
        unshear()
            .arg("correct")
            .arg(input)
            .args(["--k", "0.2"])
            .assert()
            .success();
    }
    assert!(dir.path().join("in/noext.unshear.png").is_file());
    assert!(dir.path().join("in/face.unshear.png").is_file());
    let out_dir = dir.path().join("out");
    unshear()
        .arg("correct")
        .arg(&noext)
        .arg(&pbm)
        .arg("--out-dir")
        .arg(&out_dir)
        .args(["--k", "0.2"])
        .assert()
        .success();
    assert!(out_dir.join("noext.png").is_file());
    assert!(out_dir.join("face.png").is_file());
    // A pipe with --out-dir, as its error message offers.
    let link = dir.path().join("stdin");
    std::os::unix::fs::symlink("/dev/stdin", &link).expect("link");
    unshear()
        .arg("correct")
        .arg(&link)
        .arg("--out-dir")
        .arg(&out_dir)
        .write_stdin(std::fs::read(fixture("subject01.normal.jpeg")).expect("read"))
        .assert()
        .success();
    assert!(out_dir.join("stdin.png").is_file());
}

/// A run refused because its output exists writes no annotation either: every output is
/// checked before any work.
#[test]
fn an_existing_output_leaves_the_annotation_unwritten() {
    let dir = tempfile::tempdir().expect("temp");
    let input = dir.path().join("face.jpeg");
    copy("subject01.normal.jpeg", &input);
    let (out, note) = (dir.path().join("out.png"), dir.path().join("note.png"));
    std::fs::write(&out, b"kept").expect("write");
    let run = unshear()
        .arg("correct")
        .arg(&input)
        .arg("-o")
        .arg(&out)
        .arg("--annotate")
        .arg(&note)
        .assert()
        .code(1)
        .get_output()
        .clone();
    assert!(stderr_of(&run).contains("--force"), "{}", stderr_of(&run));
    assert!(!note.exists());
    assert_eq!(std::fs::read(&out).expect("read"), b"kept");
}

/// Negative numbers reach the range checks (exit 2 with the range named) instead of being
/// taken for flags; a negative shear is valid.
#[test]
fn negative_numbers_get_the_range_message() {
    for (flag, value, says) in [
        ("--min-confidence", "-0.1", "0 to 1"),
        ("--jobs", "-1", "--jobs"),
        ("--max-crops", "-2", "--max-crops"),
    ] {
        let out = unshear()
            .args(["estimate", flag, value])
            .arg(fixture("subject01.normal.jpeg"))
            .assert()
            .code(2)
            .get_output()
            .clone();
        let stderr = stderr_of(&out);
        assert!(!stderr.contains("unexpected argument"), "{stderr}");
        assert!(stderr.contains(says), "{flag}: {stderr}");
    }
    let dir = tempfile::tempdir().expect("temp");
    unshear()
        .args(["correct", "--k", "-0.3", "-o"])
        .arg(dir.path().join("neg.png"))
        .arg(fixture("subject01.normal.jpeg"))
        .assert()
        .success();
}

/// An `--out-dir` that is a file is named as not a folder (exit 2, before any work).
#[test]
fn out_dir_that_is_a_file_is_not_a_folder() {
    let dir = tempfile::tempdir().expect("temp");
    let afile = dir.path().join("afile");
    std::fs::write(&afile, b"x").expect("write");
    let out = unshear()
        .arg("correct")
        .arg(fixture("subject01.normal.jpeg"))
        .arg("--out-dir")
        .arg(&afile)
        .assert()
        .code(2)
        .get_output()
        .clone();
    assert!(
        stderr_of(&out).contains("not a folder"),
        "{}",
        stderr_of(&out)
    );
}

/// With --annotate and no face, the message says the annotation was written.
#[test]
fn no_face_with_annotate_says_the_annotation_was_written() {
    let dir = tempfile::tempdir().expect("temp");
    let blank = dir.path().join("blank.png");
    image::GrayImage::from_pixel(120, 90, image::Luma([90]))
        .save(&blank)
        .expect("save");
    let ann = dir.path().join("ann.png");
    let out = unshear()
        .arg("correct")
        .arg(&blank)
        .arg("--annotate")
        .arg(&ann)
        .assert()
        .success()
        .get_output()
        .clone();
    let stderr = stderr_of(&out);
    assert!(ann.is_file());
    assert!(!dir.path().join("blank.unshear.png").exists());
    assert!(
        stderr.contains("only the annotation") && !stderr.contains("nothing written"),
        "{stderr}"
    );
}

/// An input that is not a regular file (here a link to /dev/stdin, a pipe) has no folder to
/// write beside: without -o it fails asking for -o; with -o it is read.
#[cfg(target_os = "linux")]
#[test]
fn a_pipe_needs_an_output_path() {
    let dir = tempfile::tempdir().expect("temp");
    let link = dir.path().join("in.jpeg");
    std::os::unix::fs::symlink("/dev/stdin", &link).expect("link");
    let face = std::fs::read(fixture("subject01.normal.jpeg")).expect("read");
    let out = unshear()
        .arg("correct")
        .arg(&link)
        .write_stdin(face.clone())
        .assert()
        .code(1)
        .get_output()
        .clone();
    assert!(stderr_of(&out).contains("-o OUT"), "{}", stderr_of(&out));
    assert!(!dir.path().join("in.unshear.jpeg").exists());
    let fixed = dir.path().join("fixed.png");
    unshear()
        .arg("correct")
        .arg(&link)
        .arg("-o")
        .arg(&fixed)
        .write_stdin(face)
        .assert()
        .success();
    assert!(fixed.is_file());
}

/// `-` is standard input for `video` only: for stills it is a usage error saying so.
#[test]
fn dash_for_stills_is_a_usage_error() {
    for command in ["estimate", "correct"] {
        let out = unshear()
            .args([command, "-"])
            .assert()
            .code(2)
            .get_output()
            .clone();
        assert!(
            stderr_of(&out).contains("video only"),
            "{}",
            stderr_of(&out)
        );
    }
}

/// The corrected photo keeps the input's colour profile and EXIF block, whatever format it is
/// written in that stores them.
#[test]
fn corrected_photos_keep_their_profile_and_exif() {
    use image::ImageEncoder;
    let dir = tempfile::tempdir().expect("temp");
    let face = image::open(fixture("subject01.normal.jpeg")).expect("fixture");
    // A made-up RGB profile (only its header's colour space is looked at) and an EXIF block
    // holding an upright orientation tag (big-endian TIFF, one entry).
    let mut profile: Vec<u8> = (0..=255).collect();
    profile[16..20].copy_from_slice(b"RGB ");
    let mut exif = b"MM\x00\x2a\x00\x00\x00\x08\x00\x01".to_vec();
    exif.extend_from_slice(&[0x01, 0x12, 0, 3, 0, 0, 0, 1, 0, 1, 0, 0, 0, 0, 0, 0]);
    let input = dir.path().join("in.jpg");
    let mut jpeg = Vec::new();
    let mut encoder = image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpeg, 95);
    encoder.set_icc_profile(profile.clone()).expect("icc");
    encoder.set_exif_metadata(exif.clone()).expect("exif");
    let rgb = face.to_rgb8();
    encoder
        .write_image(
            &rgb,
            rgb.width(),
            rgb.height(),
            image::ExtendedColorType::Rgb8,
        )
        .expect("encode");
    std::fs::write(&input, jpeg).expect("write");
    for name in ["out.jpg", "out.png", "out.webp"] {
        let out = dir.path().join(name);
        unshear()
            .arg("correct")
            .arg(&input)
            .args(["--k", "0.1", "-o"])
            .arg(&out)
            .assert()
            .success();
        let (_, meta) = unshear::imageio::read_image_with_metadata(&out, 1 << 24).expect("read");
        assert_eq!(meta.icc_profile.as_ref(), Some(&profile), "{name}");
        assert_eq!(meta.exif.as_ref(), Some(&exif), "{name}");
    }
}

/// A JPEG of `img` whose EXIF block holds `orientation` (big-endian TIFF, one entry).
fn jpeg_with_orientation(img: &image::RgbImage, orientation: u8, path: &Path) {
    use image::ImageEncoder;
    let mut exif = b"MM\x00\x2a\x00\x00\x00\x08\x00\x01".to_vec();
    exif.extend_from_slice(&[
        0x01,
        0x12,
        0,
        3,
        0,
        0,
        0,
        1,
        0,
        orientation,
        0,
        0,
        0,
        0,
        0,
        0,
    ]);
    let mut jpeg = Vec::new();
    let mut encoder = image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpeg, 95);
    encoder.set_exif_metadata(exif).expect("exif");
    encoder
        .write_image(
            img,
            img.width(),
            img.height(),
            image::ExtendedColorType::Rgb8,
        )
        .expect("encode");
    std::fs::write(path, jpeg).expect("write");
}

/// A picture its EXIF orientation turns a quarter (a phone held upright) was read out column
/// by column, so a pan skews it vertically: its faces are found upright, the vertical shear is
/// measured (`"readout": "columns"`) and undone along the columns. Turned by half (180
/// degrees), rows stay rows, and the same picture sheared along its rows reads as usual.
#[test]
fn pictures_turned_a_quarter_are_corrected_along_their_columns() {
    use image::DynamicImage;
    let dir = tempfile::tempdir().expect("temp");
    let face = image::open(fixture("subject01.normal.jpeg")).expect("fixture");
    let (w, h) = (face.width(), face.height());
    // The face on a wider grey canvas, so that a vertical shear keeps it inside.
    let mut wide = image::RgbImage::from_pixel(w + 160, h, image::Rgb([128, 128, 128]));
    image::imageops::overlay(&mut wide, &face.to_rgb8(), 80, 0);
    let wide = DynamicImage::ImageRgb8(wide);
    let shear = |img: &DynamicImage, k: f64| {
        unshear::warp::apply_shear(
            img,
            unshear::Shear::about_middle(k, img.height()),
            unshear::warp::Interpolation::Linear,
            unshear::warp::Canvas::Same,
        )
        .0
    };
    let transpose = |img: &DynamicImage| img.rotate90().fliph();
    // Upright as shown, sheared by 0.3 along the shown columns, and along the rows.
    let vertical = transpose(&shear(&transpose(&wide), 0.3)).to_rgb8();
    let horizontal = shear(&wide, 0.3).to_rgb8();
    let cases = [
        // 6: turned 90 degrees clockwise for display; the file holds it turned back.
        ("quarter.jpg", 6, image::imageops::rotate270(&vertical)),
        ("half.jpg", 3, image::imageops::rotate180(&horizontal)),
    ];
    for (name, orientation, stored) in &cases {
        jpeg_with_orientation(stored, *orientation, &dir.path().join(name));
    }
    let estimate = |name: &str| {
        let out = unshear()
            .args(["estimate", "--json"])
            .arg(dir.path().join(name))
            .assert()
            .success()
            .get_output()
            .clone();
        json_lines(&out.stdout).remove(0)
    };
    for name in ["half.jpg", "quarter.jpg"] {
        let line = estimate(name);
        let k = line["k"].as_f64().expect("measured");
        assert!((k - 0.3).abs() < 0.05, "{line}");
        assert_eq!(line["faces"].as_array().map(Vec::len), Some(1), "{line}");
        let columns = name == "quarter.jpg";
        assert_eq!(line.get("readout").is_some(), columns, "{line}");
        if columns {
            assert_eq!(line["readout"], "columns");
            assert!(line["warnings"].to_string().contains("column by column"));
        }
    }
    let out = dir.path().join("quarter.fixed.png");
    let run = unshear()
        .arg("correct")
        .arg(dir.path().join("quarter.jpg"))
        .arg("-o")
        .arg(&out)
        .assert()
        .success()
        .get_output()
        .clone();
    let said = String::from_utf8_lossy(&run.stdout);
    assert!(said.contains("along the columns"), "{said}");
    // Back to the upright face, to within two resamplings and JPEG's loss (grey levels, mean
    // over the face); the input was far off.
    let fixed = image::open(&out).expect("written").to_rgb8();
    let wide = wide.to_rgb8();
    let off = |img: &image::RgbImage| {
        let (mut sum, mut n) = (0.0, 0.0);
        for y in 40..h - 40 {
            for x in 100..w + 60 {
                let (a, b) = (img.get_pixel(x, y), wide.get_pixel(x, y));
                sum += (0..3)
                    .map(|c| (f64::from(a[c]) - f64::from(b[c])).abs())
                    .sum::<f64>()
                    / 3.0;
                n += 1.0;
            }
        }
        sum / n
    };
    assert_eq!(fixed.dimensions(), wide.dimensions());
    assert!(off(&fixed) < 6.0, "{}", off(&fixed));
    assert!(off(&vertical) > 12.0, "{}", off(&vertical));
}

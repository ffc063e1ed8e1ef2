//! The `unshear eval` harness: the shear it applies is exactly `unshear distort`'s, and the
//! evaluations run end to end on the development data when `../shared/data` exists (each such
//! test prints "skipped: ..." and passes when it does not).

use assert_cmd::Command;
use unshear::warp::{try_apply_shear, Canvas, Interpolation};
use unshear::{imageio, Shear};

mod common;
use common::{fixture, shared_data as shared};

fn unshear() -> Command {
    Command::cargo_bin("unshear").expect("binary built")
}

#[test]
fn harness_shear_matches_unshear_distort() {
    let dir = tempfile::tempdir().expect("tempdir");
    let input = fixture("subject03.normal.jpeg");
    let img = imageio::read_image(&input, imageio::DEFAULT_MAX_PIXELS).expect("fixture");
    for k in [0.33, -0.2] {
        let out = dir.path().join(format!("d{k}.png"));
        unshear()
            .args(["distort", "--canvas", "expand", "--k", &k.to_string(), "-o"])
            .arg(&out)
            .arg(&input)
            .assert()
            .success();
        let cli = imageio::read_image(&out, imageio::DEFAULT_MAX_PIXELS).expect("output");
        // Exactly what `eval shear` and `eval recognition` do to each image.
        let shear = Shear::about_middle(k, img.height());
        let (ours, _) =
            try_apply_shear(&img, shear, Interpolation::Linear, Canvas::Expand).expect("shear");
        assert_eq!(
            (cli.width(), cli.height()),
            (ours.width(), ours.height()),
            "k = {k}"
        );
        assert_eq!(cli.to_rgb8().as_raw(), ours.to_rgb8().as_raw(), "k = {k}");
    }
}

#[test]
fn eval_shear_writes_its_report() {
    let Some(data) = shared("caltech-webfaces") else {
        return;
    };
    let dir = tempfile::tempdir().expect("tempdir");
    let out = unshear()
        .args(["eval", "shear", "--limit", "3", "--k", "0,0.2", "--data"])
        .arg(&data)
        .arg("--out")
        .arg(dir.path())
        .assert()
        .success();
    let md = String::from_utf8_lossy(&out.get_output().stdout).into_owned();
    assert!(md.contains("| +0.20 | 3 |"), "{md}");
    for f in [
        "samples.csv",
        "samples.json",
        "summary.md",
        "estimates.png",
        "errors.png",
    ] {
        assert!(dir.path().join(f).is_file(), "{f}");
    }
    let json: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("samples.json")).expect("json"),
    )
    .expect("valid JSON");
    assert_eq!(json.as_array().map(Vec::len), Some(6));
}

#[test]
fn eval_nostrils_reports_on_dlib_faces() {
    let Some(dir) = shared("dlib-example-faces/examples/faces") else {
        return;
    };
    let out = unshear()
        .args(["eval", "nostrils", "--xml"])
        .arg(dir.join("training_with_face_landmarks.xml"))
        .assert()
        .success();
    let md = String::from_utf8_lossy(&out.get_output().stdout).into_owned();
    assert!(md.contains("Faces: 18"), "{md}");
    assert!(md.contains("| nostrils |"), "{md}");
}

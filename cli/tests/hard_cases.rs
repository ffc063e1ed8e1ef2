//! Hard non-faces and hard faces, made here (issue 39, item 5): textures must give no accepted
//! shear, and faces cut by a border, covered, painted, drawn, shown on a screen or turned
//! sideways must give no accepted shear beyond the plausible bound, nor one far from the
//! truth. A wrong correction is worse than none.

use std::path::PathBuf;

use assert_cmd::Command;
use image::{imageops, DynamicImage, Rgb, RgbImage};
use unshear::config::DEFAULT_MAX_SHEAR;
use unshear::warp::{apply_shear, Canvas, Interpolation};
use unshear::{Config, ImageReport, Shear, Unshear};

mod common;

/// A tiny deterministic generator (xorshift), so the textures are the same on every run.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
}

fn noise(w: u32, h: u32, seed: u64) -> RgbImage {
    let mut r = Rng(seed);
    RgbImage::from_fn(w, h, |_, _| {
        let v = (r.unit() * 255.0) as u8;
        Rgb([v, v, v])
    })
}

/// Blurred noise tinted green: the texture that gave a "face" with `k = 0.397`.
fn blurred_green_noise(seed: u64) -> RgbImage {
    let n = imageops::blur(&noise(320, 240, seed), 2.5);
    RgbImage::from_fn(320, 240, |x, y| {
        let v = f64::from(n.get_pixel(x, y)[0]);
        Rgb([(v * 0.5) as u8, v.min(255.0) as u8, (v * 0.3) as u8])
    })
}

/// Woven fabric: two crossing sinusoids with a slow wobble.
fn fabric() -> RgbImage {
    RgbImage::from_fn(320, 240, |x, y| {
        let (fx, fy) = (f64::from(x), f64::from(y));
        let v = 128.0 + 50.0 * (fx * 0.8 + (fy * 0.05).sin() * 3.0).sin() + 40.0 * (fy * 0.7).sin();
        let v = v.clamp(0.0, 255.0) as u8;
        Rgb([v, v / 2, v / 3])
    })
}

/// Foliage: overlapping leaf-like ellipses of greens and dark gaps.
fn foliage(seed: u64) -> RgbImage {
    let mut r = Rng(seed);
    let mut img = RgbImage::from_pixel(320, 240, Rgb([20, 40, 15]));
    for _ in 0..400 {
        let (cx, cy) = (r.unit() * 340.0 - 10.0, r.unit() * 260.0 - 10.0);
        let (a, b) = (6.0 + r.unit() * 14.0, 3.0 + r.unit() * 6.0);
        let t = r.unit() * std::f64::consts::PI;
        let shade = 60.0 + r.unit() * 150.0;
        let (s, c) = t.sin_cos();
        for y in (cy - a).max(0.0) as u32..((cy + a).min(239.0) as u32) {
            for x in (cx - a).max(0.0) as u32..((cx + a).min(319.0) as u32) {
                let (dx, dy) = (f64::from(x) - cx, f64::from(y) - cy);
                let (u, v) = (c * dx + s * dy, -s * dx + c * dy);
                if (u / a).powi(2) + (v / b).powi(2) <= 1.0 {
                    img.put_pixel(
                        x,
                        y,
                        Rgb([(shade * 0.4) as u8, shade as u8, (shade * 0.2) as u8]),
                    );
                }
            }
        }
    }
    img
}

/// Grass: thin bright and dark blades leaning a little.
fn grass(seed: u64) -> RgbImage {
    let mut r = Rng(seed);
    let mut img = RgbImage::from_pixel(320, 240, Rgb([40, 90, 30]));
    for _ in 0..900 {
        let (x0, y0) = (r.unit() * 320.0, r.unit() * 240.0);
        let (len, lean) = (15.0 + r.unit() * 40.0, r.unit() * 0.6 - 0.3);
        let shade = 40.0 + r.unit() * 170.0;
        for i in 0..len as u32 {
            let (x, y) = (x0 + lean * f64::from(i), y0 - f64::from(i));
            if (0.0..320.0).contains(&x) && (0.0..240.0).contains(&y) {
                img.put_pixel(
                    x as u32,
                    y as u32,
                    Rgb([(shade * 0.5) as u8, shade as u8, 20]),
                );
            }
        }
    }
    img
}

fn fixture_face(name: &str) -> RgbImage {
    unshear::imageio::read_image(&common::fixture(name), unshear::imageio::DEFAULT_MAX_PIXELS)
        .expect("fixture")
        .to_rgb8()
}

fn sheared(img: &RgbImage, k: f64) -> RgbImage {
    let img = DynamicImage::ImageRgb8(img.clone());
    apply_shear(
        &img,
        Shear::about_middle(k, img.height()),
        Interpolation::Linear,
        Canvas::Same,
    )
    .0
    .to_rgb8()
}

/// The face moved so that about `cut` of its width or height lies beyond one border
/// (`side`: 0 left, 1 right, 2 top, 3 bottom), the uncovered part filled grey.
fn cut_by_border(face: &RgbImage, side: u32, cut: f64) -> RgbImage {
    let (w, h) = face.dimensions();
    // The fixture faces' eyes sit near the middle; their face spans about 40% of the width.
    let (dx, dy) = match side {
        0 => (-(f64::from(w) * (0.3 + 0.4 * cut)) as i64, 0),
        1 => ((f64::from(w) * (0.3 + 0.4 * cut)) as i64, 0),
        2 => (0, -(f64::from(h) * (0.25 + 0.5 * cut)) as i64),
        _ => (0, (f64::from(h) * (0.25 + 0.5 * cut)) as i64),
    };
    let mut out = RgbImage::from_pixel(w, h, Rgb([128, 128, 128]));
    imageops::overlay(&mut out, face, dx, dy);
    out
}

/// A block over the upper face (the eyes) or the lower face (nose and mouth).
fn covered(face: &RgbImage, eyes: bool) -> RgbImage {
    let mut out = face.clone();
    let (w, h) = face.dimensions();
    let (y0, y1) = if eyes { (0.33, 0.50) } else { (0.55, 0.80) };
    for y in (f64::from(h) * y0) as u32..(f64::from(h) * y1) as u32 {
        for x in (f64::from(w) * 0.3) as u32..(f64::from(w) * 0.72) as u32 {
            out.put_pixel(x, y, Rgb([30, 30, 200]));
        }
    }
    out
}

/// Face paint: bright patches on the forehead and cheeks, stripes under the eyes.
fn painted(face: &RgbImage) -> RgbImage {
    let mut out = face.clone();
    let (w, h) = face.dimensions();
    let mut r = Rng(7);
    for _ in 0..40 {
        let (cx, cy) = (
            f64::from(w) * (0.3 + 0.4 * r.unit()),
            f64::from(h) * (0.2 + 0.6 * r.unit()),
        );
        let colour = Rgb([(r.unit() * 255.0) as u8, (r.unit() * 255.0) as u8, 40]);
        for y in (cy - 5.0).max(0.0) as u32..(cy + 5.0).min(f64::from(h)) as u32 {
            for x in (cx - 3.0).max(0.0) as u32..(cx + 3.0).min(f64::from(w)) as u32 {
                out.put_pixel(x, y, colour);
            }
        }
    }
    out
}

/// Line art: the face's edges drawn black on white.
fn line_art(face: &RgbImage) -> RgbImage {
    let g = DynamicImage::ImageRgb8(face.clone()).to_luma8();
    let (w, h) = g.dimensions();
    let at = |x: u32, y: u32| f64::from(g.get_pixel(x.min(w - 1), y.min(h - 1))[0]);
    RgbImage::from_fn(w, h, |x, y| {
        let gx = at(x + 1, y) - at(x.saturating_sub(1), y);
        let gy = at(x, y + 1) - at(x, y.saturating_sub(1));
        let ink = if gx.hypot(gy) > 40.0 { 0 } else { 255 };
        Rgb([ink, ink, ink])
    })
}

/// The face, scaled down, on a "screen" (a dark bezel) inside a bigger textured photo.
fn on_a_screen(face: &RgbImage) -> RgbImage {
    let mut photo = foliage(11);
    photo = imageops::resize(&photo, 640, 480, imageops::FilterType::Triangle);
    let small = imageops::resize(face, 240, 182, imageops::FilterType::Triangle);
    let bezel = RgbImage::from_pixel(264, 206, Rgb([15, 15, 18]));
    imageops::overlay(&mut photo, &bezel, 200, 140);
    imageops::overlay(&mut photo, &small, 212, 152);
    photo
}

fn estimate(unshear: &Unshear, img: &RgbImage) -> ImageReport {
    unshear.estimate(&DynamicImage::ImageRgb8(img.clone()))
}

/// Every accepted estimate within the plausible bound, and the image's shear too.
fn assert_bounded(what: &str, report: &ImageReport) {
    for f in &report.faces {
        if let Some(k) = f.k {
            assert!(k.abs() <= DEFAULT_MAX_SHEAR, "{what}: accepted k = {k}");
        }
        if f.k_measured.abs() > DEFAULT_MAX_SHEAR {
            assert!(f.k.is_none() && f.refused.is_some(), "{what}: {f:?}");
        }
    }
    if let Some(k) = report.k {
        assert!(k.abs() <= DEFAULT_MAX_SHEAR, "{what}: image k = {k}");
    }
}

#[test]
fn textures_give_no_accepted_shear() {
    let unshear = Unshear::new(Config::default()).expect("models");
    let mut cases: Vec<(String, RgbImage)> = vec![
        ("fabric".into(), fabric()),
        ("white noise".into(), noise(320, 240, 3)),
    ];
    for seed in 1..=6 {
        cases.push((
            format!("blurred green noise {seed}"),
            blurred_green_noise(seed),
        ));
    }
    for seed in 1..=2 {
        cases.push((format!("foliage {seed}"), foliage(seed)));
        cases.push((format!("grass {seed}"), grass(seed)));
    }
    for (what, img) in &cases {
        let report = estimate(&unshear, img);
        assert_bounded(what, &report);
        assert!(
            report.k.is_none() && report.faces.iter().all(|f| f.k.is_none()),
            "{what}: a shear accepted from a texture: {:?}",
            report.faces
        );
    }
}

/// Hard faces: each either refused or measured within 0.15 of the shear applied (a gross error
/// would make the picture worse), and never beyond the bound.
#[test]
fn hard_faces_are_measured_well_or_refused() {
    let unshear = Unshear::new(Config::default()).expect("models");
    let face = fixture_face("subject01.normal.jpeg");
    let mut cases: Vec<(String, RgbImage, Option<f64>)> = Vec::new();
    for side in 0..4 {
        for cut in [0.3, 0.6] {
            cases.push((
                format!("cut {cut} by border {side}"),
                cut_by_border(&face, side, cut),
                Some(0.0),
            ));
        }
    }
    for k in [0.0, 0.25] {
        let f = sheared(&face, k);
        cases.push((format!("eyes covered, k {k}"), covered(&f, true), Some(k)));
        cases.push((format!("mouth covered, k {k}"), covered(&f, false), Some(k)));
        cases.push((format!("painted, k {k}"), painted(&f), Some(k)));
        cases.push((format!("line art, k {k}"), line_art(&f), Some(k)));
        cases.push((format!("on a screen, k {k}"), on_a_screen(&f), Some(k)));
    }
    // Turned sideways: beyond the rolls searched, the shear is not measurable as a row shift.
    cases.push(("turned 90 degrees".into(), imageops::rotate90(&face), None));
    cases.push((
        "turned 270 degrees".into(),
        imageops::rotate270(&face),
        None,
    ));
    for (what, img, truth) in &cases {
        let report = estimate(&unshear, img);
        assert_bounded(what, &report);
        for f in report.faces.iter().filter(|f| f.k.is_some()) {
            let k = f.k.unwrap_or(0.0);
            match truth {
                Some(t) => assert!(
                    (k - t).abs() <= 0.15,
                    "{what}: accepted k = {k:.3}, truth {t}: {f:?}"
                ),
                None => assert!(
                    k.abs() <= 0.15,
                    "{what}: accepted k = {k:.3} from a sideways face: {f:?}"
                ),
            }
        }
    }
}

/// A face whose measured shear is beyond `max_shear` is refused as implausible, its
/// measurement kept; the same face within the bound is accepted.
#[test]
fn an_estimate_beyond_the_bound_is_refused_and_kept_as_measured() {
    let face = fixture_face("subject14.normal.jpeg");
    let img = sheared(&face, 0.3);
    let strict = Unshear::new(Config {
        max_shear: 0.2,
        ..Config::default()
    })
    .expect("models");
    let report = estimate(&strict, &img);
    let f = report.faces.first().expect("the face is found");
    assert!((f.k_measured - 0.3).abs() < 0.1, "{f:?}");
    assert_eq!(f.k, None);
    assert_eq!(f.refused, Some(unshear::Refusal::ImplausibleShear));
    assert_eq!(report.k, None);
    let default = Unshear::new(Config::default()).expect("models");
    let report = estimate(&default, &img);
    assert!((report.k.expect("accepted") - 0.3).abs() < 0.1);
}

/// `correct` leaves an input with no trustworthy face untouched: nothing written, exit code 0
/// (docs/cli.md), and stderr says why.
#[test]
fn correct_leaves_a_texture_untouched_and_says_why() {
    let dir = tempfile::tempdir().expect("temp dir");
    let input: PathBuf = dir.path().join("leaves.png");
    blurred_green_noise(4).save(&input).expect("save");
    let res = Command::cargo_bin("unshear")
        .expect("binary")
        .args(["correct", "--json"])
        .arg(&input)
        .assert()
        .success();
    let stderr = String::from_utf8_lossy(&res.get_output().stderr).to_string();
    assert!(
        stderr.contains("nothing written, the input is left as it is"),
        "{stderr}"
    );
    assert!(
        stderr.contains("no face found") || stderr.contains("no trustworthy"),
        "{stderr}"
    );
    let line = &common::json_lines(&res.get_output().stdout)[0];
    assert!(line["k"].is_null());
    assert!(!dir.path().join("leaves.unshear.png").exists());
}

/// A JPEG damaged in transit whose header declares 308x56826 pixels but holds the data of a
/// 320x243 photo: bounded cost (the views that would be mostly padding are skipped) and a
/// warning that the decode is mostly without data.
#[test]
fn a_damaged_jpeg_declaring_a_tall_image_is_reported_as_missing_data() {
    let mut bytes = std::fs::read(common::fixture("subject01.normal.jpeg")).expect("fixture");
    let sof = bytes
        .windows(2)
        .position(|w| w == [0xFF, 0xC0])
        .expect("baseline JPEG");
    bytes[sof + 5..sof + 7].copy_from_slice(&56826u16.to_be_bytes());
    bytes[sof + 7..sof + 9].copy_from_slice(&308u16.to_be_bytes());
    let dir = tempfile::tempdir().expect("temp dir");
    let input = dir.path().join("damaged.jpg");
    std::fs::write(&input, &bytes).expect("write");
    let res = Command::cargo_bin("unshear")
        .expect("binary")
        .args(["estimate", "--json", "--quick"])
        .arg(&input)
        .assert()
        .success();
    let line = &common::json_lines(&res.get_output().stdout)[0];
    let warnings: Vec<&str> = line["warnings"]
        .as_array()
        .expect("warnings")
        .iter()
        .filter_map(|w| w.as_str())
        .collect();
    assert!(
        warnings.iter().any(|w| w.contains("without data")),
        "{warnings:?}"
    );
    assert!(
        warnings.iter().any(|w| w.contains("not searched")),
        "{warnings:?}"
    );
    assert!(line["k"].is_null());
}

//! The scene ruler on drawn scenes with a known shear, roll or pitch, and (when
//! `../shared/data` is there) on real photos sheared by a known `k`.

use super::*;
use image::Luma;

const W: u32 = 640;
const H: u32 = 480;

/// A filled shape of the drawn scene: the band `x0 + lean * (y - y0) <= x <= x1 + lean * (y -
/// y0)`, `y0 <= y <= y1`, in scene pixels (`lean` 0: an upright rectangle).
#[derive(Clone, Copy)]
struct Shape {
    x0: f64,
    x1: f64,
    y0: f64,
    y1: f64,
    lean: f64,
    value: f64,
}

fn rect(x0: f64, y0: f64, x1: f64, y1: f64, value: f64) -> Shape {
    Shape {
        x0,
        x1,
        y0,
        y1,
        lean: 0.0,
        value,
    }
}

fn intensity(shapes: &[Shape], x: f64, y: f64) -> f64 {
    let mut v = 150.0;
    for s in shapes {
        let shift = s.lean * (y - s.y0);
        if y >= s.y0 && y <= s.y1 && x >= s.x0 + shift && x <= s.x1 + shift {
            v = s.value;
        }
    }
    v
}

/// `shapes` seen through `to_scene` (an output pixel to the scene point it shows), 3x3
/// supersampled so edges are anti-aliased as a camera's are.
fn render(shapes: &[Shape], to_scene: impl Fn(f64, f64) -> (f64, f64)) -> GrayImage {
    GrayImage::from_fn(W, H, |x, y| {
        let mut sum = 0.0;
        for i in 0..3 {
            for j in 0..3 {
                let (sx, sy) = to_scene(
                    f64::from(x) + (f64::from(i) - 1.0) / 3.0,
                    f64::from(y) + (f64::from(j) - 1.0) / 3.0,
                );
                sum += intensity(shapes, sx, sy);
            }
        }
        Luma([(sum / 9.0).round() as u8])
    })
}

/// A street: building edges and poles reaching beyond the frame, columns of windows, and
/// horizontal sills and a kerb across it.
fn street() -> Vec<Shape> {
    let mut s = vec![
        rect(-200.0, -300.0, 90.0, 800.0, 200.0),
        rect(560.0, -300.0, 900.0, 800.0, 90.0),
        rect(250.0, -300.0, 268.0, 800.0, 40.0),
        rect(400.0, -300.0, 430.0, 800.0, 220.0),
        rect(-300.0, 395.0, 1000.0, 800.0, 110.0),
    ];
    for col in [120.0, 170.0, 300.0, 470.0] {
        for row in [60.0, 170.0, 280.0] {
            s.push(rect(col, row, col + 32.0, row + 60.0, 60.0));
        }
    }
    for y in [140.0, 250.0] {
        s.push(rect(-300.0, y, 1000.0, y + 6.0, 100.0));
    }
    s
}

/// Only upright poles, reaching beyond the frame (no horizontals at all).
fn poles() -> Vec<Shape> {
    [60.0, 190.0, 330.0, 450.0, 580.0]
        .iter()
        .map(|&x| rect(x, -400.0, x + 16.0, 900.0, 50.0))
        .collect()
}

fn sheared(k: f64) -> impl Fn(f64, f64) -> (f64, f64) {
    let c = f64::from(H) / 2.0;
    move |x, y| (x - k * (y - c), y)
}

/// The camera rolled by `degrees` (positive: the picture's right side lower).
fn rolled(degrees: f64) -> impl Fn(f64, f64) -> (f64, f64) {
    let (s, c) = degrees.to_radians().sin_cos();
    let (cx, cy) = (f64::from(W) / 2.0, f64::from(H) / 2.0);
    // The scene point turned by +a appears at the pixel: invert by turning back.
    move |x, y| {
        let (dx, dy) = (x - cx, y - cy);
        (cx + c * dx + s * dy, cy - s * dx + c * dy)
    }
}

/// The camera pitched up by `degrees`, focal length one long side, about the centre.
fn pitched(degrees: f64) -> impl Fn(f64, f64) -> (f64, f64) {
    let f = f64::from(W.max(H));
    let (s, c) = degrees.to_radians().sin_cos();
    let (cx, cy) = (f64::from(W) / 2.0, f64::from(H) / 2.0);
    move |x, y| {
        let (px, py, pz) = ((x - cx) / f, (y - cy) / f, 1.0);
        let (qy, qz) = (c * py - s * pz, s * py + c * pz);
        (cx + f * px / qz, cy + f * qy / qz)
    }
}

fn estimate(img: &GrayImage) -> Option<SceneShear> {
    estimate_scene_shear(img, &SceneParams::default())
}

/// Drawn edges are exact: the error is the detector's end points (about 0.3 px on segments of
/// 100 px and more, a tilt error of a few thousandths) plus the renderer's anti-aliasing.
const DRAWN_TOLERANCE: f64 = 0.01;

#[test]
fn a_sheared_street_gives_its_shear() {
    for k in [-0.35, -0.1, 0.0, 0.15, 0.3] {
        let img = render(&street(), sheared(k));
        let s = estimate(&img).unwrap_or_else(|| panic!("k = {k}: no reading"));
        assert!((s.k - k).abs() <= DRAWN_TOLERANCE, "k = {k}: {s:?}");
        assert!(s.uncertainty > 0.0 && s.uncertainty <= DEFAULT_MAX_UNCERTAINTY);
        assert!(s.lines >= MIN_LINES && s.segments >= s.lines, "{s:?}");
        let roll = s.roll_degrees.expect("the sills give the roll");
        assert!(roll.abs() < 0.3, "k = {k}: roll {roll}");
        assert!(!s.voters.is_empty());
    }
}

#[test]
fn sheared_poles_without_horizontals_are_read_with_the_roll_unknown() {
    let img = render(&poles(), sheared(0.2));
    let s = estimate(&img).expect("a reading");
    assert!((s.k - 0.2).abs() <= DRAWN_TOLERANCE, "{s:?}");
    assert_eq!(s.roll_degrees, None);
    assert!(s.uncertainty >= ROLL_PRIOR, "the unseen roll counts: {s:?}");
}

#[test]
fn a_roll_is_not_read_as_shear() {
    for degrees in [-5.0, 3.0, 6.0] {
        let img = render(&street(), rolled(degrees));
        let s = estimate(&img).expect("a reading");
        assert!(s.k.abs() <= DRAWN_TOLERANCE, "roll {degrees}: {s:?}");
        let roll = s.roll_degrees.expect("the roll");
        assert!((roll - degrees).abs() < 0.5, "roll {degrees}: {s:?}");
    }
    // Rolled and then sheared by the readout: the shear alone.
    let roll = rolled(4.0);
    let shear = sheared(0.2);
    let img = render(&street(), move |x, y| {
        let (a, b) = shear(x, y);
        roll(a, b)
    });
    let s = estimate(&img).expect("a reading");
    assert!((s.k - 0.2).abs() <= DRAWN_TOLERANCE, "{s:?}");
}

#[test]
fn a_pitch_is_not_read_as_shear() {
    for degrees in [-12.0, 8.0, 15.0] {
        let img = render(&street(), pitched(degrees));
        match estimate(&img) {
            Some(s) => {
                assert!(s.k.abs() <= DRAWN_TOLERANCE, "pitch {degrees}: {s:?}");
                assert!(s.convergence.abs() > 0.05, "pitch {degrees}: {s:?}");
            }
            None => panic!("pitch {degrees}: the verticals span the picture, a reading is due"),
        }
    }
    let pitch = pitched(10.0);
    let shear = sheared(-0.25);
    let img = render(&street(), move |x, y| {
        let (a, b) = shear(x, y);
        pitch(a, b)
    });
    let s = estimate(&img).expect("a reading");
    assert!((s.k + 0.25).abs() <= 2.0 * DRAWN_TOLERANCE, "{s:?}");
}

/// A leaning structure alone is refused, or its reading's uncertainty covers the truth (0).
fn refused_or_covered(img: &GrayImage, what: &str) {
    if let Some(s) = estimate(img) {
        assert!(s.k.abs() <= 2.0 * s.uncertainty, "{what}: {s:?}");
    }
}

#[test]
fn a_leaning_structure_alone_is_not_a_shear() {
    let pole = Shape {
        x0: 300.0,
        x1: 318.0,
        y0: -100.0,
        y1: 700.0,
        lean: 0.25,
        value: 40.0,
    };
    refused_or_covered(&render(&[pole], |x, y| (x, y)), "a tilted pole");
    // A stair: two stringers at dx/dy = 0.4 with its steps between them.
    let mut stair = vec![
        Shape {
            x0: 150.0,
            x1: 162.0,
            y0: 40.0,
            y1: 460.0,
            lean: -0.4,
            value: 60.0,
        },
        Shape {
            x0: 260.0,
            x1: 272.0,
            y0: 40.0,
            y1: 460.0,
            lean: -0.4,
            value: 60.0,
        },
    ];
    for i in 0..10 {
        let y = 50.0 + 40.0 * f64::from(i);
        let x = 162.0 - 0.4 * (y - 40.0);
        stair.push(rect(x, y, x + 98.0, y + 6.0, 200.0));
    }
    refused_or_covered(&render(&stair, |x, y| (x, y)), "a stair");
    // The stair beside upright poles: the poles' group wins, or the two are refused.
    let mut both = stair;
    both.extend(poles().into_iter().filter(|p| p.x0 > 330.0));
    if let Some(s) = estimate(&render(&both, |x, y| (x, y))) {
        assert!(s.k.abs() <= 2.0 * s.uncertainty, "a stair and poles: {s:?}");
    }
}

#[test]
fn blank_noisy_and_tiny_pictures_give_nothing() {
    assert!(estimate(&GrayImage::from_pixel(W, H, Luma([90]))).is_none());
    let mut rng = crate::rng::SplitMix64::new(7);
    let noise = GrayImage::from_fn(W, H, |_, _| Luma([(rng.next_f64() * 255.0) as u8]));
    assert!(estimate(&noise).is_none());
    assert!(estimate(&GrayImage::new(8, 8)).is_none());
    assert!(estimate(&GrayImage::new(0, 0)).is_none());
}

#[test]
fn a_large_picture_is_read_at_the_working_size() {
    // 1920x1080: averaged down by 3; the segments come back in input pixels.
    let (big_w, big_h) = (1920u32, 1080u32);
    let k = 0.18;
    let scale = f64::from(big_h) / f64::from(H);
    let shapes = street();
    let c = f64::from(big_h) / 2.0;
    let img = GrayImage::from_fn(big_w, big_h, |x, y| {
        let (x, y) = (f64::from(x), f64::from(y));
        let (sx, sy) = ((x - k * (y - c)) / scale, y / scale);
        Luma([intensity(&shapes, sx - 80.0, sy) as u8])
    });
    let s = estimate(&img).expect("a reading");
    assert!((s.k - k).abs() <= DRAWN_TOLERANCE, "{s:?}");
    let inside = |p: Point| p.x > -2.0 && p.x < f64::from(big_w) + 2.0 && p.y > -2.0;
    assert!(s.voters.iter().all(|v| inside(v.from) && inside(v.to)));
    assert!(s
        .voters
        .iter()
        .any(|v| (v.from.y - v.to.y).abs() > 0.5 * f64::from(big_h)));
}

/// Real web photos (the first 120 Caltech development photos in name order, whole), each
/// sheared by ±0.2 about its middle row and cropped to the pixels that stay inside
/// (`Canvas::Crop`: no wedge edge shows `k`). Truth: the applied `k` plus the photo's own
/// reading when it has one (its own lean), else the applied `k`. Prints how many are answered
/// and how accurately; fails when fewer than 5 are answered or fewer than half of the answers are
/// within 0.05 (on the development photos about 70-80% are, docs/accuracy.md).
#[test]
fn real_photos_sheared_by_a_known_k() {
    use crate::warp::{try_apply_shear, Canvas, Interpolation};
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data/caltech-webfaces/images");
    let Ok(entries) = std::fs::read_dir(&dir) else {
        let _ = std::io::Write::write_all(
            &mut std::io::stderr(),
            b"skipped: ../shared/data/caltech-webfaces not found\n",
        );
        return;
    };
    let mut paths: Vec<_> = entries.filter_map(|e| Some(e.ok()?.path())).collect();
    paths.sort();
    paths.truncate(120);
    let (mut runs, mut answered, mut within) = (0, 0, 0);
    for path in &paths {
        let Ok(img) = image::open(path) else {
            continue;
        };
        let own = estimate(&crate::detect::to_gray_opencv(&img)).map_or(0.0, |s| s.k);
        for k in [0.2, -0.2] {
            let shear = crate::Shear::about_middle(k, img.height());
            let (sheared, _) = try_apply_shear(&img, shear, Interpolation::Linear, Canvas::Crop)
                .expect("a valid shear");
            runs += 1;
            if let Some(s) = estimate(&crate::detect::to_gray_opencv(&sheared)) {
                answered += 1;
                within += usize::from((s.k - (k + own)).abs() <= 0.05);
            }
        }
    }
    let _ = std::io::Write::write_all(
        &mut std::io::stderr(),
        format!("real photos: {answered} of {runs} answered, {within} within 0.05\n").as_bytes(),
    );
    assert!(answered >= 5, "{answered} of {runs} answered");
    assert!(2 * within >= answered, "{within} of {answered} within 0.05");
}

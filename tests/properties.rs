//! Invariants as property tests (proptest): distort-then-correct is the identity on the valid
//! interior; the estimate does not change under translation or uniform scaling of the image and
//! changes sign under a mirror. (That the `--json` line always parses is a property test in the
//! command-line tool, `cli/src/report.rs`, where the line is built.)
//!
//! The estimate properties run the whole pipeline, so they draw few cases.

use image::{imageops, DynamicImage, GrayImage, Luma};
use proptest::prelude::*;
use unshear::warp::{apply_shear, remove_shear, Canvas, Interpolation};
use unshear::{Shear, Unshear};

/// A smooth random grey image: the sum of two sinusoids with wavelength >= `min_wavelength`
/// pixels and total amplitude `amplitude` around 128. Returns it with the largest horizontal
/// second derivative of the underlying function, `sum(a_i (2 pi / lambda_i)^2)`.
fn smooth_image(
    w: u32,
    h: u32,
    waves: &[(f64, f64, f64, f64)], // (amplitude, wavelength, vertical wavelength, phase)
) -> (GrayImage, f64) {
    let img = GrayImage::from_fn(w, h, |x, y| {
        let v: f64 = waves
            .iter()
            .map(|&(a, lx, ly, p)| {
                a * (std::f64::consts::TAU * (f64::from(x) / lx + f64::from(y) / ly) + p).sin()
            })
            .sum();
        Luma([(128.0 + v).round().clamp(0.0, 255.0) as u8])
    });
    let curvature = waves
        .iter()
        .map(|&(a, lx, _, _)| a * (std::f64::consts::TAU / lx).powi(2))
        .sum();
    (img, curvature)
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 64,
        failure_persistence: None,
        ..ProptestConfig::default()
    })]

    /// Shearing by `k` and shearing back gives the input again wherever both steps read inside
    /// the image (the columns more than `|k| * H / 2 + 2` pixels from either side).
    ///
    /// Tolerance: a fractional shift `t` there and back again is, for linear interpolation, the
    /// blur `[t(1-t), 1-2t(1-t), t(1-t)]`, whose error is at most `f''/4` for a function with
    /// horizontal second derivative `f''`; plus 1 grey level for rounding each pass to 8 bits and
    /// 0.5 for the 8-bit quantisation of the input seen through the second difference. Cubic
    /// (Catmull-Rom) is more accurate than linear on smooth content, so the same bound holds.
    #[test]
    fn distort_then_correct_is_the_identity_inside(
        w in 24u32..96,
        h in 2u32..40,
        k in -0.5f64..0.5,
        a1 in 0.0f64..60.0,
        l1 in 12.0f64..80.0,
        v1 in 6.0f64..200.0,
        p1 in 0.0f64..6.3,
        a2 in 0.0f64..40.0,
        l2 in 20.0f64..200.0,
        p2 in 0.0f64..6.3,
        cubic in any::<bool>(),
    ) {
        let (img, curvature) = smooth_image(w, h, &[(a1, l1, v1, p1), (a2, l2, -v1, p2)]);
        let interp = if cubic { Interpolation::Cubic } else { Interpolation::Linear };
        let shear = Shear::about_middle(k, h);
        let input = DynamicImage::ImageLuma8(img.clone());
        let (sheared, _) = apply_shear(&input, shear, interp, Canvas::Same);
        let (back, _) = remove_shear(&sheared, shear, interp, Canvas::Same);
        let back = back.to_luma8();
        prop_assert_eq!(back.dimensions(), img.dimensions());
        let margin = (k.abs() * f64::from(h) / 2.0).ceil() as u32 + 2;
        let tolerance = curvature / 4.0 + 1.5;
        for y in 0..h {
            for x in margin..w.saturating_sub(margin) {
                let (a, b) = (img.get_pixel(x, y)[0], back.get_pixel(x, y)[0]);
                prop_assert!(
                    f64::from(a.abs_diff(b)) <= tolerance,
                    "({x}, {y}): {a} -> {b}, tolerance {tolerance:.2}"
                );
            }
        }
    }

    /// Integer row shifts (integer `k`, pivot 0) copy pixels exactly: nothing is lost where the
    /// shifted row still covers the pixel.
    #[test]
    fn integer_row_shifts_are_exact(w in 24u32..64, h in 1u32..6, k in -2i32..=2, cubic in any::<bool>()) {
        let img = GrayImage::from_fn(w, h, |x, y| Luma([((x * 37 + y * 101) % 256) as u8]));
        let interp = if cubic { Interpolation::Cubic } else { Interpolation::Linear };
        let shear = Shear::new(f64::from(k), 0.0);
        let input = DynamicImage::ImageLuma8(img.clone());
        let (sheared, _) = apply_shear(&input, shear, interp, Canvas::Same);
        let (back, _) = remove_shear(&sheared, shear, interp, Canvas::Same);
        let back = back.to_luma8();
        for y in 0..h {
            let s = k * y as i32;
            for x in 0..w {
                let src = x as i32 + s;
                if src >= 0 && src < w as i32 {
                    prop_assert_eq!(img.get_pixel(x, y), back.get_pixel(x, y), "({}, {})", x, y);
                }
            }
        }
    }
}

/// The three committed fixture faces, grey.
fn faces() -> Vec<GrayImage> {
    [
        "subject01.normal.jpeg",
        "subject03.normal.jpeg",
        "subject14.normal.jpeg",
    ]
    .iter()
    .map(|n| {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/faces");
        unshear::imageio::read_image(&path.join(n), unshear::imageio::DEFAULT_MAX_PIXELS)
            .expect("fixture")
            .to_luma8()
    })
    .collect()
}

fn unshear() -> &'static Unshear {
    static U: std::sync::OnceLock<Unshear> = std::sync::OnceLock::new();
    U.get_or_init(|| Unshear::new(unshear::Config::default()).expect("built-in models"))
}

/// A fixture face sheared by `k` (bilinear, same canvas).
fn sheared_face(face: usize, k: f64) -> GrayImage {
    let img = DynamicImage::ImageLuma8(faces()[face].clone());
    let shear = Shear::about_middle(k, img.height());
    apply_shear(&img, shear, Interpolation::Linear, Canvas::Same)
        .0
        .to_luma8()
}

/// The measured shear (refused or not: these properties are of the estimator, not of the
/// confidence threshold).
fn k_of(img: &GrayImage) -> Option<f64> {
    finite_median(
        unshear()
            .estimate_gray(img)
            .faces
            .iter()
            .map(|f| f.k_measured)
            .collect(),
    )
}

/// `img` on a mid-grey canvas `extra` pixels larger in each direction, at `(dx, dy)`.
fn placed(img: &GrayImage, extra: u32, dx: u32, dy: u32) -> GrayImage {
    let mut canvas = GrayImage::from_pixel(img.width() + extra, img.height() + extra, Luma([128]));
    imageops::replace(&mut canvas, img, i64::from(dx), i64::from(dy));
    canvas
}

/// Worst change of the estimate seen under translation, over the 15 sheared faces of
/// `estimate_is_invariant_on_a_grid` and 5 offsets each, with the default (MOSSE) filters:
/// 0.0094, rounded up with room for the seeded random cases. (With UMACE filters one face's
/// nostril or nose peak moves to a neighbouring maximum when the detector's box shifts by a few
/// pixels: 0.16 with equation 5, 0.110 with the shear-roll-yaw model on the nostrils, 0.163 on
/// the nose tip.)
const TRANSLATION_TOLERANCE: f64 = 0.03;
/// Worst change seen under x2 enlargement on the same faces: 0.0089 with MOSSE filters, rounded
/// up. (UMACE: 0.046 with equation 5, 0.102-0.155 with the shear-roll-yaw model, one face whose
/// every axis reads about 0 at its own size.)
const SCALE_TOLERANCE: f64 = 0.03;
/// Worst `|k + k_mirrored|` seen on the same faces: 0.0149 with MOSSE filters, rounded up.
/// (UMACE: 0.14-0.18.) The filters are trained mirror-augmented, so left and right are treated
/// alike; what is left is detector and peak noise.
const MIRROR_TOLERANCE: f64 = 0.04;
/// Median change over the grid: the typical case, far tighter than the worst one (measured
/// medians 0.0022 to 0.0029 with MOSSE filters; 0.009 to 0.021 with UMACE).
const MEDIAN_TOLERANCE: f64 = 0.01;

fn estimate_config() -> ProptestConfig {
    ProptestConfig {
        cases: 6,
        // Fixed, so the suite is reproducible: the tolerances above are measured ones, not bounds.
        rng_seed: proptest::test_runner::RngSeed::Fixed(0x0075_6e73_6865_6172),
        failure_persistence: None,
        ..ProptestConfig::default()
    }
}

proptest! {
    #![proptest_config(estimate_config())]

    /// The same face moved by whole pixels on a larger canvas gives the same shear.
    #[test]
    fn estimate_is_invariant_under_translation(
        face in 0usize..3, k in -0.3f64..0.3, dx in 0u32..80, dy in 0u32..80,
    ) {
        let img = sheared_face(face, k);
        let (Some(a), Some(b)) = (k_of(&img), k_of(&placed(&img, 80, dx, dy))) else {
            return Err(TestCaseError::fail("face not found"));
        };
        prop_assert!((a - b).abs() <= TRANSLATION_TOLERANCE, "{a} vs {b}");
    }

    /// `k` is dimensionless: twice the size, the same shear.
    #[test]
    fn estimate_is_invariant_under_uniform_scale(face in 0usize..3, k in -0.3f64..0.3) {
        let img = sheared_face(face, k);
        let double = imageops::resize(&img, img.width() * 2, img.height() * 2, imageops::FilterType::Triangle);
        let (Some(a), Some(b)) = (k_of(&img), k_of(&double)) else {
            return Err(TestCaseError::fail("face not found"));
        };
        prop_assert!((a - b).abs() <= SCALE_TOLERANCE, "{a} vs {b}");
    }

    /// A mirror image has the opposite shear (`x -> W - 1 - x` turns `x + k y` into `x - k y`).
    #[test]
    fn estimate_changes_sign_under_a_mirror(face in 0usize..3, k in -0.3f64..0.3) {
        let img = sheared_face(face, k);
        let (Some(a), Some(b)) = (k_of(&img), k_of(&imageops::flip_horizontal(&img))) else {
            return Err(TestCaseError::fail("face not found"));
        };
        prop_assert!((a + b).abs() <= MIRROR_TOLERANCE, "{a} vs {b}");
    }
}

/// The median of the finite values, `None` when there are none.
fn finite_median(mut values: Vec<f64>) -> Option<f64> {
    values.retain(|v| v.is_finite());
    if values.is_empty() {
        return None;
    }
    values.sort_by(f64::total_cmp);
    let n = values.len();
    Some(if n % 2 == 1 {
        values[n / 2]
    } else {
        (values[n / 2 - 1] + values[n / 2]) / 2.0
    })
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// The three invariances on a fixed grid (3 faces x 5 shears): every case within the worst-case
/// tolerances, and the median change within [`MEDIAN_TOLERANCE`]. Run with `--nocapture` to see
/// the measured figures the tolerances come from.
#[test]
fn estimate_is_invariant_on_a_grid() {
    let (mut moved, mut scaled, mut mirrored) = (Vec::new(), Vec::new(), Vec::new());
    for face in 0..3 {
        for k in [-0.3, -0.15, 0.0, 0.15, 0.3] {
            let img = sheared_face(face, k);
            let base = k_of(&img).expect("face found");
            for (dx, dy) in [(0, 0), (7, 3), (31, 50), (63, 17), (80, 80)] {
                moved.push((k_of(&placed(&img, 80, dx, dy)).expect("found") - base).abs());
            }
            let double = imageops::resize(
                &img,
                img.width() * 2,
                img.height() * 2,
                imageops::FilterType::Triangle,
            );
            scaled.push((k_of(&double).expect("found") - base).abs());
            mirrored.push((k_of(&imageops::flip_horizontal(&img)).expect("found") + base).abs());
        }
    }
    let worst = |v: &[f64]| v.iter().copied().fold(0.0, f64::max);
    for (what, v, tolerance) in [
        ("translation", &moved, TRANSLATION_TOLERANCE),
        ("x2 scale", &scaled, SCALE_TOLERANCE),
        ("mirror", &mirrored, MIRROR_TOLERANCE),
    ] {
        let (m, w) = (median(v.clone()), worst(v));
        println!(
            "{what}: median |change| {m:.4}, worst {w:.4} over {} cases",
            v.len()
        );
        assert!(w <= tolerance, "{what}: worst {w} > {tolerance}");
        assert!(
            m <= MEDIAN_TOLERANCE,
            "{what}: median {m} > {MEDIAN_TOLERANCE}"
        );
    }
}

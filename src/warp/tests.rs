//! Tests of the row-shift warp. Tolerances are stated at each assertion.

use super::*;
use image::{GenericImageView, GrayImage, Luma, Rgb, Rgb32FImage, RgbImage, Rgba, RgbaImage};

/// A smooth image: sum of low-frequency sinusoids in 0..=255 (periods of about 30 px and more,
/// enough curvature that interpolation error is measurable above 8-bit rounding).
fn smooth_value(x: f64, y: f64) -> f64 {
    use std::f64::consts::TAU;
    128.0
        + 50.0 * (TAU * x / 29.0).sin()
        + 40.0 * (TAU * (y / 31.0 + x / 97.0)).cos()
        + 20.0 * (TAU * (x + 2.0 * y) / 47.0).sin()
}

fn smooth_gray(w: u32, h: u32) -> GrayImage {
    GrayImage::from_fn(w, h, |x, y| {
        Luma([smooth_value(f64::from(x), f64::from(y)).round() as u8])
    })
}

fn smooth_rgb(w: u32, h: u32) -> RgbImage {
    RgbImage::from_fn(w, h, |x, y| {
        let (x, y) = (f64::from(x), f64::from(y));
        Rgb([
            smooth_value(x, y).round() as u8,
            smooth_value(y + 7.0, x).round() as u8,
            smooth_value(x * 0.7 + 3.0, y * 1.3).round() as u8,
        ])
    })
}

/// Mean and max absolute difference over the pixels for which `keep(x, y)` holds.
fn error_stats(a: &GrayImage, b: &GrayImage, keep: impl Fn(u32, u32) -> bool) -> (f64, u8, usize) {
    let (mut sum, mut max, mut count) = (0.0, 0u8, 0usize);
    for (x, y, p) in a.enumerate_pixels() {
        if keep(x, y) {
            let d = p[0].abs_diff(b.get_pixel(x, y)[0]);
            sum += f64::from(d);
            max = max.max(d);
            count += 1;
        }
    }
    (sum / count as f64, max, count)
}

#[test]
fn distort_then_correct_restores_interior() {
    let (w, h) = (160u32, 120u32);
    let img = DynamicImage::ImageLuma8(smooth_gray(w, h));
    for k in [-0.4, -0.2, 0.2, 0.4] {
        let shear = Shear::about_middle(k, h);
        let mut means = Vec::new();
        for interp in [Interpolation::Linear, Interpolation::Cubic] {
            let (distorted, _) = apply_shear(&img, shear, interp, Canvas::Same);
            let (restored, p) = remove_shear(&distorted, shear, interp, Canvas::Same);
            assert_eq!(p, Placement::default());
            // Interior: the distorted pixel read by the correction (x + s) must itself have come
            // from inside the input, away from the 2-px border (3 px to cover the cubic taps).
            let keep = |x: u32, y: u32| {
                let s = shear.row_shift(f64::from(y));
                let xs = f64::from(x) + s;
                let lim = f64::from(w) - 4.0;
                (3.0..=lim).contains(&xs) && (3.0..=lim).contains(&f64::from(x))
            };
            let (mean, max, count) =
                error_stats(img.as_luma8().unwrap(), restored.as_luma8().unwrap(), keep);
            assert!(count > 5000, "interior too small: {count}");
            match interp {
                // Two passes of linear interpolation blur a little: mean < 1 grey level, max < 6.
                Interpolation::Linear => {
                    assert!(mean < 1.0 && max < 6, "k={k} linear mean {mean} max {max}")
                }
                // Cubic is sharper: mean < 0.5, max < 4.
                Interpolation::Cubic => {
                    assert!(mean < 0.5 && max < 4, "k={k} cubic mean {mean} max {max}")
                }
            }
            eprintln!("k={k} {interp:?}: mean {mean:.3} max {max}");
            means.push(mean);
        }
        assert!(
            means[1] < means[0],
            "k={k}: cubic ({}) not better than linear ({})",
            means[1],
            means[0]
        );
    }
}

#[test]
fn integer_shift_is_exact() {
    let (w, h) = (50u32, 20u32);
    let src = smooth_rgb(w, h);
    let img = DynamicImage::ImageRgb8(src.clone());
    // k = 1, c = 0: row y moves right by exactly y pixels.
    let shear = Shear::new(1.0, 0.0);
    for interp in [Interpolation::Linear, Interpolation::Cubic] {
        let (out, _) = apply_shear(&img, shear, interp, Canvas::Same);
        let out = out.as_rgb8().unwrap();
        for (x, y, p) in out.enumerate_pixels() {
            let expected = if x >= y {
                *src.get_pixel(x - y, y)
            } else {
                Rgb([0, 0, 0])
            };
            assert_eq!(*p, expected, "({x}, {y}) {interp:?}");
        }
        // And back again, exactly, where the content survived.
        let (back, _) = remove_shear(
            &DynamicImage::ImageRgb8(out.clone()),
            shear,
            interp,
            Canvas::Same,
        );
        let back = back.as_rgb8().unwrap();
        for (x, y, p) in back.enumerate_pixels() {
            if x + y < w {
                assert_eq!(p, src.get_pixel(x, y));
            }
        }
    }
}

fn all_variants() -> Vec<DynamicImage> {
    let rgba = RgbaImage::from_fn(23, 17, |x, y| {
        Rgba([
            (x * 11) as u8,
            (y * 13) as u8,
            ((x * y) % 251) as u8,
            (200 - x) as u8,
        ])
    });
    let rgba = DynamicImage::ImageRgba8(rgba);
    vec![
        DynamicImage::ImageLuma8(rgba.to_luma8()),
        DynamicImage::ImageLumaA8(rgba.to_luma_alpha8()),
        DynamicImage::ImageRgb8(rgba.to_rgb8()),
        rgba.clone(),
        DynamicImage::ImageLuma16(rgba.to_luma16()),
        DynamicImage::ImageLumaA16(rgba.to_luma_alpha16()),
        DynamicImage::ImageRgb16(rgba.to_rgb16()),
        DynamicImage::ImageRgba16(rgba.to_rgba16()),
        DynamicImage::ImageRgb32F(rgba.to_rgb32f()),
        DynamicImage::ImageRgba32F(rgba.to_rgba32f()),
    ]
}

#[test]
fn zero_shear_is_identity_for_every_variant() {
    for img in all_variants() {
        for interp in [Interpolation::Linear, Interpolation::Cubic] {
            for canvas in [Canvas::Same, Canvas::Expand, Canvas::Crop] {
                let (out, p) = apply_shear(&img, Shear::new(0.0, 3.7), interp, canvas);
                assert_eq!(p, Placement::default());
                assert_eq!(out, img, "{:?} {interp:?} {canvas:?}", img.color());
            }
        }
    }
}

#[test]
fn channel_layout_is_preserved() {
    for img in all_variants() {
        for canvas in [Canvas::Same, Canvas::Expand, Canvas::Crop] {
            let (out, _) = remove_shear(
                &img,
                Shear::about_middle(0.3, img.height()),
                Interpolation::Cubic,
                canvas,
            );
            assert_eq!(out.color(), img.color(), "{canvas:?}");
        }
    }
}

/// The u8 fixed-point kernels agree with the float kernels to within 1 grey level.
#[test]
fn fixed_point_matches_float() {
    let src = smooth_rgb(97, 61);
    let img8 = DynamicImage::ImageRgb8(src.clone());
    let imgf = DynamicImage::ImageRgb32F(DynamicImage::ImageRgb8(src).to_rgb32f());
    for k in [-0.37, 0.13, 0.61] {
        for interp in [Interpolation::Linear, Interpolation::Cubic] {
            for canvas in [Canvas::Same, Canvas::Expand, Canvas::Crop] {
                let shear = Shear::new(k, 20.3);
                let (a, pa) = apply_shear(&img8, shear, interp, canvas);
                let (b, pb) = apply_shear(&imgf, shear, interp, canvas);
                assert_eq!(pa, pb);
                let b = b.to_rgb8();
                for (p, q) in a.as_rgb8().unwrap().as_raw().iter().zip(b.as_raw()) {
                    assert!(
                        p.abs_diff(*q) <= 1,
                        "k={k} {interp:?} {canvas:?}: {p} vs {q}"
                    );
                }
            }
        }
    }
}

#[test]
fn expand_keeps_every_input_pixel() {
    // Smooth content with a 4-px zero border, so no interpolation reaches past the content.
    let (w, h) = (90u32, 70u32);
    let inner = |x: u32, y: u32| x >= 4 && y >= 4 && x < w - 4 && y < h - 4;
    let gray = GrayImage::from_fn(w, h, |x, y| {
        Luma([if inner(x, y) {
            smooth_value(f64::from(x), f64::from(y)).round() as u8
        } else {
            0
        }])
    });
    let sum_in: f64 = gray.as_raw().iter().map(|&v| f64::from(v)).sum();
    for k in [-0.45, 0.3, 1.7] {
        let shear = Shear::about_middle(k, h);
        for interp in [Interpolation::Linear, Interpolation::Cubic] {
            // Float: the sum is preserved to float precision (the weights of each row sum to 1).
            let f = DynamicImage::ImageRgb32F(DynamicImage::ImageLuma8(gray.clone()).to_rgb32f());
            let (out, p) = apply_shear(&f, shear, interp, Canvas::Expand);
            let sum_out: f64 = out
                .as_rgb32f()
                .unwrap()
                .as_raw()
                .iter()
                .map(|&v| f64::from(v) * 255.0)
                .sum::<f64>()
                / 3.0;
            assert!(
                (sum_out - sum_in).abs() < 1e-4 * sum_in,
                "k={k} {interp:?}: {sum_out} vs {sum_in}"
            );
            // The canvas spans exactly the shifted rows.
            let s0 = shear.row_shift(0.0);
            let s1 = shear.row_shift(f64::from(h - 1));
            assert_eq!(p.offset_x, s0.min(s1).floor());
            assert_eq!(
                out.width() as f64,
                (s0.max(s1) + f64::from(w) - 1.0).ceil() - p.offset_x + 1.0
            );
            // 8-bit: within rounding (at most 0.5 per output pixel, which is generous).
            let (out8, _) = apply_shear(
                &DynamicImage::ImageLuma8(gray.clone()),
                shear,
                interp,
                Canvas::Expand,
            );
            let sum8: f64 = out8
                .as_luma8()
                .unwrap()
                .as_raw()
                .iter()
                .map(|&v| f64::from(v))
                .sum();
            let n = f64::from(out8.width() * out8.height());
            assert!(
                (sum8 - sum_in).abs() <= 0.5 * n,
                "k={k} {interp:?}: {sum8} vs {sum_in}"
            );
            assert!(
                (sum8 - sum_in).abs() < 2e-3 * sum_in,
                "k={k} {interp:?}: {sum8} vs {sum_in}"
            );
        }
    }
}

#[test]
fn crop_has_no_fill_pixels() {
    let white = DynamicImage::ImageRgb8(RgbImage::from_pixel(100, 80, Rgb([255, 255, 255])));
    for k in [-0.8, -0.25, 0.1, 0.33, 2.5] {
        for interp in [Interpolation::Linear, Interpolation::Cubic] {
            for shear in [Shear::about_middle(k, 80), Shear::new(k, 5.5)] {
                let (out, _) = apply_shear(&white, shear, interp, Canvas::Crop);
                assert!(out.width() > 0 && out.height() > 0);
                assert!(
                    out.as_rgb8().unwrap().as_raw().iter().all(|&v| v == 255),
                    "k={k} {interp:?}"
                );
                let (out, _) = remove_shear(&white, shear, interp, Canvas::Crop);
                assert!(
                    out.as_rgb8().unwrap().as_raw().iter().all(|&v| v == 255),
                    "k={k} {interp:?}"
                );
            }
        }
    }
}

#[test]
fn crop_size_for_a_simple_case() {
    // 10x10, k = 1, pivot 0: h rows give width 11 - h; area h * (11 - h) peaks at h = 5 and 6
    // (30); the taller wins. Rows 0..6 shift by 0..5, so columns start at 5.
    assert_eq!(
        sheared_canvas(10, 10, Shear::new(1.0, 0.0), Canvas::Crop).unwrap(),
        (
            5,
            6,
            Placement {
                offset_x: 5.0,
                offset_y: 0.0
            }
        )
    );
    // Pivot in the middle: the rows are centred on it.
    let (w, h, p) = sheared_canvas(200, 101, Shear::new(0.5, 50.0), Canvas::Crop).unwrap();
    assert_eq!(f64::from(w), 200.0 - 0.5 * f64::from(h - 1));
    assert_eq!(p.offset_y + f64::from(h - 1) / 2.0, 50.0);
    // Same and Expand of an unsheared image.
    assert_eq!(
        sheared_canvas(7, 3, Shear::new(0.0, 1.0), Canvas::Expand).unwrap(),
        (7, 3, Placement::default())
    );
    assert!(sheared_canvas(7, 3, Shear::new(f64::NAN, 1.0), Canvas::Same).is_err());
    assert!(try_remove_shear(
        &white_l8(3, 3),
        Shear::new(f64::INFINITY, 1.0),
        Interpolation::Linear,
        Canvas::Same
    )
    .is_err());
    assert!(try_remove_shear(
        &white_l8(3, 3),
        Shear::new(1e12, 1.0),
        Interpolation::Linear,
        Canvas::Expand
    )
    .is_err());
}

fn white_l8(w: u32, h: u32) -> DynamicImage {
    DynamicImage::ImageLuma8(GrayImage::from_pixel(w, h, Luma([255])))
}

#[test]
fn fill_is_transparent_black() {
    let img = DynamicImage::ImageRgba8(RgbaImage::from_pixel(20, 20, Rgba([255, 255, 255, 255])));
    let (out, _) = apply_shear(
        &img,
        Shear::about_middle(0.5, 20),
        Interpolation::Cubic,
        Canvas::Same,
    );
    let out = out.as_rgba8().unwrap();
    assert_eq!(*out.get_pixel(0, 19), Rgba([0, 0, 0, 0]));
    assert_eq!(*out.get_pixel(19, 0), Rgba([0, 0, 0, 0]));
    assert_eq!(*out.get_pixel(10, 10), Rgba([255, 255, 255, 255]));
}

#[test]
fn cubic_overshoot_is_clamped() {
    // A hard step: cubic overshoots by about 7 %, which must clamp, not wrap around.
    let img = GrayImage::from_fn(40, 4, |x, _| Luma([if x < 20 { 0 } else { 255 }]));
    let (out, _) = apply_shear(
        &DynamicImage::ImageLuma8(img),
        Shear::new(0.5, 0.0),
        Interpolation::Cubic,
        Canvas::Same,
    );
    let row: Vec<u8> = (0..40)
        .map(|x| out.as_luma8().unwrap().get_pixel(x, 1)[0])
        .collect();
    // Row 1 is shifted by 0.5: monotone non-decreasing away from the fill edge after clamping.
    assert!(row[2..].windows(2).all(|p| p[0] <= p[1]), "{row:?}");
    assert_eq!(row[39], 255);
}

#[test]
fn region_warp_is_local_and_matches_global_inside() {
    let (w, h) = (220u32, 160u32);
    let img = DynamicImage::ImageLuma8(smooth_gray(w, h));
    let region = Rect::new(70.0, 50.0, 60.0, 50.0);
    let shear = Shear::new(0.3, region.center().y);
    for interp in [Interpolation::Linear, Interpolation::Cubic] {
        let out = remove_shear_in_region(&img, shear, region, interp);
        assert_eq!(out.color(), img.color());
        let (global, _) = remove_shear(&img, shear, interp, Canvas::Same);
        let (a, o, g) = (
            img.as_luma8().unwrap(),
            out.as_luma8().unwrap(),
            global.as_luma8().unwrap(),
        );
        let m = feather_margin(shear, region);
        let mut changed = 0;
        for (x, y, p) in o.enumerate_pixels() {
            let (xf, yf) = (f64::from(x), f64::from(y));
            let outside = xf < region.x - m - 1.0
                || xf > region.x + region.width + m + 1.0
                || yf < region.y - m - 1.0
                || yf > region.y + region.height + m + 1.0;
            if outside {
                // Byte-exact outside the feathered box.
                assert_eq!(p, a.get_pixel(x, y), "({x}, {y}) changed outside");
            } else if region.contains(Point::new(xf, yf)) {
                // Inside the box: the full correction, within 1 grey level (float vs fixed point).
                assert!(
                    p[0].abs_diff(g.get_pixel(x, y)[0]) <= 1,
                    "({x}, {y}) {} vs {}",
                    p[0],
                    g.get_pixel(x, y)[0]
                );
                changed += usize::from(p != a.get_pixel(x, y));
            }
        }
        assert!(changed > 1000, "region barely changed: {changed}");
        // The pivot row does not move.
        let yc = region.center().y as u32;
        for x in 0..w {
            assert_eq!(o.get_pixel(x, yc), a.get_pixel(x, yc));
        }
    }
}

#[test]
fn region_warp_degenerate_inputs_are_copies() {
    let img = DynamicImage::ImageRgb32F(Rgb32FImage::from_pixel(10, 10, Rgb([0.5, 0.25, 1.0])));
    let r = Rect::new(2.0, 2.0, 5.0, 5.0);
    assert_eq!(
        remove_shear_in_region(&img, Shear::new(f64::NAN, 5.0), r, Interpolation::Linear),
        img
    );
    assert_eq!(
        remove_shear_in_region(
            &img,
            Shear::new(0.3, 5.0),
            Rect::new(2.0, 2.0, 0.0, 5.0),
            Interpolation::Linear
        ),
        img
    );
    // A region far outside the image.
    assert_eq!(
        remove_shear_in_region(
            &img,
            Shear::new(0.3, 5.0),
            Rect::new(500.0, -900.0, 5.0, 5.0),
            Interpolation::Cubic
        ),
        img
    );
    // A region covering the border: no panic, same size.
    let out = remove_shear_in_region(
        &img,
        Shear::new(2.0, 0.0),
        Rect::new(-5.0, -5.0, 30.0, 30.0),
        Interpolation::Cubic,
    );
    assert_eq!(out.dimensions(), (10, 10));
}

#[test]
fn empty_images_do_not_panic() {
    let img = DynamicImage::ImageLuma8(GrayImage::new(0, 0));
    for canvas in [Canvas::Same, Canvas::Expand, Canvas::Crop] {
        let (out, _) = apply_shear(&img, Shear::new(0.3, 0.0), Interpolation::Linear, canvas);
        assert_eq!(out.dimensions(), (0, 0));
    }
}

/// The run-time-selected (AVX2) kernels and the baseline ones give identical bytes.
#[test]
fn simd_dispatch_matches_baseline() {
    let src: Vec<u8> = (0..3000u32).map(|i| (i * 37 % 251) as u8).collect();
    let n = 2900;
    let (mut a, mut b) = (vec![0u8; n], vec![0u8; n]);
    linear_u8(&mut a, &src[..n], &src[3..n + 3], 177, 79);
    linear_u8_dispatch(&mut b, &src[..n], &src[3..n + 3], 177, 79);
    assert_eq!(a, b);
    let taps = [&src[..n], &src[3..n + 3], &src[6..n + 6], &src[9..n + 9]];
    let w = [-300, 2900, 1700, -204];
    cubic_u8(&mut a, taps, w);
    cubic_u8_dispatch(&mut b, taps, w);
    assert_eq!(a, b);
}

#[test]
fn the_grey_warp_is_the_dynamic_images_warp() {
    let gray = smooth_gray(37, 29);
    let wrapped = DynamicImage::ImageLuma8(gray.clone());
    for k in [0.0, 0.3, -0.45] {
        for canvas in [Canvas::Same, Canvas::Expand, Canvas::Crop] {
            let shear = Shear::about_middle(k, gray.height());
            let (a, pa) = try_remove_shear_gray(&gray, shear, Interpolation::Linear, canvas)
                .expect("a valid shear");
            let (b, pb) = try_remove_shear(&wrapped, shear, Interpolation::Linear, canvas)
                .expect("a valid shear");
            assert_eq!(pa, pb, "{k} {canvas:?}");
            assert_eq!(DynamicImage::ImageLuma8(a), b, "{k} {canvas:?}");
        }
    }
    assert!(try_remove_shear_gray(
        &gray,
        Shear::new(f64::NAN, 0.0),
        Interpolation::Linear,
        Canvas::Expand
    )
    .is_err());
}

#[test]
fn transposing_swaps_rows_and_columns() {
    let img = DynamicImage::ImageLuma8(GrayImage::from_fn(3, 2, |x, y| Luma([(10 * y + x) as u8])));
    let t = transpose(&img).to_luma8();
    assert_eq!(t.dimensions(), (2, 3));
    for (x, y, p) in t.enumerate_pixels() {
        assert_eq!(p[0], (10 * x + y) as u8, "({x}, {y})");
    }
    assert_eq!(transpose(&transpose(&img)), img);
}

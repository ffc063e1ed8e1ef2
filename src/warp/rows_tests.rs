//! Tests of the per-row warps: [`try_shift_rows`] and [`try_resample_rows`].

use super::*;
use image::{GrayImage, ImageBuffer, Luma, Rgb, Rgb32FImage, RgbImage};

fn smooth(x: f64, y: f64) -> f64 {
    use std::f64::consts::TAU;
    128.0 + 60.0 * (TAU * x / 23.0).sin() + 50.0 * (TAU * (y / 17.0 + x / 71.0)).cos()
}

/// The same smooth content in several sample layouts.
fn images(w: u32, h: u32) -> Vec<DynamicImage> {
    let v = |x: u32, y: u32| smooth(f64::from(x), f64::from(y));
    vec![
        DynamicImage::ImageLuma8(GrayImage::from_fn(w, h, |x, y| Luma([v(x, y) as u8]))),
        DynamicImage::ImageRgb8(RgbImage::from_fn(w, h, |x, y| {
            Rgb([v(x, y) as u8, v(y, x) as u8, (255.0 - v(x, y)) as u8])
        })),
        DynamicImage::ImageLuma16(ImageBuffer::from_fn(w, h, |x, y| {
            Luma([(v(x, y) * 257.0) as u16])
        })),
        DynamicImage::ImageRgb32F(Rgb32FImage::from_fn(w, h, |x, y| {
            let a = v(x, y) as f32 / 255.0;
            Rgb([a, 1.0 - a, a * a])
        })),
    ]
}

fn ramp(k: f64, h: u32) -> Vec<f64> {
    let c = f64::from(h) / 2.0;
    (0..h).map(|y| k * (f64::from(y) - c)).collect()
}

#[test]
fn a_linear_ramp_is_the_shear_bit_for_bit() {
    // `remove_shear` reads in(x + k (y - H / 2), y): the ramp of shifts with the same pivot.
    for (w, h) in [(64u32, 48u32), (37, 29)] {
        for img in images(w, h) {
            for k in [0.3, -0.37, 0.2113, 1.0] {
                for interp in [Interpolation::Linear, Interpolation::Cubic] {
                    let shear = Shear::about_middle(k, h);
                    let want = try_remove_shear(&img, shear, interp, Canvas::Same)
                        .expect("finite")
                        .0;
                    let got = try_shift_rows(&img, &ramp(k, h), interp).expect("finite");
                    assert!(got == want, "{:?} {w}x{h} k={k} {interp:?}", img.color());
                }
            }
        }
    }
    let g = images(50, 40).remove(0).into_luma8();
    let want = try_remove_shear_gray(&g, Shear::about_middle(0.27, 40), Interpolation::Cubic, {
        Canvas::Same
    })
    .expect("finite")
    .0;
    let got = try_shift_rows_gray(&g, &ramp(0.27, 40), Interpolation::Cubic).expect("finite");
    assert_eq!(got, want);
}

#[test]
fn shifts_on_a_canvas_are_the_shear_for_a_ramp_and_crop_leaves_no_fill() {
    for (w, h) in [(64u32, 48u32), (37, 29)] {
        let img = images(w, h).remove(1);
        for k in [0.3, -0.37, 0.2113] {
            for canvas in [Canvas::Same, Canvas::Expand, Canvas::Crop] {
                let shear = Shear::about_middle(k, h);
                let want =
                    try_remove_shear(&img, shear, Interpolation::Cubic, canvas).expect("finite");
                let pivot = f64::from(h) / 2.0;
                let got = try_shift_rows_on(&img, &ramp(k, h), pivot, Interpolation::Cubic, canvas)
                    .expect("finite");
                assert!(got.0 == want.0, "{w}x{h} k={k} {canvas:?}");
                assert_eq!(got.1, want.1, "{w}x{h} k={k} {canvas:?}");
            }
        }
    }
    // A bent table (the offsets of a shear going from 0.1 to 0.5 down the rows) cropped: every
    // pixel of a white image stays white (no fill), and the expanded canvas holds every row.
    let (w, h) = (80u32, 60u32);
    let white = DynamicImage::ImageLuma8(GrayImage::from_pixel(w, h, Luma([255])));
    let shifts: Vec<f64> = (0..h)
        .map(|y| {
            let t = f64::from(y) - 30.0;
            0.3 * t + 0.2 * t * t / 60.0
        })
        .collect();
    let (crop, at) = try_shift_rows_on(&white, &shifts, 30.0, Interpolation::Linear, Canvas::Crop)
        .expect("a rectangle");
    assert!(crop
        .as_luma8()
        .expect("grey")
        .pixels()
        .all(|p| p.0[0] == 255));
    assert!(
        crop.width() > 40 && crop.height() > 30,
        "{}x{} {at:?}",
        crop.width(),
        crop.height()
    );
    let (expand, _) =
        try_shift_rows_on(&white, &shifts, 30.0, Interpolation::Linear, Canvas::Expand)
            .expect("a canvas");
    let spread = shifts.iter().cloned().fold(f64::NEG_INFINITY, f64::max)
        - shifts.iter().cloned().fold(f64::INFINITY, f64::min);
    assert!(f64::from(expand.width()) >= f64::from(w) + spread.floor());
    let total: u64 = expand
        .as_luma8()
        .expect("grey")
        .pixels()
        .map(|p| u64::from(p.0[0]))
        .sum();
    // Every row's content is there: 80 white pixels per row, give or take the edges' blend.
    let per_row = total as f64 / 255.0 / f64::from(h);
    assert!((per_row - f64::from(w)).abs() < 1.0, "{per_row}");
    assert!(try_shift_rows_on(
        &white,
        &shifts[1..],
        30.0,
        Interpolation::Linear,
        Canvas::Crop
    )
    .is_err());
}

/// The centroid of `profile` in a window of `half` samples either side of `around`.
fn centroid(profile: impl Fn(i64) -> f64, around: f64, half: i64) -> f64 {
    let c = around.round() as i64;
    let (mut m0, mut m1) = (0.0, 0.0);
    for i in c - half..=c + half {
        let v = profile(i);
        m0 += v;
        m1 += v * i as f64;
    }
    m1 / m0
}

fn gauss(d: f64, sigma: f64) -> f64 {
    (-0.5 * (d / sigma).powi(2)).exp()
}

#[test]
fn a_curved_shift_moves_a_vertical_line_onto_its_columns() {
    // A vertical line (Gaussian profile, sigma 1.5 px) at x0 = 100.3; the shift is a parabola
    // (a pan slowing down during the readout). out(x, y) = in(x + s(y)) puts the line at
    // x0 - s(y). Measured error: < 0.01 px (8 bits), < 1e-4 (float); asserted < 0.05.
    let (w, h, x0) = (200u32, 120u32, 100.3);
    let shifts: Vec<f64> = (0..h)
        .map(|y| {
            let t = f64::from(y) / f64::from(h - 1);
            -20.0 + 45.0 * t - 30.0 * t * t
        })
        .collect();
    let line = |x: u32| gauss(f64::from(x) - x0, 1.5);
    let gray = DynamicImage::ImageLuma8(GrayImage::from_fn(w, h, |x, _| {
        Luma([(230.0 * line(x)).round() as u8])
    }));
    let float =
        DynamicImage::ImageRgb32F(Rgb32FImage::from_fn(w, h, |x, _| Rgb([line(x) as f32; 3])));
    for img in [gray, float] {
        for interp in [Interpolation::Linear, Interpolation::Cubic] {
            let out = try_shift_rows(&img, &shifts, interp)
                .expect("finite")
                .to_rgb32f();
            let mut worst: f64 = 0.0;
            for (y, &s) in shifts.iter().enumerate() {
                let want = x0 - s;
                let got = centroid(|x| f64::from(out.get_pixel(x as u32, y as u32)[0]), want, 9);
                worst = worst.max((got - want).abs());
            }
            assert!(worst < 0.05, "{:?} {interp:?}: worst {worst}", img.color());
        }
    }
}

#[test]
fn integer_shifts_copy_and_fill_with_zero() {
    let (w, h) = (30u32, 8u32);
    for img in images(w, h) {
        let shifts: Vec<f64> = (0..h)
            .map(|y| [3.0, -2.0, 0.0, 5.0][y as usize % 4])
            .collect();
        for interp in [Interpolation::Linear, Interpolation::Cubic] {
            let out = try_shift_rows(&img, &shifts, interp).expect("finite");
            let (a, b) = (img.to_rgb32f(), out.to_rgb32f());
            for y in 0..h {
                let s = shifts[y as usize] as i64;
                for x in 0..w {
                    let src = i64::from(x) + s;
                    let want = if (0..i64::from(w)).contains(&src) {
                        *a.get_pixel(src as u32, y)
                    } else {
                        Rgb([0.0; 3])
                    };
                    assert_eq!(*b.get_pixel(x, y), want, "{:?} ({x}, {y})", img.color());
                }
            }
        }
    }
}

#[test]
fn bad_tables_are_refused() {
    let img = images(10, 6).remove(1);
    let g = img.to_luma8();
    for bad in [
        vec![0.0; 5],
        vec![0.0; 7],
        {
            let mut v = vec![0.5; 6];
            v[3] = f64::NAN;
            v
        },
        {
            let mut v = vec![0.5; 6];
            v[5] = f64::NEG_INFINITY;
            v
        },
    ] {
        for r in [
            try_shift_rows(&img, &bad, Interpolation::Linear).map(|_| ()),
            try_shift_rows_gray(&g, &bad, Interpolation::Cubic).map(|_| ()),
            try_resample_rows(&img, &bad).map(|_| ()),
        ] {
            assert!(
                matches!(r, Err(Error::InvalidArgument(_))),
                "{bad:?}: {r:?}"
            );
        }
    }
    // Absurd but finite shifts and sources: all fill, no panic.
    let huge = vec![1e300, -1e300, 1e18, -1e18, 4e9, -4e9];
    for interp in [Interpolation::Linear, Interpolation::Cubic] {
        let out = try_shift_rows(&img, &huge, interp).expect("finite");
        assert!(out.to_rgb8().pixels().all(|p| p.0 == [0; 3]));
    }
    let out = try_resample_rows(&img, &huge).expect("finite");
    assert!(out.to_rgb8().pixels().all(|p| p.0 == [0; 3]));
    // Empty images take empty tables.
    let empty = DynamicImage::ImageLuma8(GrayImage::new(5, 0));
    assert_eq!(
        try_shift_rows(&empty, &[], Interpolation::Linear)
            .expect("ok")
            .height(),
        0
    );
    assert_eq!(try_resample_rows(&empty, &[]).expect("ok").height(), 0);
    let narrow = DynamicImage::ImageLuma8(GrayImage::new(0, 3));
    assert!(try_shift_rows(&narrow, &[0.5; 3], Interpolation::Cubic).is_ok());
    assert!(try_resample_rows(&narrow, &[0.5; 3]).is_ok());
}

#[test]
fn resampling_at_the_rows_themselves_is_the_identity() {
    for img in images(33, 21) {
        let same: Vec<f64> = (0..21).map(f64::from).collect();
        assert!(try_resample_rows(&img, &same).expect("finite") == img);
    }
}

#[test]
fn integer_sources_copy_rows_and_fill_outside() {
    let (w, h) = (17u32, 12u32);
    for img in images(w, h) {
        let sources: Vec<f64> = (0..h).map(|y| f64::from(y) + 3.0).collect();
        let out = try_resample_rows(&img, &sources).expect("finite");
        let (a, b) = (img.to_rgb32f(), out.to_rgb32f());
        for y in 0..h {
            for x in 0..w {
                let want = if y + 3 < h {
                    *a.get_pixel(x, y + 3)
                } else {
                    Rgb([0.0; 3])
                };
                assert_eq!(*b.get_pixel(x, y), want, "{:?} ({x}, {y})", img.color());
            }
        }
    }
}

#[test]
fn resampling_blends_two_rows_and_fades_at_the_edges() {
    // Rows of constant value 200 (8 bits) and 0.8 (float). Sources: inside, half a row outside
    // either end (half the value), a whole row and more outside (0).
    let (w, h) = (9u32, 6u32);
    let gray = DynamicImage::ImageLuma8(GrayImage::from_fn(w, h, |_, y| Luma([(40 * y) as u8])));
    let sources = [-0.5, -1.0, 2.25, 5.5, 6.0, -7.0];
    let out = try_resample_rows(&gray, &sources)
        .expect("finite")
        .into_luma8();
    let row = |y: u32| out.get_pixel(3, y)[0];
    assert_eq!(row(0), 0, "half of row 0, which is 0");
    assert_eq!(row(1), 0);
    assert_eq!(row(2), 90, "3/4 of 80 + 1/4 of 120");
    assert_eq!(row(3), 100, "half of row 5 (200)");
    assert_eq!((row(4), row(5)), (0, 0));
    let flat = DynamicImage::ImageLuma16(ImageBuffer::from_pixel(w, h, Luma([40000u16])));
    let out = try_resample_rows(&flat, &sources)
        .expect("finite")
        .into_luma16();
    let got: Vec<u16> = (0..h).map(|y| out.get_pixel(0, y)[0]).collect();
    assert_eq!(got, vec![20000, 0, 40000, 20000, 0, 0]);
}

#[test]
fn a_vertical_stretch_moves_a_horizontal_line_to_its_row() {
    // A horizontal line (Gaussian profile, sigma 1.5 rows) at y0 in a 150-row image; sources
    // s(y) = c + (y - c) / a (the picture stretched by a about c = H / 2) put it at
    // c + (y0 - c) a. Measured error < 0.01 row; asserted < 0.05.
    let (w, h) = (8u32, 150u32);
    let c = f64::from(h) / 2.0;
    for (y0, a) in [(30.4, 1.06), (120.7, 0.93), (75.0, 1.2)] {
        let img = DynamicImage::ImageLuma16(ImageBuffer::from_fn(w, h, |_, y| {
            Luma([(60000.0 * gauss(f64::from(y) - y0, 1.5)).round() as u16])
        }));
        let sources: Vec<f64> = (0..h).map(|y| c + (f64::from(y) - c) / a).collect();
        for img in [img.clone(), DynamicImage::ImageLuma8(img.to_luma8())] {
            let out = try_resample_rows(&img, &sources)
                .expect("finite")
                .into_luma16();
            let want = c + (y0 - c) * a;
            let got = centroid(|y| f64::from(out.get_pixel(4, y as u32)[0]), want, 12);
            assert!(
                (got - want).abs() < 0.05,
                "{:?} y0={y0} a={a}: {got} vs {want}",
                img.color()
            );
        }
    }
}

//! Benchmarks of the row warps.
//!
//! * `remove_shear_rgb8_*`: the shear correction (`warp::remove_shear`, `Canvas::Same`,
//!   k = 0.3) on 8-bit RGB frames of 1920x1080 and 4000x3000, linear and cubic, on the default
//!   rayon pool (all cores) and on a one-thread pool (the target is 1920x1080 RGB in <= 4 ms on
//!   one core).
//! * `rows_gray8_1920x1080` and `rows_yuv420_1920x1080`: one row offset per row (a curved,
//!   quadratic offset, as a pan that changes speed during the readout gives) against the
//!   single-shear path on the same picture, and the vertical row resampling (a 3 % stretch
//!   about the middle row), on one thread. Each group runs the variants back to back, so they
//!   are compared under the same load.
//!
//! Run with `cargo bench --bench warp` (`-- rows_` for the row groups only).

use criterion::{criterion_group, criterion_main, BatchSize, Criterion, Throughput};
use image::{DynamicImage, GrayImage, Luma, Rgb, RgbImage};
use std::hint::black_box;
use unshear::video::{
    remove_shear_yuv, resample_rows_yuv, shift_rows_yuv, Chroma, VideoFormat, YuvFrame,
};
use unshear::warp::{
    remove_shear, try_remove_shear_gray, try_resample_rows, try_shift_rows_gray, Canvas,
    Interpolation,
};
use unshear::Shear;

/// A deterministic, textured test frame (the content does not affect the speed).
fn frame(w: u32, h: u32) -> DynamicImage {
    DynamicImage::ImageRgb8(RgbImage::from_fn(w, h, |x, y| {
        Rgb([
            (x ^ y) as u8,
            (x.wrapping_mul(7) + y) as u8,
            (y.wrapping_mul(3) ^ (x >> 2)) as u8,
        ])
    }))
}

fn bench_remove_shear(c: &mut Criterion) {
    let single = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("a one-thread rayon pool");
    let threads = rayon::current_num_threads();
    for (w, h) in [(1920u32, 1080u32), (4000, 3000)] {
        let img = frame(w, h);
        let shear = Shear::about_middle(0.3, h);
        let mut group = c.benchmark_group(format!("remove_shear_rgb8_{w}x{h}"));
        group.throughput(Throughput::Elements(u64::from(w) * u64::from(h)));
        if w > 2000 {
            group.sample_size(20);
        }
        for interp in [Interpolation::Linear, Interpolation::Cubic] {
            let name = format!("{interp:?}").to_lowercase();
            group.bench_function(format!("{name}/1-thread"), |b| {
                single.install(|| {
                    b.iter(|| remove_shear(black_box(&img), shear, interp, Canvas::Same))
                })
            });
            group.bench_function(format!("{name}/{threads}-threads"), |b| {
                b.iter(|| remove_shear(black_box(&img), shear, interp, Canvas::Same))
            });
        }
        group.finish();
    }
}

const W: u32 = 1920;
const H: u32 = 1080;
const K: f64 = 0.3;

fn gray(w: u32, h: u32) -> GrayImage {
    GrayImage::from_fn(w, h, |x, y| Luma([(x ^ y.wrapping_mul(3)) as u8]))
}

fn yuv420(w: u32, h: u32) -> YuvFrame {
    let format = VideoFormat {
        width: w,
        height: h,
        chroma: Chroma::Yuv420,
        full_range: false,
        frame_rate: (30, 1),
        bit_depth: 8,
    };
    let mut f = YuvFrame::blank(&format);
    f.y = gray(w, h);
    f.u = GrayImage::from_fn(w / 2, h / 2, |x, y| Luma([(x + 2 * y) as u8]));
    f.v = GrayImage::from_fn(w / 2, h / 2, |x, y| Luma([((3 * x) ^ y) as u8]));
    f
}

/// A curved row offset: the shear's ramp bent by a pan that slows down during the readout
/// (about the same range of shifts as the shear, so the edge work is comparable).
fn curved(h: u32) -> Vec<f64> {
    let c = f64::from(h) / 2.0;
    (0..h)
        .map(|y| {
            let t = f64::from(y) - c;
            K * t - 0.2 * K * t * t / c
        })
        .collect()
}

/// A 3 % vertical stretch about the middle row.
fn stretch(h: u32) -> Vec<f64> {
    let c = f64::from(h) / 2.0;
    (0..h).map(|y| c + (f64::from(y) - c) / 1.03).collect()
}

fn bench_rows(c: &mut Criterion) {
    let single = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("a one-thread rayon pool");
    let interp = Interpolation::Linear;
    let shear = Shear::about_middle(K, H);

    let g = gray(W, H);
    let mut group = c.benchmark_group(format!("rows_gray8_{W}x{H}"));
    group.throughput(Throughput::Elements(u64::from(W) * u64::from(H)));
    group.bench_function("shear/linear", |b| {
        single.install(|| {
            b.iter(|| try_remove_shear_gray(black_box(&g), shear, interp, Canvas::Same))
        })
    });
    let shifts = curved(H);
    group.bench_function("shift_rows_curved/linear", |b| {
        single.install(|| b.iter(|| try_shift_rows_gray(black_box(&g), &shifts, interp)))
    });
    let sources = stretch(H);
    let img = DynamicImage::ImageLuma8(g.clone());
    group.bench_function("resample_rows_stretch", |b| {
        single.install(|| b.iter(|| try_resample_rows(black_box(&img), &sources)))
    });
    group.finish();

    let f = yuv420(W, H);
    let mut group = c.benchmark_group(format!("rows_yuv420_{W}x{H}"));
    group.throughput(Throughput::Elements(u64::from(W) * u64::from(H)));
    group.bench_function("shear/linear", |b| {
        single.install(|| {
            b.iter_batched(
                || f.clone(),
                |mut f| {
                    remove_shear_yuv(&mut f, K, interp).expect("finite");
                    f
                },
                BatchSize::LargeInput,
            )
        })
    });
    group.bench_function("shift_rows_curved/linear", |b| {
        single.install(|| {
            b.iter_batched(
                || f.clone(),
                |mut f| {
                    shift_rows_yuv(&mut f, &shifts, interp).expect("finite");
                    f
                },
                BatchSize::LargeInput,
            )
        })
    });
    group.bench_function("resample_rows_stretch", |b| {
        single.install(|| {
            b.iter_batched(
                || f.clone(),
                |mut f| {
                    resample_rows_yuv(&mut f, &sources).expect("finite");
                    f
                },
                BatchSize::LargeInput,
            )
        })
    });
    group.finish();
}

criterion_group!(benches, bench_remove_shear, bench_rows);
criterion_main!(benches);

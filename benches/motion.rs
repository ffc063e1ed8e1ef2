//! Frame-to-frame motion (`MotionEstimator`, feature `dev`): one push of a
//! 1920x1080 and of a 1280x720 luma frame (reduction, 8 band FFTs, cross-power, peak,
//! refinement), alternating two frames of a textured scene 37.4 px apart, default settings, on
//! the default rayon pool.
//!
//! Run with `cargo bench --bench motion`.

use criterion::{criterion_group, criterion_main, Criterion};
use image::{GrayImage, Luma};
use std::hint::black_box;
use unshear::internals::MotionEstimator;
use unshear::video::MotionParams;

/// A smooth random texture (sums of sinusoids), shifted right by `dx`.
fn frame(w: u32, h: u32, dx: f64) -> GrayImage {
    // A fixed pseudo-random sequence (golden-ratio steps), no generator needed.
    let mut t = 0.5f64;
    let mut next = || {
        t = (t + 0.618_033_988_749_895).fract();
        t
    };
    let waves: Vec<(f64, f64, f64, f64)> = (0..24)
        .map(|_| {
            let period = 6.0 + 120.0 * next();
            let angle = std::f64::consts::TAU * next();
            let k = std::f64::consts::TAU / period;
            (
                k * angle.cos(),
                k * angle.sin(),
                6.3 * next(),
                4.0 + 6.0 * next(),
            )
        })
        .collect();
    GrayImage::from_fn(w, h, |x, y| {
        let (x, y) = (f64::from(x) - dx, f64::from(y));
        let v: f64 = waves
            .iter()
            .map(|&(kx, ky, p, a)| a * (kx * x + ky * y + p).sin())
            .sum();
        Luma([(128.0f64 + v).clamp(0.0, 255.0) as u8])
    })
}

fn bench(c: &mut Criterion) {
    for (w, h) in [(1920, 1080), (1280, 720)] {
        let frames = [frame(w, h, 0.0), frame(w, h, 37.4)];
        let mut m = MotionEstimator::new(MotionParams::default());
        m.push(&frames[0]);
        let mut i = 0;
        c.bench_function(&format!("motion push {w}x{h}"), |b| {
            b.iter(|| {
                i += 1;
                black_box(m.push(black_box(&frames[i % 2])))
            })
        });
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);

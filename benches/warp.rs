//! Benchmarks of the shear correction (`warp::remove_shear`, `Canvas::Same`, k = 0.3) on 8-bit RGB
//! frames of 1920x1080 and 4000x3000, linear and cubic, on the default rayon pool (all cores) and
//! on a one-thread pool (the target is 1920x1080 RGB in <= 4 ms on one core).
//!
//! Run with `cargo bench --bench warp`.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use image::{DynamicImage, Rgb, RgbImage};
use std::hint::black_box;
use unshear::warp::{remove_shear, Canvas, Interpolation};
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

criterion_group!(benches, bench_remove_shear);
criterion_main!(benches);

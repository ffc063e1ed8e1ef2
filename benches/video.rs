//! End-to-end video throughput on a synthetic 1920x1080 4:2:0 clip: parse y4m bytes, track and
//! detect the face, estimate, filter, correct all three planes, serialise y4m, on the default
//! rayon pool (all cores). A Yale fixture face, scaled 3x (a face box of about 440 px), pans
//! across the frame with a shear that follows the pan speed.
//!
//! Run with `cargo bench --bench video`; criterion's "thrpt" line is frames per second. Two
//! variants: the default locator (the landmark network) and `Locator::Filters`.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use image::{imageops, DynamicImage, GrayImage, Luma};
use std::hint::black_box;
use unshear::pipeline::Locator;
use unshear::video::y4m::{Y4mReader, Y4mWriter};
use unshear::video::{run, Chroma, ProcessOptions, VideoFormat, VideoProcessor, YuvFrame};
use unshear::warp::{apply_shear, Canvas, Interpolation};
use unshear::{Shear, Unshear};

const W: u32 = 1920;
const H: u32 = 1080;
const FRAMES: usize = 60;

/// The clip as y4m bytes.
fn clip() -> Vec<u8> {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/fixtures/faces/subject01.normal.jpeg"
    );
    let face = unshear::imageio::read_image(path.as_ref(), 1 << 24)
        .expect("fixture")
        .to_luma8();
    let face = imageops::resize(&face, 960, 729, imageops::FilterType::Triangle);
    let format = VideoFormat {
        width: W,
        height: H,
        chroma: Chroma::Yuv420,
        full_range: false,
        frame_rate: (30, 1),
        bit_depth: 8,
    };
    let mut w = Y4mWriter::new(Vec::new(), &format).expect("header");
    for t in 0..FRAMES {
        let k = 0.2 * (t as f64 / FRAMES as f64 * std::f64::consts::TAU).sin();
        let x = 480 + (200.0 * (t as f64 / FRAMES as f64 * std::f64::consts::TAU).cos()) as i64;
        let mut scene = GrayImage::from_pixel(W, H, Luma([110]));
        imageops::overlay(&mut scene, &face, x, 170);
        let (sheared, _) = apply_shear(
            &DynamicImage::ImageLuma8(scene),
            Shear::about_middle(k, H),
            Interpolation::Linear,
            Canvas::Same,
        );
        let mut f = YuvFrame::blank(&format);
        f.y = sheared.to_luma8();
        // Some colour, so the chroma planes are not trivially flat.
        for (x, y, p) in f.u.enumerate_pixels_mut() {
            p[0] = (96 + (x + y) % 64) as u8;
        }
        w.write_frame(&f).expect("frame");
    }
    w.finish().expect("flush")
}

fn bench_video(c: &mut Criterion) {
    let bytes = clip();
    let mut group = c.benchmark_group("video_1920x1080_420");
    group.throughput(Throughput::Elements(FRAMES as u64));
    group.sample_size(10);
    // The default locator (the landmark network), then the filters for comparison.
    for (name, locator) in [
        ("end_to_end_60_frames", Locator::Network),
        ("end_to_end_60_frames_filters", Locator::Filters),
    ] {
        let unshear = Unshear::new(unshear::Config {
            locator,
            ..unshear::Config::default()
        })
        .expect("built-in models");
        group.bench_function(name, |b| {
            b.iter(|| {
                let mut reader =
                    Y4mReader::new(black_box(bytes.as_slice()), 1 << 24).expect("clip");
                let mut writer =
                    Y4mWriter::with_header(Vec::with_capacity(bytes.len()), reader.header())
                        .expect("header");
                let mut processor = VideoProcessor::new(&unshear, ProcessOptions::default());
                let mut faces = 0usize;
                run(&mut reader, Some(&mut writer), &mut processor, |r| {
                    faces += r.faces.len()
                })
                .expect("run");
                assert!(
                    faces >= FRAMES * 9 / 10,
                    "face found in most frames: {faces}"
                );
                writer.finish().expect("flush")
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench_video);
criterion_main!(benches);

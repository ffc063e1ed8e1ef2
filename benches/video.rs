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

/// One pass over the clip's bytes as `unshear video in.y4m -o -` makes it (parse, process,
/// serialise); `on_frame` sees each frame's result.
fn run_clip(
    bytes: &[u8],
    unshear: &Unshear,
    options: ProcessOptions,
    on_frame: impl FnMut(&unshear::video::FrameResult),
) -> Vec<u8> {
    let mut reader = Y4mReader::new(black_box(bytes), 1 << 24).expect("clip");
    let mut writer =
        Y4mWriter::with_header(Vec::with_capacity(bytes.len()), reader.header()).expect("header");
    let mut processor = VideoProcessor::new(unshear, options);
    run(&mut reader, Some(&mut writer), &mut processor, on_frame).expect("run");
    writer.finish().expect("flush")
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
                let mut faces = 0usize;
                let out = run_clip(&bytes, &unshear, ProcessOptions::default(), |r| {
                    faces += r.faces.len()
                });
                assert!(
                    faces >= FRAMES * 9 / 10,
                    "face found in most frames: {faces}"
                );
                out
            })
        });
    }
    group.finish();
}

/// A physically made pan (the rolling-shutter simulator over the three fixture faces: rows
/// read over 0.8 of the frame interval, a pan that stops and turns with peak k 0.25, 1/250 s
/// of motion blur), as y4m bytes.
fn pan_clip() -> Vec<u8> {
    use unshear::dev::simulate::{Profile, Scene, ScenePhoto, SimulationParams, Simulator};
    let photos: Vec<ScenePhoto> = ["subject01", "subject03", "subject14"]
        .iter()
        .map(|name| ScenePhoto {
            image: unshear::imageio::read_image(
                format!(
                    "{}/tests/fixtures/faces/{name}.normal.jpeg",
                    env!("CARGO_MANIFEST_DIR")
                )
                .as_ref(),
                1 << 24,
            )
            .expect("fixture"),
            faces: Vec::new(),
        })
        .collect();
    let scene = Scene::from_images(&photos, H).expect("scene");
    let rho = 0.8;
    let params = SimulationParams {
        width: W,
        height: H,
        frames: FRAMES as u32,
        readout_fraction: rho,
        motion: Profile::Pause {
            v: 0.25 * f64::from(H) / rho,
        },
        ..SimulationParams::default()
    };
    let sim = Simulator::new(scene, params).expect("simulator");
    let format = VideoFormat {
        width: W,
        height: H,
        chroma: Chroma::Yuv420,
        full_range: false,
        frame_rate: (30, 1),
        bit_depth: 8,
    };
    let mut w = Y4mWriter::new(Vec::new(), &format).expect("header");
    for n in 0..FRAMES as u32 {
        let (img, _) = sim.render(n).expect("render");
        let f = unshear::video::color::image_to_yuv(
            &DynamicImage::ImageRgb8(img),
            Chroma::Yuv420,
            false,
        );
        w.write_frame(&f).expect("frame");
    }
    w.finish().expect("flush")
}

/// The pan: today's faces-only model against motion as the ruler (the readout calibrated on
/// the clip, as `unshear video` does, and given), in the same run.
fn bench_pan(c: &mut Criterion) {
    let bytes = pan_clip();
    let mut group = c.benchmark_group("video_1920x1080_pan");
    group.throughput(Throughput::Elements(FRAMES as u64));
    group.sample_size(10);
    let unshear = Unshear::new(unshear::Config::video()).expect("built-in models");
    let base = ProcessOptions {
        network_budget: unshear.config().network_budget,
        ..ProcessOptions::default()
    };
    for (name, options) in [
        (
            "faces_alone",
            ProcessOptions {
                motion: false,
                ..base
            },
        ),
        (
            "motion_calibrated",
            ProcessOptions {
                calibration_window: unshear::video::DEFAULT_CALIBRATION_WINDOW,
                ..base
            },
        ),
        (
            "motion_given",
            ProcessOptions {
                readout_fraction: Some(0.8),
                ..base
            },
        ),
    ] {
        group.bench_function(name, |b| {
            b.iter(|| run_clip(&bytes, &unshear, options, |_| {}))
        });
    }
    group.finish();
}

criterion_group!(benches, bench_video, bench_pan);
criterion_main!(benches);

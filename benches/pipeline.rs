//! Pipeline benchmarks: the estimate for one face once it is detected (target <= 1 ms), with the
//! landmark network (the default) and with the filters, upright and sheared by 0.3 (where the
//! network's walk takes more than one crop; also held to one crop), one forward pass of the
//! network and one rendering of its crop; a tilted head, searched again upright, separately;
//! face detection and the face proposals on a 1920x1080 frame, and the whole estimate of a
//! frame with one face and with none, with the thorough (default) and the quick face search.
//! Correction speed is in `benches/warp.rs`.
//!
//! The `realistic` groups time whole frames as users give them: 1920x1080 scenes composed from
//! the development photos (a face on clutter, the same sheared by 0.3, no face, eight faces) and
//! a 4000x3000 photo ([`common::scenes`]), each in memory and end to end from a JPEG file (read
//! and estimate, as `unshear estimate`; read, estimate, correct and write, as `unshear correct`),
//! beside the synthetic grey-canvas frame in the same run as a baseline. Without
//! `../shared/data` they say so and time the synthetic frame alone.
//!
//! Run: `cargo bench --bench pipeline` (the realistic rows alone: `-- realistic`; with
//! `--features dev` each frame's landmark network runs are printed too).

use criterion::{criterion_group, criterion_main, Criterion};
use image::imageops::FilterType;
use unshear::locate::network::{Budget, LandmarkNet, Workspace};
use unshear::pipeline::Detection;
use unshear::{Config, CorrectOptions, FaceStart, Locator, Unshear};

mod common;
use common::scenes::{self, Scene};

fn fixture() -> image::DynamicImage {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/fixtures/faces/subject01.normal.jpeg"
    );
    match unshear::imageio::read_image(path.as_ref(), unshear::imageio::DEFAULT_MAX_PIXELS) {
        Ok(img) => img,
        Err(e) => panic!("fixture: {e}"),
    }
}

fn single_thread<R>(f: impl FnOnce() -> R + Send) -> R
where
    R: Send,
{
    match rayon::ThreadPoolBuilder::new().num_threads(1).build() {
        Ok(pool) => pool.install(f),
        Err(e) => panic!("thread pool: {e}"),
    }
}

/// Where the pipeline starts a detection's estimate: the view it was found in.
fn start(d: &Detection) -> FaceStart {
    FaceStart {
        k: d.view_k,
        roll: d.view_roll,
        budget: None,
    }
}

fn bench(c: &mut Criterion) {
    let unshear = match Unshear::new(unshear::Config::default()) {
        Ok(u) => u,
        Err(e) => panic!("models: {e}"),
    };
    let img = fixture();
    let gray = Unshear::gray(&img);
    let face = unshear.cascade_detector().detect(&gray)[0];
    c.bench_function("estimate one face (after detection)", |b| {
        b.iter(|| unshear.estimate_face(&gray, face, FaceStart::default()))
    });
    let with_filters = match Unshear::new(Config {
        locator: Locator::Filters,
        ..Config::default()
    }) {
        Ok(u) => u,
        Err(e) => panic!("models: {e}"),
    };
    c.bench_function("estimate one face, filters (after detection)", |b| {
        b.iter(|| with_filters.estimate_face(&gray, face, FaceStart::default()))
    });
    let net = match LandmarkNet::embedded() {
        Ok(n) => n,
        Err(e) => panic!("network: {e}"),
    };
    let crop = vec![128.0f32; net.size() * net.size()];
    let mut workspace = Workspace::default();
    c.bench_function("landmark network, one crop", |b| {
        b.iter(|| net.run(&crop, &mut workspace).shear)
    });
    // Rendering one crop for the network (sheared 0.2, rolled 0.1 rad) from the fixture, at
    // about one and about two image pixels per crop pixel (2x2 and 3x3 reads per crop pixel).
    for eye_distance in [30.0, 60.0] {
        let frame = net.frame(unshear::Point::new(160.0, 110.0), eye_distance, 0.2, 0.1);
        let name = format!("landmark crop render, eyes {eye_distance} px apart");
        c.bench_function(&name, |b| b.iter(|| frame.render(&gray)));
    }
    // A head tilted by 22 degrees: its features are searched again in the face turned upright.
    let tilted = match unshear::warp::rotate::rotate_gray(&gray, 22f64.to_radians()) {
        Ok((t, _)) => t,
        Err(e) => panic!("rotate: {e}"),
    };
    let Some(&tilted_face) = unshear.detect(&tilted).first() else {
        panic!("the tilted fixture must be found");
    };
    c.bench_function(
        "estimate one face tilted 22 degrees (after detection)",
        |b| b.iter(|| unshear.estimate_face(&tilted, tilted_face.face_box, start(&tilted_face))),
    );

    // The same face sheared by 0.3, detected as the pipeline detects it (its de-sheared views):
    // the walk of crops takes several crops here, as real faces do, where the upright bench
    // face settles in one.
    let sheared = match unshear::warp::try_apply_shear(
        &img,
        unshear::Shear::about_middle(0.3, img.height()),
        unshear::warp::Interpolation::Linear,
        unshear::warp::Canvas::Expand,
    ) {
        Ok((s, _)) => Unshear::gray(&s),
        Err(e) => panic!("shear: {e}"),
    };
    let Some(&sheared_face) = unshear.detect(&sheared).first() else {
        panic!("the sheared fixture must be found");
    };
    c.bench_function("estimate one face sheared 0.3 (after detection)", |b| {
        b.iter(|| unshear.estimate_face(&sheared, sheared_face.face_box, start(&sheared_face)))
    });
    let Some(&sheared_face_filters) = with_filters.detect(&sheared).first() else {
        panic!("the sheared fixture must be found with the filters' search too");
    };
    c.bench_function(
        "estimate one face sheared 0.3, filters (after detection)",
        |b| {
            b.iter(|| {
                with_filters.estimate_face(
                    &sheared,
                    sheared_face_filters.face_box,
                    start(&sheared_face_filters),
                )
            })
        },
    );
    // The same with the network held to one crop (`--max-crops 1`), the same detection.
    let one_crop = match Unshear::new(Config {
        network_budget: Budget {
            max_passes: 1,
            ..Budget::STILL
        },
        ..Config::default()
    }) {
        Ok(u) => u,
        Err(e) => panic!("models: {e}"),
    };
    c.bench_function(
        "estimate one face sheared 0.3, one crop (after detection)",
        |b| {
            b.iter(|| one_crop.estimate_face(&sheared, sheared_face.face_box, start(&sheared_face)))
        },
    );

    // A 1920x1080 frame: the fixture enlarged to full height, on a mid-grey canvas.
    let big = img.resize(1920, 1080, FilterType::Triangle).to_luma8();
    let mut frame = image::GrayImage::from_pixel(1920, 1080, image::Luma([128]));
    image::imageops::overlay(&mut frame, &big, ((1920 - big.width()) / 2) as i64, 0);
    let mut group = c.benchmark_group("detect 1920x1080");
    group.sample_size(10);
    group.bench_function("1 thread", |b| {
        single_thread(|| b.iter(|| unshear.cascade_detector().detect(&frame)))
    });
    group.bench_function("all threads", |b| {
        b.iter(|| unshear.cascade_detector().detect(&frame))
    });
    // `--min-face 60`: the smallest scales, where most windows are, skipped.
    let min_face_60 = unshear::detect::FaceDetector::new(
        unshear::detect::Cascade::frontal_face_alt2(),
        unshear::detect::DetectorParams {
            min_size: (60, 60),
            ..Default::default()
        },
    );
    group.bench_function("min face 60, 1 thread", |b| {
        single_thread(|| b.iter(|| min_face_60.detect(&frame)))
    });
    group.bench_function("min face 60, all threads", |b| {
        b.iter(|| min_face_60.detect(&frame))
    });
    // The thorough search's face proposals (its smallest eye distance: 60 px boxes).
    let proposals = match unshear::detect::ProposalNet::embedded() {
        Ok(p) => p,
        Err(e) => panic!("proposal classifier: {e}"),
    };
    let params = unshear::detect::ProposalParams {
        min_eye_distance: unshear::pipeline::WEAK_BOX_MIN_WIDTH
            * unshear::detect::boxes::EYE_DISTANCE_PER_BOX_WIDTH,
        ..Default::default()
    };
    group.bench_function("face proposals, 1 thread", |b| {
        single_thread(|| b.iter(|| proposals.propose(&frame, &params)))
    });
    group.bench_function("face proposals, all threads", |b| {
        b.iter(|| proposals.propose(&frame, &params))
    });
    // The single-pass detector (`models/detector.bin`) for faces from 40 px boxes (eye distance
    // 15.2 px), with its own pyramid step and threshold.
    let detector = match unshear::detect::ProposalNet::embedded_detector() {
        Ok(p) => p,
        Err(e) => panic!("face detector: {e}"),
    };
    let detector_params = unshear::detect::ProposalParams {
        min_eye_distance: 40.0 * unshear::detect::boxes::EYE_DISTANCE_PER_BOX_WIDTH,
        ..detector.default_params()
    };
    let proposals_40 = unshear::detect::ProposalParams {
        min_eye_distance: 40.0 * unshear::detect::boxes::EYE_DISTANCE_PER_BOX_WIDTH,
        ..Default::default()
    };
    group.bench_function("face proposals from 40 px boxes, all threads", |b| {
        b.iter(|| proposals.propose(&frame, &proposals_40))
    });
    group.bench_function("face detector, 1 thread", |b| {
        single_thread(|| b.iter(|| detector.propose(&frame, &detector_params)))
    });
    group.bench_function("face detector, all threads", |b| {
        b.iter(|| detector.propose(&frame, &detector_params))
    });
    group.finish();

    // The default (the network detector), and the Viola-Jones searches in the same run:
    // `--thorough` and `--quick`.
    let thorough = match Unshear::new(Config::thorough()) {
        Ok(u) => u,
        Err(e) => panic!("models: {e}"),
    };
    let quick = match Unshear::new(Config::quick()) {
        Ok(u) => u,
        Err(e) => panic!("models: {e}"),
    };
    let searches = [
        ("", &unshear),
        ("thorough, ", &thorough),
        ("quick, ", &quick),
    ];
    // The same frame sheared by 0.3: the thorough search also turns the image de-sheared by the
    // shear its face measured (four detections more).
    let sheared = unshear::warp::apply_shear(
        &image::DynamicImage::ImageLuma8(frame.clone()),
        unshear::Shear::about_middle(0.3, frame.height()),
        unshear::warp::Interpolation::Linear,
        unshear::warp::Canvas::Same,
    )
    .0
    .into_luma8();
    // No face: the Viola-Jones searches search every de-sheared and turned view (13
    // detections, then 8 turned and de-sheared ones thoroughly; 7 quickly, whose turned views
    // are at 12 degrees only).
    let mut state = 0x2545_f491_u32;
    let noise = image::GrayImage::from_fn(1920, 1080, |_, _| {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        image::Luma([(state >> 24) as u8])
    });
    // A sheared frame with one small face (the fixture at a quarter of the frame's height, its
    // face box about 155 px wide): the default searches the image de-sheared by the shear
    // measured again, from half that face's size.
    let quarter = img.resize(1920, 270, FilterType::Triangle).to_luma8();
    let mut small = image::GrayImage::from_pixel(1920, 1080, image::Luma([128]));
    image::imageops::overlay(&mut small, &quarter, 800, 400);
    let small_sheared = unshear::warp::apply_shear(
        &image::DynamicImage::ImageLuma8(small),
        unshear::Shear::about_middle(0.3, 1080),
        unshear::warp::Interpolation::Linear,
        unshear::warp::Canvas::Same,
    )
    .0
    .into_luma8();
    let mut group = c.benchmark_group("estimate whole 1920x1080 frame");
    group.sample_size(10);
    group.bench_function("sheared 0.3, small face, all threads", |b| {
        b.iter(|| unshear.estimate_gray(&small_sheared))
    });
    for (name, u) in searches {
        group.bench_function(format!("{name}all threads"), |b| {
            b.iter(|| u.estimate_gray(&frame))
        });
        group.bench_function(format!("sheared 0.3, {name}all threads"), |b| {
            b.iter(|| u.estimate_gray(&sheared))
        });
        group.bench_function(format!("no face, {name}all threads"), |b| {
            b.iter(|| u.estimate_gray(&noise))
        });
    }
    group.finish();

    // A 4000x3000 photo: the fixture enlarged to full height on a mid-grey canvas (the
    // thorough search takes tens of seconds here: left out).
    let big = img.resize(4000, 3000, FilterType::Triangle).to_luma8();
    let mut photo = image::GrayImage::from_pixel(4000, 3000, image::Luma([128]));
    image::imageops::overlay(&mut photo, &big, ((4000 - big.width()) / 2) as i64, 0);
    let mut group = c.benchmark_group("estimate whole 4000x3000 photo");
    group.sample_size(10);
    for (name, u) in [("", &unshear), ("quick, ", &quick)] {
        group.bench_function(format!("{name}all threads"), |b| {
            b.iter(|| u.estimate_gray(&photo))
        });
    }
    group.finish();
}

/// Estimates a frame in memory, from a JPEG file, and from a JPEG file to a corrected JPEG, as
/// the CLI's `estimate` and `correct` do (read with metadata, estimate, correct when a shear was
/// found, write).
fn whole_frames(
    group: &mut criterion::BenchmarkGroup<'_, criterion::measurement::WallTime>,
    unshear: &Unshear,
    scenes: &[Scene],
    dir: &std::path::Path,
) {
    use unshear::imageio::{self, WriteOptions};
    let max = imageio::DEFAULT_MAX_PIXELS;
    for scene in scenes {
        let stem = scene
            .name
            .replace([' ', ',', ':', '.'], "-")
            .replace("--", "-");
        let input = dir.join(format!("{stem}.jpg"));
        let output = dir.join(format!("{stem}.corrected.jpg"));
        if let Err(e) = imageio::write_image_atomic(
            &scene.image,
            &input,
            WriteOptions {
                overwrite: true,
                ..Default::default()
            },
        ) {
            panic!("writing {}: {e}", input.display());
        }
        #[cfg(feature = "dev")]
        let runs_before = unshear::internals::landmark_network_runs();
        let report = unshear.estimate(&scene.image);
        // The landmark network's runs for the frame (counted with feature `dev` only).
        #[cfg(feature = "dev")]
        let runs = format!(
            ", {} landmark network runs",
            unshear::internals::landmark_network_runs() - runs_before
        );
        #[cfg(not(feature = "dev"))]
        let runs = String::new();
        eprintln!(
            "{}: {} face(s) found, {} accepted, k = {:?}{runs}",
            scene.name,
            report.faces.len(),
            report.faces.iter().filter(|f| f.k.is_some()).count(),
            report.k
        );
        group.bench_function(format!("{}, in memory", scene.name), |b| {
            b.iter(|| unshear.estimate(&scene.image))
        });
        group.bench_function(format!("{}, file: read + estimate", scene.name), |b| {
            b.iter(|| match imageio::read_image_with_metadata(&input, max) {
                Ok((img, metadata)) => unshear.estimate_photo(&img, &metadata),
                Err(e) => panic!("reading {}: {e}", input.display()),
            })
        });
        group.bench_function(
            format!("{}, file: read + estimate + correct + write", scene.name),
            |b| {
                b.iter(|| {
                    let (img, metadata) = match imageio::read_image_with_metadata(&input, max) {
                        Ok(v) => v,
                        Err(e) => panic!("reading {}: {e}", input.display()),
                    };
                    let report = unshear.estimate_photo(&img, &metadata);
                    let options = CorrectOptions::default();
                    if !options.changes(&report) {
                        return;
                    }
                    let fixed = match Unshear::correct(&img, &report, &options) {
                        Ok(f) => f,
                        Err(e) => panic!("correct: {e}"),
                    };
                    drop(img);
                    let written = imageio::write_image_atomic(
                        &fixed,
                        &output,
                        WriteOptions {
                            overwrite: true,
                            metadata,
                            ..Default::default()
                        },
                    );
                    if let Err(e) = written {
                        panic!("writing {}: {e}", output.display());
                    }
                })
            },
        );
    }
}

/// Whole frames as users give them (see the module's documentation).
fn realistic(c: &mut Criterion) {
    let unshear = match Unshear::new(Config::default()) {
        Ok(u) => u,
        Err(e) => panic!("models: {e}"),
    };
    // The scenes' JPEGs go to a temporary folder, or are kept in `UNSHEAR_BENCH_SCENES` (to time
    // the command line on the same files).
    let temp = match tempfile::tempdir() {
        Ok(d) => d,
        Err(e) => panic!("temporary folder: {e}"),
    };
    let dir = match std::env::var_os("UNSHEAR_BENCH_SCENES") {
        Some(d) => std::path::PathBuf::from(d),
        None => temp.path().to_path_buf(),
    };
    if let Err(e) = std::fs::create_dir_all(&dir) {
        panic!("{}: {e}", dir.display());
    }
    let (mut frames, photo) = match scenes::realistic() {
        Ok((frames, photo)) => (frames, Some(photo)),
        Err(why) => {
            eprintln!(
                "realistic frames skipped: {why}; timing the synthetic grey-canvas frame alone"
            );
            (Vec::new(), None)
        }
    };
    frames.push(scenes::grey_canvas());
    let mut group = c.benchmark_group("realistic 1920x1080");
    group.sample_size(10);
    whole_frames(&mut group, &unshear, &frames, &dir);
    group.finish();
    if let Some(photo) = photo {
        let mut group = c.benchmark_group("realistic 4000x3000");
        group.sample_size(10);
        whole_frames(&mut group, &unshear, &[photo], &dir);
        group.finish();
    }
}

criterion_group!(benches, bench, realistic);
criterion_main!(benches);

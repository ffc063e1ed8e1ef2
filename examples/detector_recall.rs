//! Measures the single-pass face detector (`models/detector.bin`) against the proposal
//! classifier (`models/proposals.bin`) on the Caltech development faces the accuracy tables
//! measure (eyes at least 40 px apart, none of whose photos either network was trained on), and
//! times both on a 1920x1080 frame and a 4000x3000 image.
//!
//! ```sh
//! cargo run --release --example detector_recall -- ../shared/data/caltech-webfaces
//! cargo run --release --example detector_recall -- ../shared/data/caltech-webfaces --time-only
//! ```
//!
//! Each photo is sheared as a whole by each `k` (0, +0.4, -0.4, about its middle row, the canvas
//! grown to hold it), both networks are run over it from eye distance 15.2 px (a 40 px
//! detector box) with their default searches, and a face counts as found by:
//! * the detector when a proposal's regressed eyes' midpoint is within 0.25 of the face's eye
//!   distance of the annotated one and its eye distance within 20% (`strict`);
//! * the proposal classifier when a window's eyes are within 0.5 eye distances and its size
//!   within 1.5 times (`loose`, what the landmark network needs from it).
//!
//! Both criteria are printed for both networks, with the proposals per photo that match no face
//! by the loose criterion, and the median error of the detector's regressed shear and roll
//! (against the applied `k` and the annotated eyes' slant) on the faces it finds.

use std::path::PathBuf;
use std::time::Instant;

use image::GrayImage;
use unshear::detect::{Proposal, ProposalNet, ProposalParams};
use unshear::dev::dataset::{by_image, AnnotatedFace, CaltechWebFaces, FaceDataset};
use unshear::warp::{try_apply_shear, Canvas, Interpolation};
use unshear::{Point, Shear};

/// Smallest eye distance searched: a 40 px detector box.
const MIN_EYE_DISTANCE: f64 = 40.0 * unshear::detect::boxes::EYE_DISTANCE_PER_BOX_WIDTH;
/// The faces measured.
const MEASURED_EYE_DISTANCE: f64 = 40.0;
const SHEARS: [f64; 3] = [0.0, 0.4, -0.4];

#[derive(Default)]
struct Tally {
    faces: usize,
    strict: usize,
    loose: usize,
    unmatched: usize,
    proposals: usize,
    k_errors: Vec<f64>,
    /// Of the faces found loosely but not strictly: eyes more than 0.25 ED off, size off by
    /// more than 20%.
    off_eyes: usize,
    off_size: usize,
    /// The signed log size error of the faces found loosely.
    log_size: Vec<f64>,
    roll_errors: Vec<f64>,
    seconds: f64,
}

fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn matches(p: &Proposal, eyes: Point, d: f64, offset: f64, ratio: f64) -> bool {
    p.eyes_midpoint.distance(eyes) < offset * d && (p.eye_distance / d).ln().abs() < ratio.ln()
}

/// The median wall time of `runs` calls of `f`, milliseconds.
fn time(runs: usize, mut f: impl FnMut() -> usize) -> f64 {
    let mut times: Vec<f64> = (0..runs)
        .map(|_| {
            let start = Instant::now();
            std::hint::black_box(f());
            start.elapsed().as_secs_f64() * 1000.0
        })
        .collect();
    median(&mut times)
}

/// The calling thread's CPU time, milliseconds: on a machine shared with other work, the time
/// a call costs, which the wall time is not.
fn thread_cpu_ms() -> f64 {
    let mut t = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `t` is a valid timespec for the call to write.
    unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut t) };
    t.tv_sec as f64 * 1000.0 + t.tv_nsec as f64 / 1e6
}

/// The median CPU time of `runs` calls of `f` on one thread (a pool of one), milliseconds.
fn cpu_time_one_thread(runs: usize, f: impl Fn() -> usize + Send + Sync) -> f64 {
    let Ok(pool) = rayon::ThreadPoolBuilder::new().num_threads(1).build() else {
        return f64::NAN;
    };
    let mut times: Vec<f64> = pool.install(|| {
        (0..runs)
            .map(|_| {
                let start = thread_cpu_ms();
                std::hint::black_box(f());
                thread_cpu_ms() - start
            })
            .collect()
    });
    median(&mut times)
}

fn timings(nets: &[(&str, &ProposalNet, ProposalParams)], fixture: &GrayImage) {
    for (w, h) in [(1920u32, 1080u32), (4000, 3000)] {
        // The fixture face enlarged to the frame's height on a mid-grey canvas (as the
        // pipeline benchmark's frame).
        let big = image::imageops::resize(
            fixture,
            fixture.width() * h / fixture.height(),
            h,
            image::imageops::FilterType::Triangle,
        );
        let mut frame = GrayImage::from_pixel(w, h, image::Luma([128]));
        image::imageops::overlay(&mut frame, &big, i64::from((w - big.width()) / 2), 0);
        for (name, net, params) in nets {
            let runs = if w > 2000 { 7 } else { 21 };
            let ms = time(runs, || net.propose(&frame, params).len());
            let cpu = cpu_time_one_thread(runs, || net.propose(&frame, params).len());
            println!(
                "{w}x{h} {name}: {} threads, median wall time {ms:.1} ms; 1 thread, median CPU \
                 time {cpu:.1} ms ({runs} runs each)",
                rayon::current_num_threads()
            );
        }
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(data) = args.first() else {
        return Err("usage: detector_recall CALTECH_DIR [--time-only] [--detector-only]".into());
    };
    let detector = ProposalNet::embedded_detector()?;
    let classifier = ProposalNet::embedded()?;
    let detector_params = ProposalParams {
        min_eye_distance: MIN_EYE_DISTANCE,
        ..detector.default_params()
    };
    let classifier_params = ProposalParams {
        min_eye_distance: MIN_EYE_DISTANCE,
        ..classifier.default_params()
    };
    let mut nets = vec![
        ("detector.bin", &detector, detector_params),
        ("proposals.bin", &classifier, classifier_params),
    ];
    if args.iter().any(|a| a == "--detector-only") {
        nets.truncate(1);
    }
    let fixture = image::open(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/fixtures/faces/subject01.normal.jpeg"
    ))?
    .into_luma8();
    timings(&nets, &fixture);
    if args.iter().any(|a| a == "--time-only") {
        return Ok(());
    }
    let photos: Vec<(PathBuf, Vec<AnnotatedFace>)> = by_image(CaltechWebFaces::new(data).faces()?)
        .into_iter()
        .filter(|(_, faces)| {
            faces
                .iter()
                .any(|f| f.eye_distance() >= MEASURED_EYE_DISTANCE)
        })
        .collect();
    let mut tallies: Vec<Vec<Tally>> = SHEARS
        .iter()
        .map(|_| nets.iter().map(|_| Tally::default()).collect())
        .collect();
    for (path, faces) in &photos {
        let img = unshear::imageio::read_image(path, unshear::imageio::DEFAULT_MAX_PIXELS)?;
        let gray = unshear::detect::to_gray_opencv(&img);
        for (si, &k) in SHEARS.iter().enumerate() {
            let shear = Shear::about_middle(k, gray.height());
            let (sheared, placement) = try_apply_shear(
                &image::DynamicImage::ImageLuma8(gray.clone()),
                shear,
                Interpolation::Linear,
                Canvas::Expand,
            )?;
            let sheared = sheared.into_luma8();
            let moved = |p: Point| placement.from_frame(shear.apply(p));
            let truth: Vec<(Point, f64, f64, bool)> = faces
                .iter()
                .map(|f| {
                    let (r, l) = (f.right_eye, f.left_eye);
                    let roll = (l.y - r.y).atan2(l.x - r.x);
                    let measured = f.eye_distance() >= MEASURED_EYE_DISTANCE;
                    (
                        moved(r).midpoint(moved(l)),
                        f.eye_distance(),
                        roll,
                        measured,
                    )
                })
                .collect();
            for (ni, (_, net, params)) in nets.iter().enumerate() {
                let start = Instant::now();
                let found = net.propose(&sheared, params);
                let t = &mut tallies[si][ni];
                t.seconds += start.elapsed().as_secs_f64();
                t.proposals += found.len();
                t.unmatched += found
                    .iter()
                    .filter(|p| !truth.iter().any(|&(e, d, ..)| matches(p, e, d, 0.5, 1.5)))
                    .count();
                for &(eyes, d, roll, measured) in &truth {
                    if !measured {
                        continue;
                    }
                    t.faces += 1;
                    let strict = found.iter().find(|p| matches(p, eyes, d, 0.25, 1.2));
                    if let Some(p) = strict {
                        t.strict += 1;
                        t.k_errors.push((p.k - k).abs());
                        t.roll_errors.push((p.roll - roll).abs().to_degrees());
                    }
                    if let Some(p) = found.iter().find(|p| matches(p, eyes, d, 0.5, 1.5)) {
                        t.loose += 1;
                        t.log_size.push((p.eye_distance / d).ln());
                        if strict.is_none() {
                            t.off_eyes += usize::from(p.eyes_midpoint.distance(eyes) >= 0.25 * d);
                            t.off_size +=
                                usize::from((p.eye_distance / d).ln().abs() >= 1.2f64.ln());
                        }
                    }
                }
            }
        }
    }
    println!(
        "{} photos with faces whose eyes are >= {MEASURED_EYE_DISTANCE} px apart",
        photos.len()
    );
    for (si, k) in SHEARS.iter().enumerate() {
        for (ni, (name, _, params)) in nets.iter().enumerate() {
            let t = &mut tallies[si][ni];
            let share = |n: usize| 100.0 * n as f64 / t.faces.max(1) as f64;
            println!(
                "k {k:+.1} {name} (step {:.3}, logit >= {}): {} faces, strict (0.25 ED, 20%) \
                 {:.1}%, loose (0.5 ED, 1.5x) {:.1}%; {:.2} proposals/photo, {:.2} matching no \
                 face; median |k error| {:.3}, |roll error| {:.1} deg; {:.0} ms/photo; of the \
                 faces found loosely only, {} with eyes 0.25 ED off, {} with size 20% off; \
                 log size error of the faces found loosely: median {:+.3}, 10%-90% {:+.3} to {:+.3}",
                params.scale_step,
                params.min_logit,
                t.faces,
                share(t.strict),
                share(t.loose),
                t.proposals as f64 / photos.len() as f64,
                t.unmatched as f64 / photos.len() as f64,
                median(&mut t.k_errors),
                median(&mut t.roll_errors),
                1000.0 * t.seconds / photos.len() as f64,
                t.off_eyes,
                t.off_size,
                median(&mut t.log_size),
                t.log_size.get(t.log_size.len() / 10).copied().unwrap_or(f64::NAN),
                t.log_size.get(t.log_size.len() * 9 / 10).copied().unwrap_or(f64::NAN),
            );
        }
    }
    Ok(())
}

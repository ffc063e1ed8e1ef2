//! Measures the scene ruler (the shear the scene's verticals give) against the faces on the
//! Caltech development photos the accuracy tables measure (at least one face with eyes 40 px
//! or more apart): each whole photo sheared by each `k` about its middle row and cropped to
//! the pixels that stay inside (`Canvas::Crop`, so no wedge edge shows `k`), then the scene
//! read, and, where it gives a shear, the faces too (the default corrector with `--ruler
//! faces`). Prints the share of photos the scene answers, its time per photo, and on the
//! answered photos the share within 0.05 of the applied `k` for the scene alone, the faces
//! alone and the two combined as `--ruler combine` combines them.
//!
//! ```sh
//! cargo run --release --example scene_ruler -- ../shared/data/caltech-webfaces [LIMIT] [--small-faces] [--verbose]
//! ```
//!
//! The truth is the applied `k`: a photo's own shear (from the camera's roll, a real rolling
//! shutter or a leaning scene) counts as error, for both rulers alike.

use std::path::PathBuf;
use std::time::Instant;

use unshear::dev::dataset::{by_image, AnnotatedFace, CaltechWebFaces, FaceDataset};
use unshear::internals::{fuse, scene_shear};
use unshear::warp::{try_apply_shear, Canvas, Interpolation};
use unshear::{Config, Ruler, Shear, ShearSource, Unshear};

const MEASURED_EYE_DISTANCE: f64 = 40.0;
const SHEARS: [f64; 5] = [0.0, 0.2, -0.2, 0.4, -0.4];
const WITHIN: f64 = 0.05;

#[derive(Default)]
struct Tally {
    runs: usize,
    answered: usize,
    scene_ok: usize,
    faces_given: usize,
    faces_ok: usize,
    fused_ok: usize,
    combined: usize,
    disagree: usize,
    covered: usize,
    scene_ms: f64,
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let data = PathBuf::from(
        args.first()
            .cloned()
            .unwrap_or_else(|| "../shared/data/caltech-webfaces".into()),
    );
    let limit: usize = args
        .get(1)
        .filter(|a| !a.starts_with("--"))
        .map_or(Ok(usize::MAX), |s| s.parse())?;
    // `--small-faces`: the other photos (every face's eyes under 40 px apart), the ones the
    // networks were trained on, to look at without touching the measured ones.
    let small = args.iter().any(|a| a == "--small-faces");
    if args.iter().any(|a| a == "--time") {
        return time_1080p(&photo_or_fixture(&data));
    }
    let verbose = args.iter().any(|a| a == "--verbose");
    let photos: Vec<(PathBuf, Vec<AnnotatedFace>)> = by_image(CaltechWebFaces::new(&data).faces()?)
        .into_iter()
        .filter(|(_, faces)| {
            small
                != faces
                    .iter()
                    .any(|f| f.eye_distance() >= MEASURED_EYE_DISTANCE)
        })
        .take(limit)
        .collect();
    let faces = Unshear::new(Config {
        ruler: Ruler::Faces,
        ..Config::default()
    })?;
    let mut tallies: Vec<Tally> = SHEARS.iter().map(|_| Tally::default()).collect();
    for (path, _) in &photos {
        let img = unshear::imageio::read_image(path, unshear::imageio::DEFAULT_MAX_PIXELS)?;
        for (t, &k) in tallies.iter_mut().zip(&SHEARS) {
            let shear = Shear::about_middle(k, img.height());
            let (sheared, _) = try_apply_shear(&img, shear, Interpolation::Linear, Canvas::Crop)?;
            let gray = Unshear::gray(&sheared);
            t.runs += 1;
            let start = Instant::now();
            let scene = scene_shear(&gray);
            t.scene_ms += start.elapsed().as_secs_f64() * 1e3;
            let Some(scene) = scene else {
                continue;
            };
            t.answered += 1;
            if verbose {
                println!(
                    "{} k {k:+.2} scene {:+.3} sd {:.3} lines {} segs {} roll {:?} conv {:+.3}",
                    path.display(),
                    scene.k,
                    scene.uncertainty,
                    scene.lines,
                    scene.segments,
                    scene.roll_degrees,
                    scene.convergence
                );
            }
            t.scene_ok += usize::from((scene.k - k).abs() <= WITHIN);
            t.covered += usize::from((scene.k - k).abs() <= 2.0 * scene.uncertainty);
            let report = faces.estimate_gray(&gray);
            let agreeing = report
                .faces
                .iter()
                .filter(|f| f.k.is_some() && !f.outvoted)
                .count();
            let (fused, source, disagree) = fuse(report.k, agreeing, Some(&scene), Ruler::Combine);
            if let Some(kf) = report.k {
                t.faces_given += 1;
                t.faces_ok += usize::from((kf - k).abs() <= WITHIN);
            }
            t.fused_ok += usize::from(fused.is_some_and(|f| (f - k).abs() <= WITHIN));
            t.combined += usize::from(source == Some(ShearSource::FacesAndScene));
            t.disagree += usize::from(disagree);
        }
    }
    println!(
        "{} photos {} {MEASURED_EYE_DISTANCE} px apart; within {WITHIN} on the photos the scene answers",
        photos.len(),
        if small { "whose faces' eyes are all under" } else { "with a face whose eyes are at least" }
    );
    println!("| k | scene answers | scene within | 2 sd cover | faces give k | faces within | combined within | combined | disagree | scene ms/photo |");
    println!("|---|---|---|---|---|---|---|---|---|---|");
    let pct = |a: usize, b: usize| 100.0 * a as f64 / b.max(1) as f64;
    let mut all = Tally::default();
    for (t, k) in tallies.iter().zip(SHEARS) {
        row(&format!("{k:+.1}"), t, &pct);
        all.runs += t.runs;
        all.answered += t.answered;
        all.scene_ok += t.scene_ok;
        all.covered += t.covered;
        all.faces_given += t.faces_given;
        all.faces_ok += t.faces_ok;
        all.fused_ok += t.fused_ok;
        all.combined += t.combined;
        all.disagree += t.disagree;
        all.scene_ms += t.scene_ms;
    }
    row("all", &all, &pct);
    Ok(())
}

/// The first development photo, else the bundled example face.
fn photo_or_fixture(data: &std::path::Path) -> PathBuf {
    let first = data.join("images/pic00001.jpg");
    if first.exists() {
        first
    } else {
        PathBuf::from(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/assets/example/face-k0.30.png"
        ))
    }
}

/// The scene ruler's time on `path` stretched to a 1920x1080 frame (median of 21 runs, after
/// one to warm up).
fn time_1080p(path: &std::path::Path) -> anyhow::Result<()> {
    let img = image::open(path)?.into_luma8();
    let frame = image::imageops::resize(&img, 1920, 1080, image::imageops::FilterType::Triangle);
    scene_shear(&frame);
    let mut times: Vec<f64> = (0..21)
        .map(|_| {
            let start = Instant::now();
            std::hint::black_box(scene_shear(&frame));
            start.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    times.sort_by(f64::total_cmp);
    println!(
        "{}: 1920x1080, scene ruler {:.1} ms (median of 21; {} threads)",
        path.display(),
        times[10],
        rayon::current_num_threads()
    );
    Ok(())
}

fn row(label: &str, t: &Tally, pct: &dyn Fn(usize, usize) -> f64) {
    println!(
        "| {label} | {}/{} ({:.1}%) | {:.1}% | {:.1}% | {} | {:.1}% | {:.1}% | {} | {} | {:.1} |",
        t.answered,
        t.runs,
        pct(t.answered, t.runs),
        pct(t.scene_ok, t.answered),
        pct(t.covered, t.answered),
        t.faces_given,
        pct(t.faces_ok, t.answered),
        pct(t.fused_ok, t.answered),
        t.combined,
        t.disagree,
        t.scene_ms / t.runs.max(1) as f64,
    );
}

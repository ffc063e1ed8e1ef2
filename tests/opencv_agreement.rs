//! Agreement with OpenCV 4's `CascadeClassifier::detectMultiScale(gray, 1.1, 3)` on real photos,
//! and a timing of one 1920x1080 frame. Both are `#[ignore]`d: they need `../shared` (the data
//! sets) and a Python with OpenCV 4's `cv2`, and take a while. Run with
//!
//! ```text
//! cargo test --release --test opencv_agreement -- --ignored --nocapture
//! ```
//!
//! Environment: `UNSHEAR_PYTHON` (default `python3`), `UNSHEAR_CALTECH_LIMIT` (Caltech images to
//! use, default 300; 0 = all). Missing data, Python or cv2 make the tests print "skipped" and pass.
//!
//! Measures, over all OpenCV boxes: *matched* = share with an IoU ≥ 0.5 partner among ours
//! (one-to-one, greedy by IoU), *extra* = our unmatched boxes / OpenCV boxes, and *identical* =
//! share of OpenCV boxes we reproduce to the pixel. It does so twice: on the grey images OpenCV
//! itself used (written as PNG by the script, so the input is byte-identical) and end to end
//! (our JPEG decoder + `to_gray_opencv`).

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use unshear::detect::{to_gray_opencv, FaceDetector};
use unshear::Rect;

fn shared() -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data");
    if p.is_dir() {
        Some(p)
    } else {
        eprintln!("skipped: ../shared not found");
        None
    }
}

#[derive(Default, Debug)]
struct Tally {
    images: usize,
    cv_boxes: usize,
    ours: usize,
    matched: usize,
    identical: usize,
    differing_images: usize,
}

impl Tally {
    fn add(&mut self, cv: &[Rect], ours: &[Rect]) {
        self.images += 1;
        self.cv_boxes += cv.len();
        self.ours += ours.len();
        let mut pairs = Vec::new();
        for (i, a) in cv.iter().enumerate() {
            for (j, b) in ours.iter().enumerate() {
                let iou = a.iou(b);
                if iou >= 0.5 {
                    pairs.push((iou, i, j));
                }
            }
        }
        pairs.sort_by(|a, b| b.0.total_cmp(&a.0));
        let (mut used_a, mut used_b) = (vec![false; cv.len()], vec![false; ours.len()]);
        for (_, i, j) in pairs {
            if !used_a[i] && !used_b[j] {
                used_a[i] = true;
                used_b[j] = true;
                self.matched += 1;
            }
        }
        self.identical += cv.iter().filter(|a| ours.contains(a)).count();
        let mut s1: Vec<_> = cv.iter().map(|r| format!("{r:?}")).collect();
        let mut s2: Vec<_> = ours.iter().map(|r| format!("{r:?}")).collect();
        s1.sort();
        s2.sort();
        if s1 != s2 {
            self.differing_images += 1;
        }
    }

    fn matched_pct(&self) -> f64 {
        100.0 * self.matched as f64 / self.cv_boxes.max(1) as f64
    }

    fn extra_pct(&self) -> f64 {
        100.0 * (self.ours - self.matched) as f64 / self.cv_boxes.max(1) as f64
    }

    fn report(&self, what: &str) {
        eprintln!(
            "{what}: {} images, {} OpenCV boxes, {} ours: matched {:.2}%, extra {:.2}%, \
             identical {:.2}%, images with any difference {}",
            self.images,
            self.cv_boxes,
            self.ours,
            self.matched_pct(),
            self.extra_pct(),
            100.0 * self.identical as f64 / self.cv_boxes.max(1) as f64,
            self.differing_images
        );
    }
}

/// Run the Python reference; `None` (after printing why) when it cannot run here.
fn opencv_reference(
    cascade: &Path,
    inputs: &[PathBuf],
    limit: usize,
    work: &Path,
) -> Option<serde_json::Value> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let python = std::env::var("UNSHEAR_PYTHON").unwrap_or_else(|_| "python3".into());
    let out = work.join("opencv.json");
    let status = Command::new(&python)
        .arg(root.join("scripts/compare_opencv.py"))
        .arg("--cascade")
        .arg(cascade)
        .arg("--out")
        .arg(&out)
        .arg("--gray-dir")
        .arg(work.join("gray"))
        .arg("--limit")
        .arg(limit.to_string())
        .args(inputs)
        .status();
    match status {
        Ok(s) if s.success() => {}
        Ok(s) => {
            eprintln!("skipped: {python} scripts/compare_opencv.py exited with {s}");
            return None;
        }
        Err(e) => {
            eprintln!("skipped: cannot run {python}: {e}");
            return None;
        }
    }
    let text = std::fs::read_to_string(&out).ok()?;
    serde_json::from_str(&text).ok()
}

fn boxes(v: &serde_json::Value) -> Vec<Rect> {
    v.as_array()
        .into_iter()
        .flatten()
        .filter_map(|b| {
            let b: Vec<f64> = b.as_array()?.iter().filter_map(|x| x.as_f64()).collect();
            (b.len() == 4).then(|| Rect::new(b[0], b[1], b[2], b[3]))
        })
        .collect()
}

/// Compare on `sets` (name, folder, image limit); returns the same-input and end-to-end tallies.
fn compare(
    det: &FaceDetector,
    cascade: &Path,
    sets: &[(&str, PathBuf, usize)],
) -> Option<(Tally, Tally)> {
    let work = tempfile::tempdir().expect("temp dir");
    let mut same_input = Tally::default();
    let mut end_to_end = Tally::default();
    for (name, dir, lim) in sets {
        let sub = work.path().join(name);
        std::fs::create_dir_all(&sub).expect("work dir");
        let reference = opencv_reference(cascade, std::slice::from_ref(dir), *lim, &sub)?;
        let mut t_same = Tally::default();
        let mut t_e2e = Tally::default();
        let mut ms = 0.0;
        for im in reference["images"].as_array().into_iter().flatten() {
            let cv = boxes(&im["boxes"]);
            let path = im["path"].as_str().unwrap_or_default();
            let gray_png = im["gray"].as_str().unwrap_or_default();
            let gray = image::open(gray_png).expect("grey png").to_luma8();
            let t0 = Instant::now();
            let ours = det.detect(&gray);
            ms += t0.elapsed().as_secs_f64() * 1e3;
            t_same.add(&cv, &ours);
            same_input.add(&cv, &ours);
            if t_same.differing_images > 0 && t_same.differing_images <= 3 && ours != cv {
                eprintln!("  differs: {path}\n    opencv {cv:?}\n    ours   {ours:?}");
            }
            let decoded = image::open(path).expect("decode");
            let ours2 = det.detect(&to_gray_opencv(&decoded));
            t_e2e.add(&cv, &ours2);
            end_to_end.add(&cv, &ours2);
        }
        t_same.report(&format!("{name}, same grey input"));
        t_e2e.report(&format!("{name}, end to end (image crate decode)"));
        eprintln!("{name}: our detection time {ms:.0} ms total");
    }
    Some((same_input, end_to_end))
}

#[test]
#[ignore = "needs ../shared and Python with OpenCV 4; slow"]
fn agrees_with_opencv_detect_multiscale() {
    let Some(data) = shared() else { return };
    let limit: usize = std::env::var("UNSHEAR_CALTECH_LIMIT")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(300);
    let cascade =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("models/haarcascade_frontalface_alt2.xml");
    let sets = [
        ("yale", data.join("yale-faces/images"), 0),
        ("caltech", data.join("caltech-webfaces/images"), limit),
    ];
    let Some((same_input, end_to_end)) = compare(&FaceDetector::frontal_face(), &cascade, &sets)
    else {
        return;
    };
    same_input.report("ALL, same grey input");
    end_to_end.report("ALL, end to end");
    assert!(same_input.matched_pct() >= 95.0, "{same_input:?}");
    assert!(same_input.extra_pct() <= 5.0, "{same_input:?}");
}

/// Other cascades exercise the other code paths: stumps (frontalface_default), 45° features and
/// deeper trees (eye_tree_eyeglasses, frontalcatface_extended) and the old XML layout
/// (licence_plate_rus_16stages). Uses Debian's opencv-data copies when installed.
#[test]
#[ignore = "needs ../shared, /usr/share/opencv4 and Python with OpenCV 4; slow"]
fn agrees_with_opencv_on_other_cascades() {
    let Some(data) = shared() else { return };
    let dir = Path::new("/usr/share/opencv4/haarcascades");
    for name in [
        "haarcascade_frontalface_default.xml",
        "haarcascade_eye_tree_eyeglasses.xml",
        "haarcascade_frontalcatface_extended.xml",
        "haarcascade_licence_plate_rus_16stages.xml",
    ] {
        let path = dir.join(name);
        let Ok(cascade) = unshear::detect::Cascade::from_file(&path) else {
            eprintln!("skipped: {} not found", path.display());
            continue;
        };
        let det = FaceDetector::new(cascade, Default::default());
        let sets = [(name, data.join("caltech-webfaces/images"), 60)];
        let Some((same_input, _)) = compare(&det, &path, &sets) else {
            return;
        };
        assert!(same_input.matched_pct() >= 95.0, "{name}: {same_input:?}");
        assert!(same_input.extra_pct() <= 5.0, "{name}: {same_input:?}");
    }
}

#[test]
#[ignore = "timing; run in release mode"]
fn time_1920x1080_single_core() {
    // A real face photo scaled up to full HD when ../shared is there, otherwise a synthetic
    // textured frame (fewer windows survive the first stages, so it is faster).
    let frame = shared()
        .and_then(|d| image::open(d.join("yale-faces/images/subject01.normal.jpeg")).ok())
        .map(|im| {
            to_gray_opencv(&im.resize_exact(1920, 1080, image::imageops::FilterType::Triangle))
        })
        .unwrap_or_else(|| {
            image::GrayImage::from_fn(1920, 1080, |x, y| {
                image::Luma([((x * 13 + y * 7 + (x * y) % 97) % 256) as u8])
            })
        });
    let det = FaceDetector::frontal_face();
    for threads in [1, 2] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("pool");
        let mut best = f64::INFINITY;
        let mut n = 0;
        for _ in 0..3 {
            let t0 = Instant::now();
            n = pool.install(|| det.detect(&frame)).len();
            best = best.min(t0.elapsed().as_secs_f64() * 1e3);
        }
        eprintln!("1920x1080, {threads} thread(s): {best:.0} ms (best of 3), {n} faces");
    }
}

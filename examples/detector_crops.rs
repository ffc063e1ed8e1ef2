//! Cuts the single-pass face detector's training windows from the Caltech development faces, for
//! `scripts/train_detector.py` (see `unshear::detect::ProposalNet::embedded_detector`).
//!
//! ```sh
//! cargo run --release --example detector_crops -- --repeat 4 ../shared/data/caltech-webfaces target/detector-crops
//! ```
//!
//! Writes `crops.u8` (32x32 bytes per window), `labels.u8` (1: face, 0: not), `targets.f32`
//! (five little-endian `f32` per window: the eyes' midpoint's offset from the window's
//! expected one, `dx` and `dy` in window eye distances; `log_scale`, the log of the face's eye
//! distance over the window's; the face's shear `k` and roll, radians; zeros for the others),
//! `photos.u32` (the photo each window comes from, for a held-out split by photo) and
//! `meta.json`. Like the landmark network's and the proposal classifier's crops, only photos
//! whose faces all have eyes under 40 px apart are used, so no photo the accuracy tables
//! measure (eyes at least 40 px apart) is trained on.
//!
//! A window is what the detector sees at run time: an axis-aligned 32x32 square of a pyramid
//! level, spanning 3.3 of its expected eye distances, the expected eyes' midpoint 0.35 of them
//! above its centre. It is rendered from the photo as if the photo had been turned by a roll
//! and then sheared (`x' = x + k y`), so the face in it is `S(k) R(roll)` of the upright face,
//! the frame `unshear::locate::network::frame_around_eyes` removes with the same `k` and `roll`
//! (the roll recorded is the total: the annotated eyes' own slant plus the turn). Each window
//! pixel averages up to 4x4 bilinear reads (the pyramid's reduction), and reads past the
//! photo's edge repeat its edge pixels (as the detector pads its levels).
//!
//! * **faces** (eyes 12-40 px apart), 32 windows each: shear uniform in +-0.55, roll uniform in
//!   +-50 degrees for half of them and +-15 for the others, the eyes' midpoint anywhere in the
//!   window's grid cell (uniform in +-0.45 eye distances each way, the cell being 0.41 each
//!   way at output stride 8) and the size anywhere in the pyramid's step (log-uniform in
//!   +-0.55 ln 1.414);
//! * **near misses** of each face (12 per face, same shear and roll): the window 1.2-2.5 eye
//!   distances away, or 2-3.5 times too large or too small;
//! * **background**: 40 windows per photo at random places and sizes (eye distances of 6 px
//!   up to a third of the photo's shorter side), shear and roll drawn as for faces, none
//!   within 0.8 eye distances of a face of half to twice its size;
//! * **noise**: 8 windows per photo of uniform pixel noise, each pixel the average of 1x1 to
//!   8x8 noise pixels (see `noise_window`).
//!
//! `--repeat R` cuts R times as many windows of every kind, each drawn afresh (the committed
//! detector was trained on `--repeat 4`).

use std::io::Write;
use std::path::{Path, PathBuf};

use image::GrayImage;
use rayon::prelude::*;
use unshear::detect::boxes::{CROP_EYE_DISTANCES, EYES_ABOVE_CENTRE};
use unshear::dev::dataset::{photos_with_small_faces, AnnotatedFace, CaltechWebFaces, FaceDataset};
use unshear::dev::SplitMix64;
use unshear::Point;

/// Side of the windows, pixels.
const SIZE: usize = 32;
/// Face windows per face.
const PER_FACE: usize = 32;
/// Near-miss windows per face.
const NEAR_MISSES: usize = 12;
/// Background windows per photo.
const BACKGROUND: usize = 40;
/// Faces with eyes closer than this are not used as faces (they are still avoided by the
/// background windows).
const MIN_EYE_DISTANCE: f64 = 12.0;
/// Photos with a face whose eyes are this far apart or more are not used.
const MAX_EYE_DISTANCE: f64 = 40.0;
/// The largest shear drawn.
const MAX_SHEAR: f64 = 0.55;
/// The largest roll drawn, radians (50 degrees).
const MAX_ROLL: f64 = 50.0 * std::f64::consts::PI / 180.0;
/// The smaller roll range drawn for half of the faces (15 degrees).
const SMALL_ROLL: f64 = 15.0 * std::f64::consts::PI / 180.0;
/// The detector's output stride, window pixels.
const STRIDE: f64 = 8.0;
/// The pyramid step the detector is run with (or less).
const SCALE_STEP: f64 = std::f64::consts::SQRT_2;
/// How much beyond its grid cell and scale step a face window is jittered (1.1: 10% more).
const JITTER_MARGIN: f64 = 1.1;
/// Most bilinear reads per window pixel and axis.
const MAX_SUPERSAMPLING: usize = 4;
/// Windows of pixel noise per photo.
const NOISE: usize = 8;
/// The largest shrinking of the noise a noise window shows.
const MAX_NOISE_SHRINK: usize = 8;

/// A roll: uniform in +-50 degrees or (half the time) +-15.
fn roll(rng: &mut SplitMix64) -> f64 {
    if rng.next_f64() < 0.5 {
        rng.symmetric(MAX_ROLL)
    } else {
        rng.symmetric(SMALL_ROLL)
    }
}

/// Window pixels per eye distance.
fn per_eye_distance() -> f64 {
    SIZE as f64 / CROP_EYE_DISTANCES
}

/// The window point where the detector expects the eyes' midpoint.
fn expected_eyes() -> Point {
    let o = (SIZE as f64 - 1.0) / 2.0;
    Point::new(o, o - EYES_ABOVE_CENTRE * per_eye_distance())
}

/// Bilinear read of `gray` at `(x, y)` (pixel centres at integers), edge pixels repeated.
fn bilinear(gray: &GrayImage, x: f64, y: f64) -> f64 {
    let (w, h) = (gray.width() as i64, gray.height() as i64);
    let (fx, fy) = (x.floor(), y.floor());
    let (ax, ay) = (x - fx, y - fy);
    let at = |xi: i64, yi: i64| -> f64 {
        let xi = xi.clamp(0, w - 1) as u32;
        let yi = yi.clamp(0, h - 1) as u32;
        f64::from(gray.get_pixel(xi, yi)[0])
    };
    let (x0, y0) = (fx as i64, fy as i64);
    let top = at(x0, y0) * (1.0 - ax) + at(x0 + 1, y0) * ax;
    let bottom = at(x0, y0 + 1) * (1.0 - ax) + at(x0 + 1, y0 + 1) * ax;
    top * (1.0 - ay) + bottom * ay
}

/// A window of the photo turned by `turn` and then sheared by `k` about `anchor` (a point of the
/// photo), showing `anchor` at the window point `offset` window eye distances from the
/// expected eyes' midpoint, at `window_eye_distance` photo pixels per window eye distance.
fn render(
    gray: &GrayImage,
    anchor: Point,
    offset: (f64, f64),
    window_eye_distance: f64,
    k: f64,
    turn: f64,
) -> Vec<u8> {
    let m = window_eye_distance / per_eye_distance();
    let e = expected_eyes();
    let (ox, oy) = (
        e.x + offset.0 * per_eye_distance(),
        e.y + offset.1 * per_eye_distance(),
    );
    // Photo = anchor + R(-turn) S(-k) (window - o) m.
    let (s, c) = turn.sin_cos();
    let map = |u: f64, v: f64| -> (f64, f64) {
        let (a, b) = ((u - ox) * m, (v - oy) * m);
        let (a, b) = (a - k * b, b);
        (anchor.x + c * a + s * b, anchor.y - s * a + c * b)
    };
    let reads = (m.ceil() as usize).clamp(1, MAX_SUPERSAMPLING);
    let mut out = Vec::with_capacity(SIZE * SIZE);
    for v in 0..SIZE {
        for u in 0..SIZE {
            let mut sum = 0.0;
            for j in 0..reads {
                for i in 0..reads {
                    let du = (i as f64 + 0.5) / reads as f64 - 0.5;
                    let dv = (j as f64 + 0.5) / reads as f64 - 0.5;
                    let (x, y) = map(u as f64 + du, v as f64 + dv);
                    sum += bilinear(gray, x, y);
                }
            }
            out.push((sum / (reads * reads) as f64).round().clamp(0.0, 255.0) as u8);
        }
    }
    out
}

/// A window: pixels, label, targets (dx, dy, log_scale, k, roll).
type Window = (Vec<u8>, u8, [f32; 5]);

/// The annotated eyes' slant: the roll of the face in the photo, radians (positive: clockwise
/// on screen, the subject's left eye lower).
fn slant(face: &AnnotatedFace) -> f64 {
    let (dx, dy) = (
        face.left_eye.x - face.right_eye.x,
        face.left_eye.y - face.right_eye.y,
    );
    dy.atan2(dx)
}

fn photo_windows(path: &Path, faces: &[AnnotatedFace], seed: u64, repeat: usize) -> Vec<Window> {
    let Ok(img) = unshear::imageio::read_image(path, unshear::imageio::DEFAULT_MAX_PIXELS) else {
        return Vec::new();
    };
    let gray = unshear::detect::to_gray_opencv(&img);
    // SplitMix64, as the library's trainers use (seeded per photo, so the windows do not
    // depend on the order the threads finish in).
    let mut rng = SplitMix64::new(seed);
    let mut out = Vec::new();
    let cell = JITTER_MARGIN * STRIDE / 2.0 / per_eye_distance();
    let step = JITTER_MARGIN * SCALE_STEP.ln() / 2.0;
    for face in faces
        .iter()
        .filter(|f| f.eye_distance() >= MIN_EYE_DISTANCE)
    {
        let mid = face.right_eye.midpoint(face.left_eye);
        let d = face.eye_distance();
        let natural = slant(face);
        for i in 0..(PER_FACE + NEAR_MISSES) * repeat {
            let k = rng.symmetric(MAX_SHEAR);
            let roll = roll(&mut rng);
            // The photo is turned by what the face's own slant leaves of the roll drawn.
            let turn = roll - natural;
            if i % (PER_FACE + NEAR_MISSES) < PER_FACE {
                let offset = (rng.symmetric(cell), rng.symmetric(cell));
                let log_scale = rng.symmetric(step);
                let pixels = render(&gray, mid, offset, d / log_scale.exp(), k, turn);
                let targets = [offset.0, offset.1, log_scale, k, roll].map(|v| v as f32);
                out.push((pixels, 1, targets));
            } else {
                let (offset, log_scale) = if rng.next_f64() < 0.6 {
                    let far = 1.2 + 1.3 * rng.next_f64();
                    let across = rng.symmetric(far);
                    let far = if rng.next_f64() < 0.5 { far } else { -far };
                    let offset = if rng.next_f64() < 0.5 {
                        (far, across)
                    } else {
                        (across, far)
                    };
                    (offset, rng.symmetric(step))
                } else {
                    let off = (2f64.ln() + rng.next_f64() * (3.5f64 / 2.0).ln()) * {
                        if rng.next_f64() < 0.5 {
                            1.0
                        } else {
                            -1.0
                        }
                    };
                    ((rng.symmetric(0.5), rng.symmetric(0.5)), off)
                };
                let pixels = render(&gray, mid, offset, d / log_scale.exp(), k, turn);
                out.push((pixels, 0, [0.0; 5]));
            }
        }
    }
    let eyes: Vec<(Point, f64)> = faces
        .iter()
        .map(|f| (f.right_eye.midpoint(f.left_eye), f.eye_distance()))
        .collect();
    let (w, h) = (f64::from(gray.width()), f64::from(gray.height()));
    let largest = (w.min(h) / 3.3).max(7.0);
    let mut made = 0;
    for _ in 0..4 * BACKGROUND * repeat {
        if made >= BACKGROUND * repeat {
            break;
        }
        let d = (6f64.ln() + rng.next_f64() * (largest / 6.0).ln()).exp();
        let centre = Point::new(rng.next_f64() * w, rng.next_f64() * h);
        let near_a_face = eyes.iter().any(|&(m, fd)| {
            let ratio = d / fd;
            m.distance(centre) < 0.8 * fd.max(d) && ratio > 0.5 && ratio < 2.0
        });
        if near_a_face {
            continue;
        }
        let (k, turn) = (rng.symmetric(MAX_SHEAR), roll(&mut rng));
        let pixels = render(&gray, centre, (0.0, 0.0), d, k, turn);
        out.push((pixels, 0, [0.0; 5]));
        made += 1;
    }
    for _ in 0..NOISE * repeat {
        out.push((noise_window(&mut rng), 0, [0.0; 5]));
    }
    out
}

/// A window of uniform pixel noise (a random mean and spread) as a pyramid level shows it:
/// each window pixel the average of `f x f` noise pixels, `f` from 1 to [`MAX_NOISE_SHRINK`].
/// The photos hold little of it, and without such windows the detector took a frame of
/// noise (a dark, grainy surveillance frame at its extreme) for twice as many weak faces.
fn noise_window(rng: &mut SplitMix64) -> Vec<u8> {
    let f = 1 + (rng.next_f64() * MAX_NOISE_SHRINK as f64) as usize;
    let f = f.min(MAX_NOISE_SHRINK);
    let mean = 40.0 + 175.0 * rng.next_f64();
    let spread = 10.0 + 118.0 * rng.next_f64();
    (0..SIZE * SIZE)
        .map(|_| {
            let sum: f64 = (0..f * f)
                .map(|_| (mean + rng.symmetric(spread)).clamp(0.0, 255.0).round())
                .sum();
            (sum / (f * f) as f64).round() as u8
        })
        .collect()
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    // `--repeat R`: R times as many windows of every kind.
    let repeat = match args.iter().position(|a| a == "--repeat") {
        Some(i) if i + 1 < args.len() => {
            let r: usize = args[i + 1].parse()?;
            args.drain(i..i + 2);
            r.max(1)
        }
        _ => 1,
    };
    let [data, out] = args.as_slice() else {
        return Err("usage: detector_crops [--repeat R] CALTECH_DIR OUT_DIR".into());
    };
    let out = PathBuf::from(out);
    let photos = photos_with_small_faces(CaltechWebFaces::new(data).faces()?, MAX_EYE_DISTANCE);
    std::fs::create_dir_all(&out)?;
    let create = |name: &str| -> std::io::Result<std::io::BufWriter<std::fs::File>> {
        Ok(std::io::BufWriter::new(std::fs::File::create(
            out.join(name),
        )?))
    };
    let mut crops = create("crops.u8")?;
    let mut labels = create("labels.u8")?;
    let mut targets = create("targets.f32")?;
    let mut photo_ids = create("photos.u32")?;
    let (mut faces, mut others, mut face_count) = (0usize, 0usize, 0usize);
    for (chunk_index, chunk) in photos.chunks(128).enumerate() {
        let windows: Vec<Vec<Window>> = chunk
            .par_iter()
            .enumerate()
            .map(|(i, (path, faces))| {
                let seed = 0x6465_7465_6374_6f72_u64 ^ (chunk_index * 128 + i) as u64;
                photo_windows(path, faces, seed, repeat)
            })
            .collect();
        for (i, photo) in windows.into_iter().enumerate() {
            let id = (chunk_index * 128 + i) as u32;
            for (pixels, label, target) in photo {
                crops.write_all(&pixels)?;
                labels.write_all(&[label])?;
                for v in target {
                    targets.write_all(&v.to_le_bytes())?;
                }
                photo_ids.write_all(&id.to_le_bytes())?;
                if label == 1 {
                    faces += 1;
                } else {
                    others += 1;
                }
            }
        }
        face_count += chunk
            .iter()
            .flat_map(|(_, f)| f)
            .filter(|f| f.eye_distance() >= MIN_EYE_DISTANCE)
            .count();
    }
    for w in [&mut crops, &mut labels, &mut targets, &mut photo_ids] {
        w.flush()?;
    }
    let meta = serde_json::json!({
        "size": SIZE,
        "faces": faces,
        "others": others,
        "annotated_faces": face_count,
        "photos": photos.len(),
        "stride": STRIDE,
        "scale_step": SCALE_STEP,
        "repeat": repeat,
        "targets": ["dx", "dy", "log_scale", "k", "roll"],
    });
    std::fs::write(out.join("meta.json"), meta.to_string())?;
    println!(
        "{faces} face windows ({face_count} faces) and {others} others from {} photos written to {}",
        photos.len(),
        out.display()
    );
    Ok(())
}

//! Cuts the face proposal classifier's training windows from the Caltech development faces, for
//! `scripts/train_proposals.py` (see `unshear::detect::ProposalNet`).
//!
//! ```sh
//! cargo run --release --example proposal_crops -- ../shared/data/caltech-webfaces target/proposal-crops
//! ```
//!
//! Writes `crops.u8` (32x32 bytes per window), `labels.u8` (1: face, 0: not) and `meta.json`.
//! Like the landmark network's crops, only photos whose faces all have eyes under 40 px apart
//! are used, so no photo the accuracy tables measure (eyes at least 40 px apart) is trained on.
//!
//! Each window has the landmark crop's geometry (3.3 eye distances across, the eyes' midpoint
//! 0.35 eye distances above the centre) and is cut with the run-time renderer:
//! * **faces** (eyes 12-40 px apart), 24 windows each, from the photo as it is or sheared by a
//!   shear drawn per photo from +-0.55, cut with a further shear of up to +-0.55 (the photo as it
//!   is) or +-0.1 (the sheared copy), turned by up to +-20 degrees in half of them, the eyes moved
//!   by up to a quarter of an eye distance each way and the size by up to 15%: what the classifier
//!   must accept, run over a pyramid of 1.25 steps with a 4 px stride on any shear;
//! * **near misses** of each face (half as many): the window a whole eye distance or more
//!   away, or 1.7-3.2 times too large or too small;
//! * **background**: 24 windows per photo version at random places and sizes, none within
//!   0.7 eye distances of a face of about its size.

use std::io::Write;
use std::path::{Path, PathBuf};

use rayon::prelude::*;
use unshear::dev::dataset::{photos_with_small_faces, AnnotatedFace, CaltechWebFaces, FaceDataset};
use unshear::dev::SplitMix64;
use unshear::locate::network::{frame_around_eyes, CropFrame};
use unshear::warp::{try_apply_shear, Canvas, Interpolation, Placement};
use unshear::{Point, Shear};

/// Side of the windows, pixels.
const SIZE: usize = 32;
/// Face windows per face.
const PER_FACE: usize = 24;
/// Background windows per photo version.
const BACKGROUND: usize = 24;
/// Faces with eyes closer than this are not used.
const MIN_EYE_DISTANCE: f64 = 12.0;
/// Photos with a face whose eyes are this far apart or more are not used.
const MAX_EYE_DISTANCE: f64 = 40.0;

/// A photo as the windows are cut from it, and where its unsheared points lie in it.
struct Version {
    gray: image::GrayImage,
    shear: Shear,
    placement: Placement,
    sheared: bool,
}

impl Version {
    fn point(&self, p: Point) -> Point {
        self.placement.from_frame(self.shear.apply(p))
    }
}

type Window = (Vec<u8>, u8);

fn cut(frame: CropFrame, gray: &image::GrayImage, label: u8, out: &mut Vec<Window>) {
    if let Some(pixels) = frame.render(gray) {
        let bytes = pixels
            .iter()
            .map(|v| v.round().clamp(0.0, 255.0) as u8)
            .collect();
        out.push((bytes, label));
    }
}

fn photo_windows(path: &Path, faces: &[AnnotatedFace], seed: u64) -> Vec<Window> {
    let Ok(img) = unshear::imageio::read_image(path, unshear::imageio::DEFAULT_MAX_PIXELS) else {
        return Vec::new();
    };
    let gray = unshear::detect::to_gray_opencv(&img);
    // SplitMix64, as the library's trainers use (seeded per photo, so the windows do not
    // depend on the order the threads finish in).
    let mut rng = SplitMix64::new(seed);
    let shear = Shear::about_middle(rng.symmetric(0.55), gray.height());
    let mut versions = vec![Version {
        gray: gray.clone(),
        shear: Shear::new(0.0, 0.0),
        placement: Placement::default(),
        sheared: false,
    }];
    let luma = image::DynamicImage::ImageLuma8(gray);
    if let Ok((s, placement)) = try_apply_shear(&luma, shear, Interpolation::Linear, Canvas::Expand)
    {
        versions.push(Version {
            gray: s.into_luma8(),
            shear,
            placement,
            sheared: true,
        });
    }
    let mut out = Vec::new();
    for face in faces
        .iter()
        .filter(|f| f.eye_distance() >= MIN_EYE_DISTANCE)
    {
        for _ in 0..PER_FACE {
            let v = &versions[(rng.next_f64() * versions.len() as f64) as usize % versions.len()];
            let mid = v.point(face.right_eye).midpoint(v.point(face.left_eye));
            let d = face.eye_distance();
            let k = rng.symmetric(if v.sheared { 0.1 } else { 0.55 });
            let roll = if rng.next_f64() < 0.5 {
                0.0
            } else {
                rng.symmetric(0.35)
            };
            let size = d * rng.symmetric(0.15f64.ln_1p()).exp();
            let centre = Point::new(
                mid.x + rng.symmetric(0.25) * d,
                mid.y + rng.symmetric(0.25) * d,
            );
            cut(
                frame_around_eyes(centre, size, k, roll, SIZE),
                &v.gray,
                1,
                &mut out,
            );
            if rng.next_f64() < 0.5 {
                let side =
                    |rng: &mut SplitMix64| rng.symmetric(1.0).signum() * (0.8 + rng.next_f64());
                let (dx, dy, scale) = match (rng.next_f64() * 3.0) as usize {
                    0 => (side(&mut rng), rng.symmetric(1.5), 1.0),
                    1 => (rng.symmetric(1.5), side(&mut rng), 1.0),
                    _ => {
                        let s = 1.7 + 1.5 * rng.next_f64();
                        let s = if rng.next_f64() < 0.5 { s } else { 1.0 / s };
                        (rng.symmetric(0.3), rng.symmetric(0.3), s)
                    }
                };
                let centre = Point::new(mid.x + dx * d, mid.y + dy * d);
                cut(
                    frame_around_eyes(centre, d * scale, k, roll, SIZE),
                    &v.gray,
                    0,
                    &mut out,
                );
            }
        }
    }
    for v in &versions {
        let eyes: Vec<(Point, f64)> = faces
            .iter()
            .map(|f| {
                let mid = v.point(f.right_eye).midpoint(v.point(f.left_eye));
                (mid, f.eye_distance())
            })
            .collect();
        let (w, h) = (f64::from(v.gray.width()), f64::from(v.gray.height()));
        let largest = (w.min(h) / 3.3).max(9.0);
        let mut made = 0;
        for _ in 0..4 * BACKGROUND {
            if made >= BACKGROUND {
                break;
            }
            let d = (8f64.ln() + rng.next_f64() * (largest / 8.0).ln()).exp();
            let centre = Point::new(rng.next_f64() * w, rng.next_f64() * h);
            let near_a_face = eyes.iter().any(|&(m, fd)| {
                let ratio = d / fd;
                m.distance(centre) < 0.7 * fd.max(d) && ratio > 0.6 && ratio < 1.6
            });
            if near_a_face {
                continue;
            }
            let roll = if rng.next_f64() < 0.5 {
                0.0
            } else {
                rng.symmetric(0.35)
            };
            let frame = frame_around_eyes(centre, d, rng.symmetric(0.3), roll, SIZE);
            cut(frame, &v.gray, 0, &mut out);
            made += 1;
        }
    }
    out
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [data, out] = args.as_slice() else {
        return Err("usage: proposal_crops CALTECH_DIR OUT_DIR".into());
    };
    let out = PathBuf::from(out);
    let photos = photos_with_small_faces(CaltechWebFaces::new(data).faces()?, MAX_EYE_DISTANCE);
    std::fs::create_dir_all(&out)?;
    let mut crops = std::io::BufWriter::new(std::fs::File::create(out.join("crops.u8"))?);
    let mut labels = std::io::BufWriter::new(std::fs::File::create(out.join("labels.u8"))?);
    let (mut faces, mut others) = (0usize, 0usize);
    for (chunk_index, chunk) in photos.chunks(128).enumerate() {
        let windows: Vec<Vec<Window>> = chunk
            .par_iter()
            .enumerate()
            .map(|(i, (path, faces))| {
                let seed = 0x7072_6f70_6f73_616c_u64 ^ (chunk_index * 128 + i) as u64;
                photo_windows(path, faces, seed)
            })
            .collect();
        for (pixels, label) in windows.into_iter().flatten() {
            crops.write_all(&pixels)?;
            labels.write_all(&[label])?;
            if label == 1 {
                faces += 1;
            } else {
                others += 1;
            }
        }
    }
    crops.flush()?;
    labels.flush()?;
    let meta = serde_json::json!({
        "size": SIZE,
        "faces": faces,
        "others": others,
        "photos": photos.len(),
    });
    std::fs::write(out.join("meta.json"), meta.to_string())?;
    println!(
        "{faces} face windows and {others} others from {} photos written to {}",
        photos.len(),
        out.display()
    );
    Ok(())
}

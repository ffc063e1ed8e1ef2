//! Realistic frames for the benches, composed deterministically from the development web photos
//! (`../shared/data/caltech-webfaces`, the development half the project tunes on), so that speed
//! is measured on clutter, real faces and real textures rather than a face on a flat canvas.
//!
//! Every scene is 1920x1080 RGB except the photo, 4000x3000:
//!
//! * `face on clutter`: one photo with one face scaled to cover the frame, cropped about the face;
//! * `face on clutter, sheared 0.3`: the same scene sheared by 0.3 with the library's warp (made
//!   wider first and cropped after, so that no fill shows);
//! * `no face`: a 4x3 mosaic of the parts of photos away from their annotated faces;
//! * `eight faces`: a 4x2 mosaic of eight photos with one face each;
//! * `4000x3000 photo`: the largest development photo with one face, scaled to cover 4000x3000.
//!
//! Photos are taken in file-name order by fixed rules (one annotated face, the eyes 30-50 px
//! apart, at least 640x480), so every run and every machine builds the same frames.

#![allow(dead_code)] // Each bench uses its own part of this module.

use image::imageops::{self, FilterType};
use image::{DynamicImage, RgbImage};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The frame size of the 1920x1080 scenes.
pub const FRAME: (u32, u32) = (1920, 1080);
/// The size of the large photo.
pub const PHOTO: (u32, u32) = (4000, 3000);

/// One named scene.
pub struct Scene {
    /// What the frame is, as the bench rows and the docs name it.
    pub name: &'static str,
    /// The pixels.
    pub image: DynamicImage,
}

/// One development photo with exactly one annotated face.
struct Photo {
    path: PathBuf,
    /// The midpoint of the eyes, in the photo's pixels.
    eyes: (f64, f64),
    /// The distance between the eyes, in pixels.
    eye_distance: f64,
    size: (u32, u32),
}

/// Where the development photos are: `../shared/data/caltech-webfaces` next to the repository.
pub fn data_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/caltech-webfaces")
}

/// The realistic scenes, or why they cannot be built (the shared data is absent on a fresh
/// machine; the benches then run their synthetic frame alone).
pub fn realistic() -> Result<(Vec<Scene>, Scene), String> {
    let dir = data_dir();
    let truth = dir.join("ground_truth.txt");
    let text = std::fs::read_to_string(&truth).map_err(|e| {
        format!(
            "{}: {e} (the development photos are absent)",
            truth.display()
        )
    })?;
    let photos = one_face_photos(&text, &dir.join("images"));
    // Faces as a scene of their own shows them: eyes 30-50 px apart on a photo at least
    // 640x480, scaled by 1.7-3 to fill the frame.
    let framed: Vec<&Photo> = photos
        .iter()
        .filter(|p| (30.0..=50.0).contains(&p.eye_distance) && p.size.0 >= 640 && p.size.1 >= 480)
        .collect();
    if framed.len() < 9 {
        return Err(format!("only {} photos fit the scenes", framed.len()));
    }
    let (w, h) = FRAME;
    let face = cover(framed[0], w, h)?;
    // Shear a wider scene and keep the middle: the same content, no fill at the sides.
    let margin = (0.3 * h as f64).ceil() as u32;
    let wide = cover(framed[0], w + 2 * margin, h)?;
    let (sheared, _) = unshear::warp::try_apply_shear(
        &DynamicImage::ImageRgb8(wide),
        unshear::Shear::about_middle(0.3, h),
        unshear::warp::Interpolation::Linear,
        unshear::warp::Canvas::Same,
    )
    .map_err(|e| e.to_string())?;
    let sheared = imageops::crop_imm(&sheared.into_rgb8(), margin, 0, w, h).to_image();

    let mut faces = RgbImage::new(w, h);
    for (i, p) in framed[1..9].iter().enumerate() {
        let cell = cover(p, w / 4, h / 2)?;
        let (x, y) = ((i as u32 % 4) * w / 4, (i as u32 / 4) * h / 2);
        imageops::replace(&mut faces, &cell, x as i64, y as i64);
    }

    let mut empty = RgbImage::new(w, h);
    let mut cells = 0;
    for p in &photos {
        if cells == 12 {
            break;
        }
        let Some(part) = away_from_face(p)? else {
            continue;
        };
        let cell = fill(&part, w / 4, h / 3, (part.width() / 2, part.height() / 2));
        let (x, y) = ((cells % 4) * w / 4, (cells / 4) * h / 3);
        imageops::replace(&mut empty, &cell, x as i64, y as i64);
        cells += 1;
    }
    if cells < 12 {
        return Err(format!("only {cells} photos have room beside their face"));
    }

    let largest = photos
        .iter()
        .max_by_key(|p| u64::from(p.size.0) * u64::from(p.size.1))
        .ok_or("no photo with one face")?;
    let photo = cover(largest, PHOTO.0, PHOTO.1)?;

    let scenes = vec![
        scene("face on clutter", face),
        scene("face on clutter, sheared 0.3", sheared),
        scene("no face", empty),
        scene("eight faces", faces),
    ];
    Ok((scenes, scene("4000x3000 photo", photo)))
}

/// The synthetic frame: the Yale fixture face enlarged to full height on a mid-grey 1920x1080
/// canvas (the easiest frame: nothing but the face to search).
pub fn grey_canvas() -> Scene {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/fixtures/faces/subject01.normal.jpeg"
    );
    let img =
        match unshear::imageio::read_image(path.as_ref(), unshear::imageio::DEFAULT_MAX_PIXELS) {
            Ok(img) => img,
            Err(e) => panic!("fixture: {e}"),
        };
    let (w, h) = FRAME;
    let big = img.resize(w, h, FilterType::Triangle).to_rgb8();
    let mut frame = RgbImage::from_pixel(w, h, image::Rgb([128, 128, 128]));
    imageops::overlay(&mut frame, &big, i64::from((w - big.width()) / 2), 0);
    scene("synthetic: Yale face on grey canvas", frame)
}

fn scene(name: &'static str, image: RgbImage) -> Scene {
    Scene {
        name,
        image: DynamicImage::ImageRgb8(image),
    }
}

/// The photos with exactly one annotated face, in file-name order, with their sizes.
fn one_face_photos(truth: &str, images: &Path) -> Vec<Photo> {
    let mut faces: BTreeMap<&str, Vec<[f64; 4]>> = BTreeMap::new();
    for line in truth.lines() {
        let fields: Vec<&str> = line.split_whitespace().collect();
        let Some((name, rest)) = fields.split_first() else {
            continue;
        };
        let v: Vec<f64> = rest.iter().filter_map(|s| s.parse().ok()).collect();
        if v.len() == 8 {
            faces
                .entry(name)
                .or_default()
                .push([v[0], v[1], v[2], v[3]]);
        }
    }
    faces
        .into_iter()
        .filter(|(_, f)| f.len() == 1)
        .filter_map(|(name, f)| {
            let path = images.join(name);
            let size = image::image_dimensions(&path).ok()?;
            let [x1, y1, x2, y2] = f[0];
            Some(Photo {
                path,
                eyes: ((x1 + x2) / 2.0, (y1 + y2) / 2.0),
                eye_distance: (x2 - x1).hypot(y2 - y1),
                size,
            })
        })
        .collect()
}

fn load(p: &Photo) -> Result<RgbImage, String> {
    unshear::imageio::read_image(&p.path, unshear::imageio::DEFAULT_MAX_PIXELS)
        .map(|img| img.into_rgb8())
        .map_err(|e| format!("{}: {e}", p.path.display()))
}

/// `p` scaled to cover `w` x `h` and cropped about its face (kept inside the frame).
fn cover(p: &Photo, w: u32, h: u32) -> Result<RgbImage, String> {
    let img = load(p)?;
    let centre = (p.eyes.0.max(0.0) as u32, p.eyes.1.max(0.0) as u32);
    Ok(fill(&img, w, h, centre))
}

/// `img` scaled to cover `w` x `h`, cropped so that `centre` (in `img`'s pixels) is as near the
/// middle as the borders allow.
fn fill(img: &RgbImage, w: u32, h: u32, centre: (u32, u32)) -> RgbImage {
    let s = (w as f64 / img.width() as f64).max(h as f64 / img.height() as f64);
    let (sw, sh) = (
        ((img.width() as f64 * s).ceil() as u32).max(w),
        ((img.height() as f64 * s).ceil() as u32).max(h),
    );
    let scaled = imageops::resize(img, sw, sh, FilterType::Triangle);
    let clamp = |c: f64, size: u32, span: u32| {
        (c - span as f64 / 2.0).clamp(0.0, (size - span) as f64) as u32
    };
    let x = clamp(centre.0 as f64 * s, sw, w);
    let y = clamp(centre.1 as f64 * s, sh, h);
    imageops::crop_imm(&scaled, x, y, w, h).to_image()
}

/// The larger side of `p` left or right of its face (head and hair: 2.5 eye distances either
/// side of the eyes), when it is at least 240x180 px; `None` when the face leaves no such room.
fn away_from_face(p: &Photo) -> Result<Option<RgbImage>, String> {
    let (w, h) = p.size;
    let reach = 2.5 * p.eye_distance;
    let left = (p.eyes.0 - reach).max(0.0) as u32;
    let right = ((p.eyes.0 + reach).ceil() as u32).min(w);
    let (x, width) = if left >= w - right {
        (0, left)
    } else {
        (right, w - right)
    };
    if width < 240 || h < 180 {
        return Ok(None);
    }
    let img = load(p)?;
    Ok(Some(imageops::crop_imm(&img, x, 0, width, h).to_image()))
}

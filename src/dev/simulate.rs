//! A physically faithful rolling-shutter clip simulator: a camera whose view moves over a
//! panorama (or a subject walking in front of a still camera), read out row by row and
//! integrated over an exposure, with the truth of every frame and row (issue 58).
//!
//! # The model
//!
//! Time `t` is counted in frame intervals. Row `y` (0-based, of `H` rows) of frame `n` is read
//! at `t(n, y) = n + rho * y / H`, `rho` the readout fraction ([`SimulationParams`]); the row
//! time is the **middle** of the row's exposure, which lasts `e` frame intervals (`e = 0.12` is
//! 1/250 s at 30 fps). The image content moves by `u(t) = (ux(t), uy(t))` pixels (positive x:
//! content moves right in the image, positive y: down), the integral of a velocity
//! [`Profile`] in px/frame, so row `y` of frame `n` at column `x` shows the scene point
//! `(x - ux(t), y - uy(t))` averaged over `t` in `t(n, y) ± e/2` (bilinear samples of the scene,
//! about one sample per pixel of motion). At a constant velocity `v` the rows are displaced by
//! `k * (y - c)` relative to the middle row `c = H/2`, with `k = rho * v / H`: exactly
//! [`crate::warp::apply_shear`] with [`crate::Shear::about_middle`].
//!
//! The scene ([`Scene`]) wraps around horizontally (a 360-degree panorama) and vertically (the
//! photos' bottom meets their top), so any motion keeps moving real content; give vertical
//! motion a taller scene so the seam stays out of view most of the time.
//!
//! Every frame comes with its [`FrameTruth`]: the velocity and shear at the middle row, the
//! offset of every row relative to the middle row, and where each known face appears with the
//! shear at its eyes' row.

use std::path::PathBuf;

use image::{imageops::FilterType, DynamicImage, RgbImage};
use rayon::prelude::*;
use serde::Serialize;

use crate::dev::dataset::AnnotatedFace;
use crate::error::{Error, Result};
use crate::geometry::Point;
use crate::rng::SplitMix64;

/// Steps of the position table per frame interval: positions are integrated with Simpson's
/// rule and interpolated with cubic Hermite polynomials (the exact velocities as slopes), far
/// below 0.001 px of error for every profile here.
const TABLE_STEPS_PER_FRAME: f64 = 64.0;

/// The largest frame side accepted (a bound on memory, not a limit of the model).
pub const MAX_SIDE: u32 = 16384;

/// The largest frame accepted, pixels (a bound on memory).
pub const MAX_FRAME_PIXELS: u64 = 1 << 26;

/// The widest panorama [`Scene::from_images`] builds, pixels.
pub const MAX_SCENE_WIDTH: u32 = 1 << 20;

/// The most pixels of scene (panorama plus a frame's width) a [`Simulator`] holds: it keeps
/// them as f32 RGB, 12 bytes a pixel (1.6 GB at this limit).
pub const MAX_SCENE_PIXELS: u64 = 1 << 27;

/// Frames of full speed in each direction of [`Profile::Pause`].
pub const PAUSE_MOVE_FRAMES: f64 = 20.0;
/// Frames of each smoothstep ease of [`Profile::Pause`] (full speed to still, still to full).
pub const PAUSE_EASE_FRAMES: f64 = 12.0;
/// Frames of each stop of [`Profile::Pause`].
pub const PAUSE_STILL_FRAMES: f64 = 15.0;
/// Period of [`Profile::Accelerate`], frames: the velocity changes by up to
/// `2 pi rho / 8 = 0.63 V` during one readout at `rho = 0.8`, so row offsets are visibly curved.
pub const ACCELERATE_PERIOD_FRAMES: f64 = 8.0;

/// A velocity profile: the image velocity of the content over time, px/frame (or, for
/// [`Profile::Walk`], of the subject in front of a still camera).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum Profile {
    /// A steady pan: `v` throughout.
    Constant {
        /// Velocity, px/frame.
        v: f64,
    },
    /// A camera following someone (a PTZ camera): `v` for [`PAUSE_MOVE_FRAMES`], a smoothstep
    /// ease to a stop over [`PAUSE_EASE_FRAMES`], still for [`PAUSE_STILL_FRAMES`], an ease to
    /// `-v`, and so on (starting at full speed).
    Pause {
        /// Peak velocity, px/frame.
        v: f64,
    },
    /// A pan whose speed changes within a frame: `v * sin(2 pi t / P)`, `P =`
    /// [`ACCELERATE_PERIOD_FRAMES`].
    Accelerate {
        /// Peak velocity, px/frame.
        v: f64,
    },
    /// Hand-held shake: four sinusoids (about 0.6, 1.5, 3.5 and 7 Hz, each frequency drawn
    /// within ±25%, random phases) and a slow drift (a constant share of 0.15), scaled so
    /// `|v|` never exceeds `v` and comes near it.
    Shaky {
        /// Peak velocity, px/frame.
        v: f64,
        /// Seed of the frequencies, phases and drift direction.
        seed: u64,
    },
    /// A still camera and a subject (a face sprite cut from the scene) moving across the frame
    /// at `v`: only the subject is sheared. Horizontal only.
    Walk {
        /// The subject's velocity, px/frame.
        v: f64,
    },
}

/// Relative amplitudes and base frequencies (Hz) of [`Profile::Shaky`]'s sinusoids.
const SHAKE: [(f64, f64); 4] = [(1.0, 0.6), (0.6, 1.5), (0.35, 3.5), (0.2, 7.0)];
/// [`Profile::Shaky`]'s drift, relative to the first sinusoid.
const SHAKE_DRIFT: f64 = 0.15;

fn smoothstep(s: f64) -> f64 {
    let s = s.clamp(0.0, 1.0);
    s * s * (3.0 - 2.0 * s)
}

impl Profile {
    /// The peak speed `V`, px/frame.
    pub fn peak(&self) -> f64 {
        match *self {
            Profile::Constant { v }
            | Profile::Pause { v }
            | Profile::Accelerate { v }
            | Profile::Shaky { v, .. }
            | Profile::Walk { v } => v,
        }
    }

    /// The velocity at time `t` (frame intervals), px/frame. `fps` sets the frequencies of
    /// [`Profile::Shaky`] (a hand's shake is physical, in Hz); the others ignore it.
    pub fn velocity(&self, t: f64, fps: f64) -> f64 {
        match *self {
            Profile::Constant { v } | Profile::Walk { v } => v,
            Profile::Pause { v } => {
                let (m, e, q) = (PAUSE_MOVE_FRAMES, PAUSE_EASE_FRAMES, PAUSE_STILL_FRAMES);
                let half = 2.0 * e + m + q;
                // t = 0 is the end of the first ease, at full speed.
                let p = (t + e).rem_euclid(2.0 * half);
                let (sign, q_in) = if p < half { (1.0, p) } else { (-1.0, p - half) };
                let shape = if q_in < e {
                    smoothstep(q_in / e)
                } else if q_in < e + m {
                    1.0
                } else if q_in < 2.0 * e + m {
                    1.0 - smoothstep((q_in - e - m) / e)
                } else {
                    0.0
                };
                sign * v * shape
            }
            Profile::Accelerate { v } => {
                v * (2.0 * std::f64::consts::PI * t / ACCELERATE_PERIOD_FRAMES).sin()
            }
            Profile::Shaky { v, seed } => {
                let (drift, parts) = shake_parts(seed, fps);
                let total: f64 = SHAKE.iter().map(|(a, _)| a).sum::<f64>() + SHAKE_DRIFT;
                let sum: f64 = parts
                    .iter()
                    .map(|(a, f, phase)| a * (2.0 * std::f64::consts::PI * f * t + phase).sin())
                    .sum();
                v * (drift + sum) / total
            }
        }
    }

    fn name(&self) -> &'static str {
        match self {
            Profile::Constant { .. } => "constant",
            Profile::Pause { .. } => "pause",
            Profile::Accelerate { .. } => "accelerate",
            Profile::Shaky { .. } => "shaky",
            Profile::Walk { .. } => "walk",
        }
    }
}

/// [`Profile::Shaky`]'s drift and `(amplitude, cycles per frame, phase)` of each sinusoid.
fn shake_parts(seed: u64, fps: f64) -> (f64, [(f64, f64, f64); 4]) {
    let mut rng = SplitMix64::new(seed ^ 0x5348_414b_4553_4545);
    let mut parts = [(0.0, 0.0, 0.0); 4];
    for (slot, (a, hz)) in parts.iter_mut().zip(SHAKE) {
        let f = hz * (1.25f64).powf(rng.symmetric(1.0)) / fps;
        let phase = rng.next_f64() * 2.0 * std::f64::consts::PI;
        *slot = (a, f, phase);
    }
    let drift = if rng.next_u64() & 1 == 0 {
        SHAKE_DRIFT
    } else {
        -SHAKE_DRIFT
    };
    (drift, parts)
}

/// What to render: the frame, the sensor and the motion. Plain values; [`Self::validate`]
/// checks them (every [`Simulator`] does).
#[derive(Debug, Clone, PartialEq)]
pub struct SimulationParams {
    /// Frame width, pixels.
    pub width: u32,
    /// Frame height `H`, pixels (rows).
    pub height: u32,
    /// Number of frames.
    pub frames: u32,
    /// Frames per second (written into the truth and the y4m header; sets the shake's
    /// frequencies).
    pub fps: f64,
    /// `rho`: the readout time of a whole frame over the frame interval, in (0, 1.2].
    pub readout_fraction: f64,
    /// `e`: each row's exposure over the frame interval, in [0, 1]; 0 renders one instant.
    pub exposure: f64,
    /// Horizontal motion (of the camera's view, or of the subject for [`Profile::Walk`]).
    pub motion: Profile,
    /// Vertical motion, if any (of the subject for [`Profile::Walk`]); not `Walk` itself.
    pub vertical: Option<Profile>,
    /// Sensor noise, standard deviation in grey levels (fresh every frame).
    pub noise: f64,
    /// Seed of the noise.
    pub seed: u64,
}

impl Default for SimulationParams {
    /// 1280x720, 90 frames at 30 fps, `rho = 0.8`, 1/250 s exposure, a still camera, noise 2.
    fn default() -> Self {
        Self {
            width: 1280,
            height: 720,
            frames: 90,
            fps: 30.0,
            readout_fraction: 0.8,
            exposure: 0.12,
            motion: Profile::Constant { v: 0.0 },
            vertical: None,
            noise: 2.0,
            seed: 0,
        }
    }
}

impl SimulationParams {
    /// The peak speed `V = K * H / rho` that shears a frame by `K` at the middle row.
    pub fn speed_for_k(&self, k: f64) -> f64 {
        k * f64::from(self.height) / self.readout_fraction
    }

    /// Checks every value: sizes above 0 (and within [`MAX_SIDE`] and [`MAX_FRAME_PIXELS`]),
    /// `fps` positive, `readout_fraction` in (0, 1.2], `exposure` in [0, 1], `noise` >= 0,
    /// speeds finite and at most 16 frame widths (or heights) a frame, no vertical `Walk`.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming the first bad value.
    pub fn validate(&self) -> Result<()> {
        let bad = |msg: String| Err(Error::InvalidArgument(msg));
        if self.width == 0 || self.height == 0 || self.frames == 0 {
            return bad(format!(
                "the frame size and count must be above 0 (got {}x{}, {} frames)",
                self.width, self.height, self.frames
            ));
        }
        if self.width > MAX_SIDE
            || self.height > MAX_SIDE
            || u64::from(self.width) * u64::from(self.height) > MAX_FRAME_PIXELS
        {
            return bad(format!(
                "a {}x{} frame is too large (at most {MAX_SIDE} a side, {MAX_FRAME_PIXELS} pixels)",
                self.width, self.height
            ));
        }
        if !(self.fps.is_finite() && self.fps > 0.0) {
            return bad(format!("fps must be positive (got {})", self.fps));
        }
        if !(self.readout_fraction > 0.0 && self.readout_fraction <= 1.2) {
            return bad(format!(
                "the readout fraction must be in (0, 1.2] (got {})",
                self.readout_fraction
            ));
        }
        if !(0.0..=1.0).contains(&self.exposure) {
            return bad(format!(
                "the exposure must be in [0, 1] frame intervals (got {})",
                self.exposure
            ));
        }
        if !(self.noise.is_finite() && self.noise >= 0.0) {
            return bad(format!(
                "the noise must be 0 or more grey levels (got {})",
                self.noise
            ));
        }
        let limit_x = 16.0 * f64::from(self.width);
        let limit_y = 16.0 * f64::from(self.height);
        for (profile, limit, what) in [
            (Some(self.motion), limit_x, "horizontal"),
            (self.vertical, limit_y, "vertical"),
        ] {
            let Some(p) = profile else { continue };
            let v = p.peak();
            if !v.is_finite() || v.abs() > limit {
                return bad(format!(
                    "the {what} speed must be finite and at most {limit} px/frame (got {v})"
                ));
            }
        }
        if let Some(Profile::Walk { .. }) = self.vertical {
            return bad("the vertical motion cannot be `walk`".into());
        }
        Ok(())
    }

    fn middle_row(&self) -> f64 {
        f64::from(self.height) / 2.0
    }

    /// `t(n, y) = n + rho * y / H`: when row `y` of frame `n` is read (the middle of its
    /// exposure), frame intervals.
    pub fn row_time(&self, frame: u32, y: f64) -> f64 {
        f64::from(frame) + self.readout_fraction * y / f64::from(self.height)
    }
}

/// A face of the scene: its eye centres in scene coordinates (pixel `(0, 0)` centred on
/// `(0.0, 0.0)`), so the truth can say where it appears in every frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SceneFace {
    /// The subject's right eye (image left).
    pub right_eye: Point,
    /// The subject's left eye (image right).
    pub left_eye: Point,
}

impl SceneFace {
    fn eye_distance(&self) -> f64 {
        self.right_eye.distance(self.left_eye)
    }

    fn mid(&self) -> Point {
        Point::new(
            (self.right_eye.x + self.left_eye.x) / 2.0,
            (self.right_eye.y + self.left_eye.y) / 2.0,
        )
    }
}

/// One photo of a scene, with the faces known in it (in the photo's own pixel coordinates).
#[derive(Debug, Clone)]
pub struct ScenePhoto {
    /// The photo.
    pub image: DynamicImage,
    /// Its known faces (none for a plain image).
    pub faces: Vec<SceneFace>,
}

/// The panorama the camera looks at: photos scaled to one height and joined side by side,
/// wrapping around at both ends, with the known faces in panorama coordinates.
#[derive(Debug, Clone)]
pub struct Scene {
    image: RgbImage,
    faces: Vec<SceneFace>,
}

impl Scene {
    /// A ready panorama and its faces (in its coordinates), e.g. for a test.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for an empty image.
    pub fn new(image: RgbImage, faces: Vec<SceneFace>) -> Result<Self> {
        if image.width() == 0 || image.height() == 0 {
            return Err(Error::InvalidArgument("the scene is empty".into()));
        }
        Ok(Self { image, faces })
    }

    /// Scales each photo to `height` rows (Lanczos3, aspect kept) and joins them left to
    /// right, moving their faces along.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] without photos, for an empty photo, `height` 0 or above
    /// [`MAX_SIDE`], or a panorama wider than [`MAX_SCENE_WIDTH`].
    pub fn from_images(photos: &[ScenePhoto], height: u32) -> Result<Self> {
        if photos.is_empty() || height == 0 || height > MAX_SIDE {
            return Err(Error::InvalidArgument(format!(
                "a scene needs photos and a height in 1..={MAX_SIDE} (got {} photos, height {height})",
                photos.len()
            )));
        }
        let widths = photos
            .iter()
            .map(|photo| {
                let (w, h) = (photo.image.width(), photo.image.height());
                if w == 0 || h == 0 {
                    return Err(Error::InvalidArgument("an empty photo".into()));
                }
                Ok((f64::from(w) * f64::from(height) / f64::from(h))
                    .round()
                    .max(1.0))
            })
            .collect::<Result<Vec<f64>>>()?;
        let total: f64 = widths.iter().sum();
        if total > MAX_SCENE_WIDTH as f64 {
            return Err(Error::InvalidArgument(format!(
                "the panorama would be {total} pixels wide (at most {MAX_SCENE_WIDTH})"
            )));
        }
        let mut scaled = Vec::with_capacity(photos.len());
        let mut faces = Vec::new();
        let mut x_at = 0u64;
        for (photo, &new_w) in photos.iter().zip(&widths) {
            let (w, h) = (photo.image.width(), photo.image.height());
            let new_w = new_w as u32;
            let rgb = photo.image.to_rgb8();
            let img = image::imageops::resize(&rgb, new_w, height, FilterType::Lanczos3);
            let (sx, sy) = (
                f64::from(new_w) / f64::from(w),
                f64::from(height) / f64::from(h),
            );
            let map =
                |p: Point| Point::new((p.x + 0.5) * sx - 0.5 + x_at as f64, (p.y + 0.5) * sy - 0.5);
            faces.extend(photo.faces.iter().map(|f| SceneFace {
                right_eye: map(f.right_eye),
                left_eye: map(f.left_eye),
            }));
            x_at += u64::from(new_w);
            scaled.push(img);
        }
        let mut image = RgbImage::new(x_at as u32, height);
        let mut x = 0i64;
        for img in &scaled {
            image::imageops::replace(&mut image, img, x, 0);
            x += i64::from(img.width());
        }
        Self::new(image, faces)
    }

    /// A scene of the Caltech faces given (each photo decoded once, all its annotated faces
    /// kept), scaled to `height`.
    ///
    /// # Errors
    /// As [`crate::imageio::read_image`] and [`Self::from_images`].
    pub fn from_annotated(faces: &[AnnotatedFace], height: u32, max_pixels: u64) -> Result<Self> {
        let mut photos: Vec<(PathBuf, ScenePhoto)> = Vec::new();
        for f in faces {
            let face = SceneFace {
                right_eye: f.right_eye,
                left_eye: f.left_eye,
            };
            match photos.iter_mut().find(|(p, _)| *p == f.image) {
                Some((_, photo)) => photo.faces.push(face),
                None => photos.push((
                    f.image.clone(),
                    ScenePhoto {
                        image: crate::imageio::read_image(&f.image, max_pixels)?,
                        faces: vec![face],
                    },
                )),
            }
        }
        let photos: Vec<ScenePhoto> = photos.into_iter().map(|(_, p)| p).collect();
        Self::from_images(&photos, height)
    }

    /// A smooth seeded texture without faces (blobs of colour at several scales and fine
    /// grain): content a motion estimator can lock onto, for tests.
    pub fn textured(width: u32, height: u32, seed: u64) -> Self {
        let (width, height) = (width.clamp(1, MAX_SIDE), height.clamp(1, MAX_SIDE));
        let mut rng = SplitMix64::new(seed);
        // Periodic in x (the panorama wraps): whole numbers of cycles across the width.
        let waves: Vec<(f64, f64, f64, [f64; 3])> = (0..24)
            .map(|i| {
                let cycles = (1 + (rng.next_u64() % (4 + 3 * i as u64))) as f64;
                let fy = rng.next_f64() * 0.02 * (1.0 + i as f64 / 4.0);
                let phase = rng.next_f64() * std::f64::consts::TAU;
                let amp = 40.0 / (1.0 + i as f64 / 6.0);
                let colour = [rng.symmetric(amp), rng.symmetric(amp), rng.symmetric(amp)];
                (
                    cycles * std::f64::consts::TAU / f64::from(width),
                    fy,
                    phase,
                    colour,
                )
            })
            .collect();
        let mut image = RgbImage::new(width, height);
        let mut grain = SplitMix64::new(seed ^ 0x0067_7261_696e);
        for (x, y, px) in image.enumerate_pixels_mut() {
            let mut c = [128.0f64; 3];
            for (fx, fy, phase, colour) in &waves {
                let s =
                    (fx * f64::from(x) + fy * f64::from(y) * std::f64::consts::TAU + phase).sin();
                for (ch, a) in c.iter_mut().zip(colour) {
                    *ch += a * s;
                }
            }
            let g = grain.symmetric(12.0);
            px.0 = c.map(|v| (v + g).round().clamp(0.0, 255.0) as u8);
        }
        Self {
            image,
            faces: Vec::new(),
        }
    }

    /// The panorama.
    pub fn image(&self) -> &RgbImage {
        &self.image
    }

    /// The known faces, in panorama coordinates.
    pub fn faces(&self) -> &[SceneFace] {
        &self.faces
    }
}

/// The seed of the fixed order [`development_faces`] draws from (so `--first` always means the
/// same faces).
pub const DEVELOPMENT_FACES_SEED: u64 = 58;

/// The smallest eye distance of a development face once scaled to the scene's height, pixels.
pub const MIN_DEVELOPMENT_EYE_DISTANCE: f64 = 40.0;

/// Development faces for clips: the Caltech photos with exactly one annotated face whose eyes
/// are at least `min_eye_distance` px apart once the photo is scaled to `height` rows, in a
/// fixed order shuffled by `seed`, from the `first` on, `count` of them (fewer if the set runs
/// out). Only the photos' headers are read, and only until enough are found.
///
/// # Errors
/// [`Error::Image`] if a photo's header cannot be read.
pub fn development_faces(
    faces: Vec<AnnotatedFace>,
    height: u32,
    min_eye_distance: f64,
    first: usize,
    count: usize,
    seed: u64,
) -> Result<Vec<AnnotatedFace>> {
    let mut single: Vec<AnnotatedFace> = crate::dev::dataset::by_image(faces)
        .into_iter()
        .filter(|(_, f)| f.len() == 1)
        .filter_map(|(_, mut f)| f.pop())
        .collect();
    let mut rng = SplitMix64::new(seed);
    for i in (1..single.len()).rev() {
        let j = (rng.next_u64() % (i as u64 + 1)) as usize;
        single.swap(i, j);
    }
    let mut picked = Vec::new();
    let mut seen = 0usize;
    for f in single {
        if picked.len() >= count {
            break;
        }
        let (_, h) = image::image_dimensions(&f.image).map_err(|source| Error::Image {
            path: f.image.clone(),
            source,
        })?;
        if h == 0 || f.eye_distance() * f64::from(height) / f64::from(h) < min_eye_distance {
            continue;
        }
        if seen >= first {
            picked.push(f);
        }
        seen += 1;
    }
    Ok(picked)
}

/// One face in one frame: where its eyes appear and the shear it carries.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FaceTruth {
    /// Its index in [`Scene::faces`].
    pub face: usize,
    /// Whether this is the walking subject ([`Profile::Walk`]) rather than part of the
    /// background.
    pub subject: bool,
    /// Where the subject's right eye (image left) appears, frame pixels.
    pub right_eye: [f64; 2],
    /// Where the subject's left eye appears, frame pixels.
    pub left_eye: [f64; 2],
    /// The face's image velocity `(vx, vy)` when its eyes' row is read, px/frame.
    pub velocity: [f64; 2],
    /// The shear at its eyes' row: `rho * vx / H` at that row's time.
    pub k: f64,
}

/// The walking subject of [`Profile::Walk`] in one frame.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SubjectTruth {
    /// The sprite's centre at the middle row's time, frame pixels (it may be outside).
    pub center: [f64; 2],
    /// Its velocity `(vx, vy)` at the middle row's time, px/frame.
    pub velocity: [f64; 2],
    /// Its shear at the middle row's time, `rho * vx / H`.
    pub k: f64,
}

/// The truth of one frame: one JSON line of `unshear simulate --truth`.
///
/// The frame-level velocity, `k` and row offsets are the camera's (the background's); for
/// [`Profile::Walk`] they are 0 and the subject's motion is in [`Self::subject`] and its face.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FrameTruth {
    /// Frame number, from 0.
    pub frame: u32,
    /// The middle row's time `n + rho / 2`, frame intervals.
    pub time: f64,
    /// The image velocity `(vx, vy)` at [`Self::time`], px/frame.
    pub velocity: [f64; 2],
    /// The shear at the middle row: `rho * vx / H` at [`Self::time`] (`d row_offsets / dy` at
    /// `c = H/2`).
    pub k: f64,
    /// For every row `y`, `ux(t(n, y)) - ux(t(n, H/2))`: how far it is displaced relative to
    /// the middle row; `out(x, y) = in(x + row_offsets[y], y)` undoes it.
    pub row_offsets: Vec<f64>,
    /// The same for vertical motion, when there is any.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub row_offsets_y: Option<Vec<f64>>,
    /// The scene faces whose eyes are both inside the frame, at least one eye distance from
    /// its edges, and not covered by the walking subject.
    pub faces: Vec<FaceTruth>,
    /// The walking subject ([`Profile::Walk`] only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub subject: Option<SubjectTruth>,
    /// The horizontal motion profile's name (`constant`, `pause`, `accelerate`, `shaky`,
    /// `walk`).
    pub motion: &'static str,
    /// `rho`, as in [`SimulationParams::readout_fraction`].
    pub readout_fraction: f64,
    /// `e`, as in [`SimulationParams::exposure`].
    pub exposure: f64,
    /// Frames per second.
    pub fps: f64,
}

/// A position `u(t)` tabulated from a velocity profile: Simpson's rule between nodes, cubic
/// Hermite (with the exact velocities as slopes) within them.
#[derive(Debug, Clone)]
struct Track {
    t0: f64,
    step: f64,
    pos: Vec<f64>,
    vel: Vec<f64>,
    profile: Option<Profile>,
    fps: f64,
}

impl Track {
    /// `u(0) = 0`, tabulated over `[t0, t1]`.
    fn new(profile: Option<Profile>, fps: f64, t0: f64, t1: f64) -> Self {
        let step = 1.0 / TABLE_STEPS_PER_FRAME;
        let n = ((t1 - t0) / step).ceil() as usize + 1;
        let v = |t: f64| profile.map_or(0.0, |p| p.velocity(t, fps));
        let vel: Vec<f64> = (0..n).map(|i| v(t0 + i as f64 * step)).collect();
        let mut pos = vec![0.0; n];
        for i in 1..n {
            let mid = v(t0 + (i as f64 - 0.5) * step);
            pos[i] = pos[i - 1] + step / 6.0 * (vel[i - 1] + 4.0 * mid + vel[i]);
        }
        let mut track = Self {
            t0,
            step,
            pos,
            vel,
            profile,
            fps,
        };
        let at_zero = track.at(0.0);
        track.pos.iter_mut().for_each(|p| *p -= at_zero);
        track
    }

    fn velocity(&self, t: f64) -> f64 {
        self.profile.map_or(0.0, |p| p.velocity(t, self.fps))
    }

    fn at(&self, t: f64) -> f64 {
        let last = self.pos.len() - 1;
        let s = (t - self.t0) / self.step;
        if s <= 0.0 {
            return self.pos[0] + (t - self.t0) * self.vel[0];
        }
        if s >= last as f64 {
            return self.pos[last] + (t - self.t0 - last as f64 * self.step) * self.vel[last];
        }
        let i = s.floor() as usize;
        let f = s - i as f64;
        let (p0, p1) = (self.pos[i], self.pos[i + 1]);
        let (m0, m1) = (self.vel[i] * self.step, self.vel[i + 1] * self.step);
        let (f2, f3) = (f * f, f * f * f);
        (2.0 * f3 - 3.0 * f2 + 1.0) * p0
            + (f3 - 2.0 * f2 + f) * m0
            + (-2.0 * f3 + 3.0 * f2) * p1
            + (f3 - f2) * m1
    }
}

/// The walking subject: an elliptical, soft-edged cut of the scene around a face.
#[derive(Debug, Clone)]
struct Sprite {
    face: usize,
    /// The cut's centre in scene coordinates.
    source: Point,
    /// Semi-axes of the ellipse, pixels.
    half: (f64, f64),
    /// Where its centre is in the frame at `t = 0`.
    start: Point,
}

impl Sprite {
    /// Opacity at `(dx, dy)` from the centre: 1 inside, a smooth fall to 0 over the outer
    /// 15% of the radius.
    fn alpha(&self, dx: f64, dy: f64) -> f32 {
        let r = ((dx / self.half.0).powi(2) + (dy / self.half.1).powi(2)).sqrt();
        (1.0 - smoothstep((r - 0.85) / 0.15)) as f32
    }
}

/// Renders the frames of one clip and their truth.
#[derive(Debug, Clone)]
pub struct Simulator {
    params: SimulationParams,
    scene: Scene,
    /// The panorama as f32 RGB, each row followed by its first `width + 2` columns again so a
    /// row span never wraps.
    padded: Vec<f32>,
    padded_width: usize,
    /// Scene point seen at frame `(0, 0)` when `u = 0`.
    origin: Point,
    x: Track,
    y: Track,
    sprite: Option<Sprite>,
}

impl Simulator {
    /// A simulator of `params` over `scene`. A pan starts with the scene's first face (if any)
    /// in the middle of the frame; a walk's still background is the part of the panorama
    /// farthest from the subject's face (the first face, or the scene's middle without one).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] from [`SimulationParams::validate`], or for a scene of more
    /// than [`MAX_SCENE_PIXELS`] with the frame's width added.
    pub fn new(scene: Scene, params: SimulationParams) -> Result<Self> {
        params.validate()?;
        let held = (u64::from(scene.image.width()) + u64::from(params.width) + 2)
            * u64::from(scene.image.height());
        if held > MAX_SCENE_PIXELS {
            return Err(Error::InvalidArgument(format!(
                "a {}x{} scene with {}-pixel-wide frames is too large to hold (at most \
                 {MAX_SCENE_PIXELS} pixels)",
                scene.image.width(),
                scene.image.height(),
                params.width
            )));
        }
        let (w, h) = (f64::from(params.width), f64::from(params.height));
        let (sw, sh) = (
            f64::from(scene.image.width()),
            f64::from(scene.image.height()),
        );
        let y_origin = f64::from((scene.image.height() as i64 - params.height as i64) as i32 / 2);
        let walk = matches!(params.motion, Profile::Walk { .. });
        let sprite = walk.then(|| {
            let (face, source, half) = match scene.faces.first() {
                Some(f) => {
                    let d = f.eye_distance().max(4.0);
                    let m = f.mid();
                    (0, Point::new(m.x, m.y + 0.45 * d), (1.4 * d, 2.0 * d))
                }
                None => (
                    usize::MAX,
                    Point::new(sw / 2.0, sh / 2.0),
                    (h / 6.0, h / 4.0),
                ),
            };
            Sprite {
                face,
                source,
                half,
                start: Point::new(w / 2.0, source.y - y_origin),
            }
        });
        let origin = match (&sprite, scene.faces.first()) {
            (Some(s), _) => Point::new(s.source.x + sw / 2.0 - w / 2.0, y_origin),
            (None, Some(f)) => Point::new(f.mid().x - w / 2.0, y_origin),
            (None, None) => Point::new(0.0, y_origin),
        };
        let margin = 2.0 + params.exposure;
        let t1 = f64::from(params.frames) + 1.2 + margin;
        let x = Track::new(Some(params.motion), params.fps, -margin, t1);
        let y = Track::new(params.vertical, params.fps, -margin, t1);
        let padded_width = scene.image.width() as usize + params.width as usize + 2;
        let src_w = scene.image.width() as usize;
        let mut padded = vec![0f32; padded_width * 3 * scene.image.height() as usize];
        padded
            .par_chunks_mut(padded_width * 3)
            .zip(scene.image.par_chunks(src_w * 3))
            .for_each(|(dst, src)| {
                for (i, d) in dst.iter_mut().enumerate() {
                    *d = f32::from(src[i % (src_w * 3)]);
                }
            });
        Ok(Self {
            params,
            scene,
            padded,
            padded_width,
            origin,
            x,
            y,
            sprite,
        })
    }

    /// The parameters.
    pub fn params(&self) -> &SimulationParams {
        &self.params
    }

    /// The scene.
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    fn walking(&self) -> bool {
        self.sprite.is_some()
    }

    /// The camera's content offset `u(t) = (ux, uy)` at time `t`, pixels, `u(0) = (0, 0)`:
    /// always 0 for a walk (the camera is still).
    pub fn offset(&self, t: f64) -> [f64; 2] {
        if self.walking() {
            [0.0, 0.0]
        } else {
            [self.x.at(t), self.y.at(t)]
        }
    }

    /// The camera's image velocity `v(t) = du/dt` at time `t`, px/frame.
    pub fn velocity(&self, t: f64) -> [f64; 2] {
        if self.walking() {
            [0.0, 0.0]
        } else {
            [self.x.velocity(t), self.y.velocity(t)]
        }
    }

    /// The walking subject's centre in the frame at time `t` (it wraps from one side to the
    /// other while out of view).
    fn sprite_center(&self, s: &Sprite, t: f64) -> Point {
        let w = f64::from(self.params.width);
        let span = w + 2.0 * s.half.0;
        let x = (s.start.x + self.x.at(t) + s.half.0).rem_euclid(span) - s.half.0;
        Point::new(x, s.start.y + self.y.at(t))
    }

    /// Renders frame `n` and its truth.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for `n` past the clip's last frame.
    pub fn render(&self, n: u32) -> Result<(RgbImage, FrameTruth)> {
        if n >= self.params.frames {
            return Err(Error::InvalidArgument(format!(
                "frame {n} is past the clip's {} frames",
                self.params.frames
            )));
        }
        let (w, h) = (self.params.width as usize, self.params.height as usize);
        let mut out = RgbImage::new(self.params.width, self.params.height);
        out.par_chunks_mut(w * 3).enumerate().for_each_init(
            || vec![0f32; w * 3],
            |acc, (y, row)| {
                self.render_row(n, y, acc);
                self.finish_row(n, y, acc, row);
            },
        );
        debug_assert_eq!(out.len(), w * h * 3);
        Ok((out, self.truth(n)))
    }

    /// The exposure's sample times for the row read at `t`: one per pixel of motion, at least
    /// one, at the middles of equal sub-intervals.
    fn sample_times(&self, t: f64) -> impl Iterator<Item = f64> {
        let e = self.params.exposure;
        let count = if e == 0.0 {
            1
        } else {
            let (a, b) = (t - e / 2.0, t + e / 2.0);
            let dist = if let Some(s) = &self.sprite {
                let (p, q) = (self.sprite_center(s, a), self.sprite_center(s, b));
                // The subject wraps while out of view: its true travel is |v| e.
                (self.x.velocity(t).abs() * e).max((q.y - p.y).abs())
            } else {
                (self.x.at(b) - self.x.at(a)).hypot(self.y.at(b) - self.y.at(a))
            };
            (dist.ceil() as usize).max(1)
        };
        (0..count).map(move |i| t + e * ((i as f64 + 0.5) / count as f64 - 0.5))
    }

    /// Bilinear row-span weights: where a span of the scene row at `sy` starting at column
    /// `sx` begins in `padded`, and the four weights.
    fn span(&self, sx: f64, sy: f64) -> (usize, usize, [f32; 4]) {
        let sw = self.scene.image.width() as i64;
        let sh = self.scene.image.height() as i64;
        let (x0, y0) = (sx.floor(), sy.floor());
        let (fx, fy) = ((sx - x0) as f32, (sy - y0) as f32);
        let col = (x0 as i64).rem_euclid(sw) as usize;
        let r0 = (y0 as i64).rem_euclid(sh) as usize;
        let r1 = (r0 + 1) % sh as usize;
        let stride = self.padded_width * 3;
        (
            r0 * stride + col * 3,
            r1 * stride + col * 3,
            [
                (1.0 - fx) * (1.0 - fy),
                fx * (1.0 - fy),
                (1.0 - fx) * fy,
                fx * fy,
            ],
        )
    }

    /// Adds the scene row span seen from `(sx, sy)` (for frame columns 0..width) into `acc`.
    fn add_span(&self, acc: &mut [f32], sx: f64, sy: f64) {
        let n = acc.len();
        let (a, b, [w00, w01, w10, w11]) = self.span(sx, sy);
        let r0 = &self.padded[a..a + n + 3];
        if w10 == 0.0 && w11 == 0.0 {
            for ((o, p), q) in acc.iter_mut().zip(&r0[..n]).zip(&r0[3..]) {
                *o += w00 * p + w01 * q;
            }
        } else {
            let r1 = &self.padded[b..b + n + 3];
            for (((o, p), q), (r, s)) in acc
                .iter_mut()
                .zip(&r0[..n])
                .zip(&r0[3..])
                .zip(r1[..n].iter().zip(&r1[3..]))
            {
                *o += w00 * p + w01 * q + w10 * r + w11 * s;
            }
        }
    }

    /// The scene's colour at `(sx, sy)`, bilinear, wrapping.
    fn sample(&self, sx: f64, sy: f64) -> [f32; 3] {
        let (a, b, [w00, w01, w10, w11]) = self.span(sx, sy);
        let p = &self.padded;
        [0, 1, 2].map(|c| w00 * p[a + c] + w01 * p[a + 3 + c] + w10 * p[b + c] + w11 * p[b + 3 + c])
    }

    /// Row `y` of frame `n`, averaged over its exposure, into `acc` (not yet rounded).
    fn render_row(&self, n: u32, y: usize, acc: &mut [f32]) {
        acc.iter_mut().for_each(|v| *v = 0.0);
        let t = self.params.row_time(n, y as f64);
        let fy = y as f64;
        let mut count = 0usize;
        match &self.sprite {
            None => {
                for ts in self.sample_times(t) {
                    let sx = self.origin.x - self.x.at(ts);
                    let sy = fy + self.origin.y - self.y.at(ts);
                    self.add_span(acc, sx, sy);
                    count += 1;
                }
            }
            Some(s) => {
                // A still background behind the subject: sum of (bg + alpha (sprite - bg)).
                let mut bg = vec![0f32; acc.len()];
                self.add_span(&mut bg, self.origin.x, fy + self.origin.y);
                let w = self.params.width as i64;
                for ts in self.sample_times(t) {
                    count += 1;
                    let c = self.sprite_center(s, ts);
                    let dy = fy - c.y;
                    if dy.abs() >= s.half.1 {
                        continue;
                    }
                    let from = ((c.x - s.half.0).floor() as i64).clamp(0, w) as usize;
                    let to = ((c.x + s.half.0).ceil() as i64 + 1).clamp(0, w) as usize;
                    for x in from..to {
                        let dx = x as f64 - c.x;
                        let alpha = s.alpha(dx, dy);
                        if alpha <= 0.0 {
                            continue;
                        }
                        let colour = self.sample(s.source.x + dx, s.source.y + dy);
                        for (ch, v) in colour.iter().enumerate() {
                            let i = 3 * x + ch;
                            acc[i] += alpha * (v - bg[i]);
                        }
                    }
                }
                for (o, b) in acc.iter_mut().zip(&bg) {
                    *o += count as f32 * b;
                }
            }
        }
        let scale = 1.0 / count.max(1) as f32;
        acc.iter_mut().for_each(|v| *v *= scale);
    }

    /// Adds the sensor noise of row `y` of frame `n` and rounds into `row`.
    fn finish_row(&self, n: u32, y: usize, acc: &[f32], row: &mut [u8]) {
        let sigma = self.params.noise as f32;
        if sigma == 0.0 {
            for (o, v) in row.iter_mut().zip(acc) {
                *o = v.round().clamp(0.0, 255.0) as u8;
            }
            return;
        }
        let mut rng = SplitMix64::new(
            self.params
                .seed
                .wrapping_mul(0x9e37_79b9_7f4a_7c15)
                .wrapping_add(u64::from(n) << 32)
                .wrapping_add(y as u64),
        );
        // Irwin-Hall: four 16-bit uniforms from one draw, sum - 2 has variance 1/3.
        let unit = 3f32.sqrt() / 65536.0;
        for (o, v) in row.iter_mut().zip(acc) {
            let r = rng.next_u64();
            let sum = (r & 0xffff) + ((r >> 16) & 0xffff) + ((r >> 32) & 0xffff) + (r >> 48);
            let g = (sum as f32 - 2.0 * 65535.0) * unit;
            *o = (v + sigma * g).round().clamp(0.0, 255.0) as u8;
        }
    }

    /// The truth of frame `n` (no pixels rendered).
    pub fn truth(&self, n: u32) -> FrameTruth {
        let p = &self.params;
        let h = f64::from(p.height);
        let c = p.middle_row();
        let tc = p.row_time(n, c);
        let rows = |u: &dyn Fn(f64) -> f64| -> Vec<f64> {
            let mid = u(tc);
            (0..p.height)
                .map(|y| u(p.row_time(n, f64::from(y))) - mid)
                .collect()
        };
        let walking = self.walking();
        let row_offsets = if walking {
            vec![0.0; p.height as usize]
        } else {
            rows(&|t| self.x.at(t))
        };
        let row_offsets_y = (p.vertical.is_some() && !walking).then(|| rows(&|t| self.y.at(t)));
        let velocity = self.velocity(tc);
        let subject = self.sprite.as_ref().map(|s| {
            let centre = self.sprite_center(s, tc);
            let v = [self.x.velocity(tc), self.y.velocity(tc)];
            SubjectTruth {
                center: [centre.x, centre.y],
                velocity: v,
                k: p.readout_fraction * v[0] / h,
            }
        });
        FrameTruth {
            frame: n,
            time: tc,
            velocity,
            k: p.readout_fraction * velocity[0] / h,
            row_offsets,
            row_offsets_y,
            faces: self.faces_in(n),
            subject,
            motion: p.motion.name(),
            readout_fraction: p.readout_fraction,
            exposure: p.exposure,
            fps: p.fps,
        }
    }

    /// The faces whose eyes are in frame `n`, with the row-time dependence solved.
    fn faces_in(&self, n: u32) -> Vec<FaceTruth> {
        let p = &self.params;
        let (w, h) = (f64::from(p.width), f64::from(p.height));
        let (sw, sh) = (
            f64::from(self.scene.image.width()),
            f64::from(self.scene.image.height()),
        );
        let tc = p.row_time(n, p.middle_row());
        let mut found = Vec::new();
        // Where a point moving with `pos(t)` (frame coordinates) is seen: y = pos_y(t(n, y)).
        let solve = |pos: &dyn Fn(f64) -> Point| -> (Point, f64) {
            let mut y = pos(tc).y;
            for _ in 0..8 {
                y = pos(p.row_time(n, y)).y;
            }
            let t = p.row_time(n, y);
            (Point::new(pos(t).x, y), t)
        };
        let mut push = |face: usize, subject: bool, right: Point, left: Point, v: [f64; 2]| {
            let d = right.distance(left).max(1.0);
            let inside = |q: Point| q.x >= d && q.x <= w - d && q.y >= d && q.y <= h - d;
            if inside(right) && inside(left) {
                found.push(FaceTruth {
                    face,
                    subject,
                    right_eye: [right.x, right.y],
                    left_eye: [left.x, left.y],
                    velocity: v,
                    k: p.readout_fraction * v[0] / h,
                });
            }
        };
        // Whether the walking subject covers a background eye at `q` when its row is read.
        let hidden = |q: Point, t: f64| {
            self.sprite.as_ref().is_some_and(|s| {
                let c = self.sprite_center(s, t);
                s.alpha(q.x - c.x, q.y - c.y) > 0.5
            })
        };
        // Background faces: every copy of the wrapped panorama near the view.
        let u = self.offset(tc);
        for (i, f) in self.scene.faces.iter().enumerate() {
            let m = f.mid();
            let fx = m.x - self.origin.x + u[0];
            let fy = m.y - self.origin.y + u[1];
            let d = f.eye_distance();
            let span = |at: f64, size: f64, period: f64| {
                let lo = ((-at - d - size) / period).floor() as i64 - 1;
                let hi = ((size - at + d + size) / period).ceil() as i64 + 1;
                lo..=hi
            };
            for mx in span(fx, w, sw) {
                for my in span(fy, h, sh) {
                    let shift = Point::new(mx as f64 * sw, my as f64 * sh);
                    let at = |e: Point| {
                        let base = Point::new(
                            e.x + shift.x - self.origin.x,
                            e.y + shift.y - self.origin.y,
                        );
                        solve(&|t| {
                            let u = self.offset(t);
                            Point::new(base.x + u[0], base.y + u[1])
                        })
                    };
                    let (right, tr) = at(f.right_eye);
                    let (left, tl) = at(f.left_eye);
                    if hidden(right, tr) || hidden(left, tl) {
                        continue;
                    }
                    let v = self.velocity((tr + tl) / 2.0);
                    push(i, false, right, left, v);
                }
            }
        }
        // The walking subject.
        if let Some(s) = &self.sprite {
            if let Some(f) = self.scene.faces.get(s.face) {
                let at = |e: Point| {
                    solve(&|t| {
                        let c = self.sprite_center(s, t);
                        Point::new(c.x + e.x - s.source.x, c.y + e.y - s.source.y)
                    })
                };
                let (right, tr) = at(f.right_eye);
                let (left, tl) = at(f.left_eye);
                let t = (tr + tl) / 2.0;
                push(
                    s.face,
                    true,
                    right,
                    left,
                    [self.x.velocity(t), self.y.velocity(t)],
                );
            }
        }
        found
    }
}

#[cfg(test)]
mod tests;

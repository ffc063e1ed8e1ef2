//! Video: the shear of every frame of a clip, tracked faces, `k` filtered over time, frames
//! corrected in their own colour layout.
//!
//! ```text
//! y4m / frame folder ─▶ FrameSource ─▶ FaceTracker ─▶ Unshear::estimate_face ─▶ ShearSmoother
//!                                                                                    │ k
//!                 FrameSink ◀─ remove_shear_yuv / warp (Y, U, V planes) ◀────────────┘
//! ```
//!
//! * [`y4m`]: YUV4MPEG2 streams (files or pipes, e.g. `ffmpeg -f yuv4mpegpipe`), read with the
//!   `y4m` crate behind a header check that bounds the frame size before anything is allocated,
//!   written with the input's own header so that an unmodified stream round-trips byte for byte.
//! * [`frames`]: folders of numbered still images in and out.
//! * [`tracker`]: faces followed from frame to frame in a window around their last position, with
//!   a full (down-scaled) detection every N frames or when the track is lost.
//! * [`temporal`]: a constant-velocity Kalman filter on `k` with innovation gating, and a
//!   fixed-lag smoother over it (each frame's `k` from the frames after it too, at a latency of
//!   a few frames); without a face the filtered `k` is held, then decays to 0.
//! * [`process`]: all of the above per frame ([`VideoProcessor`], which holds frames back
//!   for the smoother's lag and flushes them at the end) and the threaded
//!   read → process → write loop ([`run`]).
//! * [`ffmpeg`]: what the `ffmpeg` and `ffprobe` programs are asked to do for containers (MP4,
//!   MOV, MKV, WebM): their command lines and the parsing of `ffprobe`'s JSON. The library
//!   starts no process; the `unshear video` command runs them.
//!
//! # Formats
//!
//! Supported y4m layouts: 8-bit `Cmono`, `C420`, `C420jpeg`, `C420mpeg2`, `C420paldv`, `C422`,
//! `C444` (a missing `C` tag means 4:2:0, as in FFmpeg), and high bit depth `C420p10`,
//! `C422p10`, `C444p10`, `C420p12`, `C422p12`, `C444p12`, `Cmono12` (little-endian 16-bit
//! samples, [`YuvFrame<u16>`], corrected and written at their own depth). **Not supported**
//! (refused with an error naming the tag): other depths (`C420p9`, `C420p16`, `Cmono10`...),
//! `C411`, `C444alpha`; interlaced material is processed as if progressive (the `I` tag is kept
//! but fields are not separated). Frame folders take every format [`crate::imageio`] reads.
//!
//! # Geometry of the correction
//!
//! The whole frame is de-sheared about its middle row `c = H / 2`, as for still images. A
//! chroma plane subsampled by `hs` horizontally and `vs` vertically holds, in its row `yc`,
//! samples taken at luma row `vs * yc + o` (`o = 0.5` for 4:2:0 with chroma between luma rows,
//! `0` for co-sited `paldv` and for 4:2:2 / 4:4:4), and a luma shift of `d` pixels is `d / hs`
//! chroma pixels. So the chroma plane is de-sheared with `k' = k vs / hs` about chroma row
//! `(c - o) / vs` (see [`chroma_shear`]); for 4:2:0 that is the same `k` about `(c - 0.5) / 2`.
//! Pixels shifted in from outside the frame get the plane's neutral value (black: 16 for
//! limited-range luma, 0 for full range; 128 for chroma; times `2^(depth - 8)` at higher bit
//! depths), not the 0 that still images get.

pub mod color;
pub mod ffmpeg;
pub mod frames;
pub mod process;
pub mod temporal;
pub mod tracker;
pub mod y4m;

pub use process::{
    run, FrameResult, FrameSink, FrameSource, KSource, ProcessOptions, RunStats, VideoProcessor,
};

use std::borrow::Cow;

use image::{DynamicImage, GrayImage, ImageBuffer, Luma};

use crate::warp::{self, Canvas, Interpolation};
use crate::{Error, Result, Shear};

/// How the colour of a YUV frame is laid out.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Chroma {
    /// Grey only (y4m `Cmono`): the U and V planes are empty.
    Mono,
    /// 4:2:0 with chroma rows between luma rows (`C420`, `C420jpeg`, `C420mpeg2`).
    Yuv420,
    /// 4:2:0 with chroma rows on the even luma rows (`C420paldv`, as FFmpeg reads it).
    Yuv420CoSited,
    /// 4:2:2: half the columns, every row.
    Yuv422,
    /// 4:4:4: no subsampling.
    Yuv444,
}

impl Chroma {
    /// Horizontal and vertical subsampling factors `(hs, vs)` (`(1, 1)` for mono).
    pub fn subsampling(self) -> (u32, u32) {
        match self {
            Chroma::Mono | Chroma::Yuv444 => (1, 1),
            Chroma::Yuv420 | Chroma::Yuv420CoSited => (2, 2),
            Chroma::Yuv422 => (2, 1),
        }
    }

    /// The size of each chroma plane for a `width` x `height` frame (`(0, 0)` for mono).
    /// Odd sizes round up, as in y4m.
    pub fn plane_size(self, width: u32, height: u32) -> (u32, u32) {
        if self == Chroma::Mono {
            return (0, 0);
        }
        let (hs, vs) = self.subsampling();
        (width.div_ceil(hs), height.div_ceil(vs))
    }

    /// The luma row (fraction) that chroma row 0 is sampled at.
    pub fn chroma_row_offset(self) -> f64 {
        match self {
            Chroma::Yuv420 => 0.5,
            _ => 0.0,
        }
    }
}

/// What a y4m header (or the frame folder's first image) says about every frame.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct VideoFormat {
    /// Luma width, pixels.
    pub width: u32,
    /// Luma height, pixels.
    pub height: u32,
    /// Colour layout.
    pub chroma: Chroma,
    /// Full-range samples (y4m `XCOLORRANGE=FULL`) rather than limited (16-235 luma).
    pub full_range: bool,
    /// Frames per second as a fraction `(numerator, denominator)`.
    pub frame_rate: (u32, u32),
    /// Bits per sample: 8, or 10 and 12 (stored in 16-bit samples, [`VideoFrame::Yuv16`]).
    pub bit_depth: u32,
}

impl VideoFormat {
    /// Frames per second (25 when the rate is degenerate, as FFmpeg assumes).
    pub fn fps(&self) -> f64 {
        let (n, d) = self.frame_rate;
        if n == 0 || d == 0 {
            25.0
        } else {
            f64::from(n) / f64::from(d)
        }
    }

    /// Bytes of one frame's samples (two bytes a sample above 8 bits).
    pub fn frame_bytes(&self) -> u64 {
        let (cw, ch) = self.chroma.plane_size(self.width, self.height);
        let samples =
            u64::from(self.width) * u64::from(self.height) + 2 * u64::from(cw) * u64::from(ch);
        samples * self.bytes_per_sample()
    }

    /// 1 for 8-bit samples, 2 above.
    pub fn bytes_per_sample(&self) -> u64 {
        if self.bit_depth > 8 {
            2
        } else {
            1
        }
    }
}

/// One plane of samples: [`GrayImage`] for 8-bit video, 16-bit samples above.
pub type Plane<T> = ImageBuffer<Luma<T>, Vec<T>>;

mod sealed {
    pub trait Sealed {}
    impl Sealed for u8 {}
    impl Sealed for u16 {}
}

/// The sample type of a [`YuvFrame`]: `u8` for 8-bit video, `u16` for 10 and 12 bits (values
/// in the low bits, as in y4m and FFmpeg's `p10le` formats).
pub trait YuvSample: image::Primitive + Send + Sync + sealed::Sealed + 'static {
    /// The sample of a value, rounded and clamped to `0..=max`.
    fn from_f64(v: f64, max: u32) -> Self;
    /// The value as `f64`.
    fn to_f64(self) -> f64;
    /// The plane as an image the warp takes (`Luma8` or `Luma16`), without copying.
    fn into_image(plane: Plane<Self>) -> DynamicImage;
    /// The plane back out of the warp's result.
    fn from_image(image: DynamicImage) -> Plane<Self>;
}

impl YuvSample for u8 {
    fn from_f64(v: f64, max: u32) -> Self {
        v.round().clamp(0.0, f64::from(max.min(255))) as u8
    }
    fn to_f64(self) -> f64 {
        f64::from(self)
    }
    fn into_image(plane: Plane<Self>) -> DynamicImage {
        DynamicImage::ImageLuma8(plane)
    }
    fn from_image(image: DynamicImage) -> Plane<Self> {
        match image {
            DynamicImage::ImageLuma8(g) => g,
            other => other.to_luma8(),
        }
    }
}

impl YuvSample for u16 {
    fn from_f64(v: f64, max: u32) -> Self {
        v.round().clamp(0.0, f64::from(max.min(65535))) as u16
    }
    fn to_f64(self) -> f64 {
        f64::from(self)
    }
    fn into_image(plane: Plane<Self>) -> DynamicImage {
        DynamicImage::ImageLuma16(plane)
    }
    fn from_image(image: DynamicImage) -> Plane<Self> {
        match image {
            DynamicImage::ImageLuma16(g) => g,
            other => other.to_luma16(),
        }
    }
}

/// One YUV frame: three planes (U and V empty for mono) and the y4m frame parameters. 8-bit
/// by default; `YuvFrame<u16>` holds 10- and 12-bit video.
#[derive(Debug, Clone, PartialEq)]
pub struct YuvFrame<T: YuvSample = u8> {
    /// Colour layout of the planes.
    pub chroma: Chroma,
    /// Whether samples are full range (decides the fill value of luma).
    pub full_range: bool,
    /// Bits per sample (8 for `u8` planes; 10 or 12 for `u16`): decides fill values and the
    /// largest value a correction may produce.
    pub bit_depth: u32,
    /// Luma.
    pub y: Plane<T>,
    /// Blue-difference chroma (Cb).
    pub u: Plane<T>,
    /// Red-difference chroma (Cr).
    pub v: Plane<T>,
    /// The text after `FRAME ` in a y4m stream, kept for the output.
    pub params: Option<Vec<u8>>,
}

impl<T: YuvSample> YuvFrame<T> {
    /// A frame of constant planes (black for the range, neutral chroma) at `format`'s bit
    /// depth.
    pub fn blank(format: &VideoFormat) -> Self {
        let (cw, ch) = format.chroma.plane_size(format.width, format.height);
        let depth = format.bit_depth;
        let max = max_value(depth);
        let black = T::from_f64(luma_black(format.full_range, depth), max);
        let neutral = T::from_f64(chroma_neutral(depth), max);
        Self {
            chroma: format.chroma,
            full_range: format.full_range,
            bit_depth: depth,
            y: Plane::from_pixel(format.width, format.height, Luma([black])),
            u: Plane::from_pixel(cw, ch, Luma([neutral])),
            v: Plane::from_pixel(cw, ch, Luma([neutral])),
            params: None,
        }
    }
}

impl YuvFrame<u16> {
    /// The luma plane reduced to 8 bits (rounded), for face detection and measurement.
    pub fn luma8(&self) -> GrayImage {
        let shift = self.bit_depth.saturating_sub(8).min(15);
        let half = if shift == 0 { 0 } else { 1u32 << (shift - 1) };
        let (w, h) = self.y.dimensions();
        let data = self
            .y
            .as_raw()
            .iter()
            .map(|&v| ((u32::from(v) + half) >> shift).min(255) as u8)
            .collect();
        GrayImage::from_raw(w, h, data).unwrap_or_else(|| GrayImage::new(w, h))
    }

    /// The frame reduced to 8 bits (rounded), e.g. to be written as images.
    pub fn to_8bit(&self) -> YuvFrame {
        let shift = self.bit_depth.saturating_sub(8).min(15);
        let half = if shift == 0 { 0 } else { 1u32 << (shift - 1) };
        let reduce = |p: &Plane<u16>| {
            let data = p
                .as_raw()
                .iter()
                .map(|&v| ((u32::from(v) + half) >> shift).min(255) as u8)
                .collect();
            GrayImage::from_raw(p.width(), p.height(), data)
                .unwrap_or_else(|| GrayImage::new(p.width(), p.height()))
        };
        YuvFrame {
            chroma: self.chroma,
            full_range: self.full_range,
            bit_depth: 8,
            y: reduce(&self.y),
            u: reduce(&self.u),
            v: reduce(&self.v),
            params: self.params.clone(),
        }
    }
}

/// A frame as it travels through the pipeline: YUV planes from y4m, or a decoded image from a
/// frame folder.
#[derive(Debug, Clone, PartialEq)]
pub enum VideoFrame {
    /// 8-bit planes from a y4m stream.
    Yuv(YuvFrame),
    /// 10- or 12-bit planes from a y4m stream, in 16-bit samples.
    Yuv16(YuvFrame<u16>),
    /// An image from a frame folder (any channel layout [`crate::imageio`] reads).
    Image(DynamicImage),
}

impl VideoFrame {
    /// Width and height of the (luma) picture.
    pub fn dimensions(&self) -> (u32, u32) {
        match self {
            VideoFrame::Yuv(f) => f.y.dimensions(),
            VideoFrame::Yuv16(f) => f.y.dimensions(),
            VideoFrame::Image(i) => (i.width(), i.height()),
        }
    }

    /// The grey picture that faces are detected and measured on: the Y plane itself for 8-bit
    /// YUV (borrowed, no copy), the Y plane rounded to 8 bits for deeper YUV, OpenCV's grey
    /// conversion for images.
    pub fn luma(&self) -> Cow<'_, GrayImage> {
        match self {
            VideoFrame::Yuv(f) => Cow::Borrowed(&f.y),
            VideoFrame::Yuv16(f) => Cow::Owned(f.luma8()),
            VideoFrame::Image(i) => Cow::Owned(crate::detect::to_gray_opencv(i)),
        }
    }

    /// De-shears the whole frame by `k` about its middle row (see the module docs for the
    /// chroma geometry); the size is kept.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when `k` is not finite.
    pub fn remove_shear(self, k: f64, interp: Interpolation) -> Result<VideoFrame> {
        match self {
            VideoFrame::Yuv(mut f) => {
                remove_shear_yuv(&mut f, k, interp)?;
                Ok(VideoFrame::Yuv(f))
            }
            VideoFrame::Yuv16(mut f) => {
                remove_shear_yuv(&mut f, k, interp)?;
                Ok(VideoFrame::Yuv16(f))
            }
            VideoFrame::Image(i) => {
                let shear = Shear::about_middle(k, i.height());
                Ok(VideoFrame::Image(
                    warp::try_remove_shear(&i, shear, interp, Canvas::Same)?.0,
                ))
            }
        }
    }
}

/// Luma of black: 0 in full range, 16 in limited range (scaled to the bit depth).
fn luma_black(full_range: bool, bit_depth: u32) -> f64 {
    if full_range {
        0.0
    } else {
        16.0 * depth_scale(bit_depth)
    }
}

/// Chroma of grey: 128 at 8 bits (scaled to the bit depth).
fn chroma_neutral(bit_depth: u32) -> f64 {
    128.0 * depth_scale(bit_depth)
}

/// `2^(depth - 8)`: how much larger a level is at `bit_depth` than at 8 bits.
fn depth_scale(bit_depth: u32) -> f64 {
    f64::from(1u32 << bit_depth.clamp(8, 16).saturating_sub(8))
}

/// The largest sample value at `bit_depth` (255 at 8 bits, 1023 at 10).
fn max_value(bit_depth: u32) -> u32 {
    (1u32 << bit_depth.clamp(1, 16)) - 1
}

/// The shear that a chroma plane of `chroma` needs so that it moves with a luma plane of
/// `height` rows sheared by `k` about its middle row (see the module docs).
pub fn chroma_shear(chroma: Chroma, k: f64, height: u32) -> Shear {
    let (hs, vs) = chroma.subsampling();
    let (hs, vs) = (f64::from(hs), f64::from(vs));
    let c = f64::from(height) / 2.0;
    Shear::new(k * vs / hs, (c - chroma.chroma_row_offset()) / vs)
}

/// De-shears every plane of `frame` in place by `k` (luma about `H / 2`, chroma by
/// [`chroma_shear`]); uncovered pixels become black luma and neutral chroma. Works at the
/// frame's own bit depth (16-bit planes are interpolated in `f32`, cubic overshoot clamped to
/// the depth's range).
///
/// # Errors
/// [`Error::InvalidArgument`] when `k` is not finite.
pub fn remove_shear_yuv<T: YuvSample>(
    frame: &mut YuvFrame<T>,
    k: f64,
    interp: Interpolation,
) -> Result<()> {
    if !k.is_finite() {
        return Err(Error::InvalidArgument(format!("shear {k} is not finite")));
    }
    if k == 0.0 {
        return Ok(());
    }
    let height = frame.y.height();
    let depth = frame.bit_depth;
    let luma = Shear::about_middle(k, height);
    let black = luma_black(frame.full_range, depth);
    frame.y = shift_plane(std::mem::take(&mut frame.y), luma, interp, black, depth)?;
    if frame.chroma != Chroma::Mono {
        let cs = chroma_shear(frame.chroma, k, height);
        let neutral = chroma_neutral(depth);
        frame.u = shift_plane(std::mem::take(&mut frame.u), cs, interp, neutral, depth)?;
        frame.v = shift_plane(std::mem::take(&mut frame.v), cs, interp, neutral, depth)?;
    }
    Ok(())
}

/// One plane through [`warp::try_remove_shear`] (the AVX2 path for 8 bits), then the uncovered
/// pixels, which the warp fills with 0, re-filled with `fill` with the same linear fade over the
/// edge pixel; above 8 bits, values past the depth's largest (cubic overshoot) are clamped.
fn shift_plane<T: YuvSample>(
    plane: Plane<T>,
    shear: Shear,
    interp: Interpolation,
    fill: f64,
    bit_depth: u32,
) -> Result<Plane<T>> {
    let (w, h) = plane.dimensions();
    if w == 0 || h == 0 {
        return Ok(plane);
    }
    // The refill needs only each row's first and last input pixel.
    let edges: Vec<(T, T)> = if fill != 0.0 {
        plane
            .as_raw()
            .chunks_exact(w as usize)
            .map(|r| (r[0], r[r.len() - 1]))
            .collect()
    } else {
        Vec::new()
    };
    let (out, _) = warp::try_remove_shear(&T::into_image(plane), shear, interp, Canvas::Same)?;
    let mut out = T::from_image(out);
    let max = max_value(bit_depth);
    if bit_depth > 8 && interp != Interpolation::Linear {
        let top = T::from_f64(f64::from(max), max);
        for p in out.iter_mut() {
            if *p > top {
                *p = top;
            }
        }
    }
    if fill != 0.0 {
        refill_edges(&edges, &mut out, shear, fill, max);
    }
    Ok(out)
}

/// Rewrites the output pixels of a de-sheared plane whose source position `x + k (y - c)` lies
/// outside the input (`edges`: each input row's first and last pixel). Written by hand because
/// the warp's fill value is fixed at 0; it touches only the pixels beyond the edges, with the
/// warp's linear fade over the edge pixel, and leaves the interior as the warp made it.
fn refill_edges<T: YuvSample>(
    edges: &[(T, T)],
    out: &mut Plane<T>,
    shear: Shear,
    fill: f64,
    max: u32,
) {
    let w = out.width() as usize;
    let last = (w - 1) as f64;
    for (y, (row_out, &(first, end))) in out.chunks_exact_mut(w).zip(edges).enumerate() {
        // Output x reads input position p = x + d.
        let d = shear.row_shift(y as f64);
        let (first, end) = (first.to_f64(), end.to_f64());
        // Left edge: p < 0.
        let left_end = (-d).ceil().clamp(0.0, w as f64) as usize;
        for (x, o) in row_out.iter_mut().enumerate().take(left_end) {
            let t = (x as f64 + d + 1.0).clamp(0.0, 1.0); // weight of the first pixel
            *o = T::from_f64(fill * (1.0 - t) + first * t, max);
        }
        // Right edge: p > w - 1.
        let right_start = ((last - d).floor() + 1.0).clamp(0.0, w as f64) as usize;
        for (x, o) in row_out
            .iter_mut()
            .enumerate()
            .skip(right_start.max(left_end))
        {
            let p = x as f64 + d;
            if p <= last {
                continue;
            }
            let t = (p - last).clamp(0.0, 1.0); // weight of the fill
            *o = T::from_f64(end * (1.0 - t) + fill * t, max);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::Luma;

    fn textured(w: u32, h: u32) -> GrayImage {
        GrayImage::from_fn(w, h, |x, y| {
            Luma([(128.0 + 90.0 * ((x as f64) / 7.0).sin() * ((y as f64) / 11.0).cos()) as u8])
        })
    }

    #[test]
    fn plane_sizes_round_up() {
        assert_eq!(Chroma::Yuv420.plane_size(5, 3), (3, 2));
        assert_eq!(Chroma::Yuv422.plane_size(5, 3), (3, 3));
        assert_eq!(Chroma::Yuv444.plane_size(5, 3), (5, 3));
        assert_eq!(Chroma::Mono.plane_size(5, 3), (0, 0));
        let f = VideoFormat {
            width: 5,
            height: 3,
            chroma: Chroma::Yuv420,
            full_range: false,
            frame_rate: (30000, 1001),
            bit_depth: 8,
        };
        assert_eq!(f.frame_bytes(), 15 + 2 * 6);
        assert!((f.fps() - 29.97).abs() < 0.01);
    }

    #[test]
    fn chroma_shear_moves_with_luma() {
        // 4:2:0: chroma row yc sits at luma row 2 yc + 0.5; its shift in chroma pixels must be
        // half the luma shift there.
        let (k, h) = (0.3, 240);
        let luma = Shear::about_middle(k, h);
        for chroma in [
            Chroma::Yuv420,
            Chroma::Yuv420CoSited,
            Chroma::Yuv422,
            Chroma::Yuv444,
        ] {
            let (hs, vs) = chroma.subsampling();
            let cs = chroma_shear(chroma, k, h);
            for yc in [0.0, 17.0, 59.0, 119.0] {
                let y = f64::from(vs) * yc + chroma.chroma_row_offset();
                let want = luma.row_shift(y) / f64::from(hs);
                assert!(
                    (cs.row_shift(yc) - want).abs() < 1e-12,
                    "{chroma:?} row {yc}"
                );
            }
        }
    }

    #[test]
    fn zero_shear_is_identity_and_nan_is_refused() {
        let format = VideoFormat {
            width: 16,
            height: 8,
            chroma: Chroma::Yuv420,
            full_range: false,
            frame_rate: (25, 1),
            bit_depth: 8,
        };
        let mut f = YuvFrame::blank(&format);
        f.y = textured(16, 8);
        let before = f.clone();
        remove_shear_yuv(&mut f, 0.0, Interpolation::Linear).expect("k = 0");
        assert_eq!(f, before);
        assert!(remove_shear_yuv(&mut f, f64::NAN, Interpolation::Linear).is_err());
    }

    #[test]
    fn uncovered_pixels_get_the_neutral_value() {
        let format = VideoFormat {
            width: 40,
            height: 40,
            chroma: Chroma::Yuv420,
            full_range: false,
            frame_rate: (25, 1),
            bit_depth: 8,
        };
        let mut f = YuvFrame::blank(&format);
        f.y = GrayImage::from_pixel(40, 40, Luma([200]));
        f.u = GrayImage::from_pixel(20, 20, Luma([60]));
        remove_shear_yuv(&mut f, 0.5, Interpolation::Linear).expect("finite k");
        // Top row: output x reads input x + 0.5 (0 - 20) = x - 10: the first 9 columns are
        // uncovered (x = 9 is the half-covered fade pixel), the rest inside.
        let row0: Vec<u8> = (0..40).map(|x| f.y.get_pixel(x, 0)[0]).collect();
        assert!(row0[..9].iter().all(|&v| v == 16), "{row0:?}");
        assert!(row0[10..].iter().all(|&v| v == 200), "{row0:?}");
        // Bottom row reads x + 9.5: the last 9 columns uncovered, one faded.
        let row39: Vec<u8> = (0..40).map(|x| f.y.get_pixel(x, 39)[0]).collect();
        assert!(row39[31..].iter().all(|&v| v == 16), "{row39:?}");
        assert_eq!(row39[30], 108, "half of 200 and half of 16");
        assert!(row39[..30].iter().all(|&v| v == 200), "{row39:?}");
        // Chroma: neutral fill, never 0.
        assert!(f
            .u
            .pixels()
            .all(|p| p[0] == 60 || p[0] >= 60 && p[0] <= 128));
        assert_eq!(f.u.get_pixel(0, 0)[0], 128);
        assert_eq!(f.v.get_pixel(0, 0)[0], 128);
    }

    #[test]
    fn subsampled_chroma_matches_subsampling_the_corrected_full_plane() {
        // Correcting a 4:4:4 plane and then averaging 2x2 blocks (which samples at luma rows
        // 2 yc + 0.5) must agree with correcting the averaged 4:2:0 plane, away from the edges.
        let (w, h, k) = (96u32, 64u32, 0.25);
        let full = textured(w, h);
        let average = |g: &GrayImage| {
            GrayImage::from_fn(w / 2, h / 2, |x, y| {
                let s: u32 = [(0, 0), (1, 0), (0, 1), (1, 1)]
                    .iter()
                    .map(|(dx, dy)| u32::from(g.get_pixel(2 * x + dx, 2 * y + dy)[0]))
                    .sum();
                Luma([((s + 2) / 4) as u8])
            })
        };
        let format = VideoFormat {
            width: w,
            height: h,
            chroma: Chroma::Yuv444,
            full_range: true,
            frame_rate: (25, 1),
            bit_depth: 8,
        };
        let mut f444 = YuvFrame::blank(&format);
        f444.u = full.clone();
        remove_shear_yuv(&mut f444, k, Interpolation::Cubic).expect("finite");
        let mut f420 = YuvFrame::blank(&VideoFormat {
            chroma: Chroma::Yuv420,
            ..format
        });
        f420.u = average(&full);
        remove_shear_yuv(&mut f420, k, Interpolation::Cubic).expect("finite");
        let want = average(&f444.u);
        let mut worst = 0i32;
        for y in 0..h / 2 {
            for x in 12..w / 2 - 12 {
                let d = i32::from(want.get_pixel(x, y)[0]) - i32::from(f420.u.get_pixel(x, y)[0]);
                worst = worst.max(d.abs());
            }
        }
        // Resampling before or after averaging differs by interpolation error only (measured:
        // 1 level); a chroma shear of k / 2, forgetting that the rows are subsampled too, gave
        // 50. (A pivot off by the half-row siting moves chroma by only k / 8 pixel here; the
        // exact formula is checked in `chroma_shear_moves_with_luma`.)
        assert!(worst <= 3, "worst difference {worst}");
    }

    #[test]
    fn ten_bit_planes_are_corrected_at_their_depth() {
        // A 10-bit frame whose values are the 8-bit frame's times 4: the correction must be the
        // 8-bit one times 4 (to within the 8-bit path's rounding), fill with 64 / 512, and stay
        // within 0..=1023 with cubic interpolation's overshoot.
        let format = VideoFormat {
            width: 48,
            height: 32,
            chroma: Chroma::Yuv420,
            full_range: false,
            frame_rate: (25, 1),
            bit_depth: 10,
        };
        let mut f8 = YuvFrame::blank(&VideoFormat {
            bit_depth: 8,
            ..format.clone()
        });
        f8.y = GrayImage::from_fn(48, 32, |x, _| Luma([if x % 8 < 4 { 16 } else { 235 }]));
        let mut f10: YuvFrame<u16> = YuvFrame::blank(&format);
        assert_eq!(
            (f10.y.get_pixel(0, 0)[0], f10.u.get_pixel(0, 0)[0]),
            (64, 512)
        );
        f10.y = Plane::from_fn(48, 32, |x, y| {
            Luma([u16::from(f8.y.get_pixel(x, y)[0]) * 4])
        });
        for interp in [Interpolation::Linear, Interpolation::Cubic] {
            let (mut a, mut b) = (f8.clone(), f10.clone());
            remove_shear_yuv(&mut a, 0.37, interp).expect("finite");
            remove_shear_yuv(&mut b, 0.37, interp).expect("finite");
            let mut worst = 0i32;
            for (p8, p10) in a.y.pixels().zip(b.y.pixels()) {
                assert!(p10[0] <= 1023);
                worst = worst.max((i32::from(p8[0]) * 4 - i32::from(p10[0])).abs());
            }
            assert!(worst <= 4, "{interp:?}: worst {worst}");
            // Uncovered corners: limited-range black and neutral chroma at 10 bits.
            assert_eq!(b.y.get_pixel(0, 0)[0], 64);
            assert_eq!(b.u.get_pixel(0, 0)[0], 512);
            assert_eq!(b.luma8().get_pixel(47, 0)[0], a.y.get_pixel(47, 0)[0]);
        }
    }
}

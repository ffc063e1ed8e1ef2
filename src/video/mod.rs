//! Video: the shear of every frame of a clip from the image motion between frames times the
//! sensor's line time (the readout calibrated from the faces), or from tracked faces filtered
//! over time; frames corrected row by row in their own colour layout.
//!
//! ```text
//!                               ┌▶ MotionEstimator (bands) ─▶ VelocitySpline ─▶ RowMotion ─┐ k, row offsets
//! y4m / frame folder ─▶ FrameSource                                  ▲ rho                    │
//!                               └▶ FaceTracker ─▶ Unshear::estimate_face ─▶ ReadoutCalibrator   │
//!                                                          └──────────▶ ShearSmoother ───────┤ k (faces)
//!                 FrameSink ◀─ shift_rows / remove_shear_yuv (Y, U, V planes) ◀───────────────┘
//! ```
//!
//! * [`y4m`]: YUV4MPEG2 streams (files or pipes, e.g. `ffmpeg -f yuv4mpegpipe`), read with the
//!   `y4m` crate behind a header check that bounds the frame size before anything is allocated,
//!   written with the input's own header so that an unmodified stream round-trips byte for byte.
//! * [`frames`]: folders of numbered still images in and out.
//! * `motion`: the content's displacement between consecutive frames, band of rows by band of
//!   rows (phase correlation, then robust least squares), with an uncertainty.
//! * `readout`: the rolling-shutter model: the velocity through a frame's readout fitted to the
//!   bands, each row's offset, and the readout fraction calibrated from the faces.
//! * `tracker`: faces followed from frame to frame in a window around their last position, with
//!   a full (down-scaled) detection every N frames or when the track is lost.
//! * `temporal`: a constant-velocity Kalman filter on `k` with innovation gating, and a
//!   fixed-lag smoother over it (each frame's `k` from the frames after it too, at a latency of
//!   a few frames); without a face the filtered `k` is held, then decays to 0.
//! * `process`: all of the above per frame ([`VideoProcessor`], which holds frames back
//!   for the smoother's lag or the readout's calibration and flushes them at the end) and the
//!   threaded read → process → write loop ([`run`]).
//!
//! Containers (MP4, MOV, MKV, WebM) go through the `ffmpeg` and `ffprobe` programs as y4m pipes;
//! the command-line tool (the `unshear-cli` crate) runs them, and the library starts no process.
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
//!
//! The same siting carries an offset per row ([`shift_rows_yuv`], a pan whose speed changes
//! during the readout) and a vertical resampling ([`resample_rows_yuv`], vertical motion during
//! the readout) to the chroma planes: chroma row `yc` takes the luma table's value at luma
//! position `vs * yc + o`, read linearly between luma rows; a shift is divided by `hs`, a
//! source row `s` becomes chroma row `(s - o) / vs`.

pub(crate) mod anchors;
pub mod color;
pub mod frames;
pub(crate) mod motion;
pub(crate) mod process;
pub(crate) mod readout;
pub(crate) mod temporal;
pub(crate) mod timing;
pub(crate) mod tracker;
pub mod y4m;

pub use motion::MotionParams;
pub use process::{
    analyse, replay, run, Deblur, FrameResult, FrameSink, FrameSource, KSource, ProcessOptions,
    RunStats, ShearSource, SourceCounts, VideoProcessor, DEFAULT_CALIBRATION_WINDOW,
};
pub use readout::{check_readout_fraction, Calibration, CalibrationParams, MAX_READOUT_FRACTION};
pub use temporal::{FilterParams, Update, DEFAULT_SMOOTHING_LAG};
pub use tracker::{TrackerParams, TrackerStats};

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

    /// Shifts every row by its own amount, `out(x, y) = in(x + shifts[y], y)` with `shifts` per
    /// (luma) row in (luma) pixels: the correction of a pan whose speed changes during the
    /// readout. YUV frames go through [`shift_rows_yuv`], images through
    /// `warp::try_shift_rows`; the size is kept.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when `shifts.len()` is not the height or a shift is not
    /// finite.
    pub fn shift_rows(self, shifts: &[f64], interp: Interpolation) -> Result<VideoFrame> {
        match self {
            VideoFrame::Yuv(mut f) => {
                shift_rows_yuv(&mut f, shifts, interp)?;
                Ok(VideoFrame::Yuv(f))
            }
            VideoFrame::Yuv16(mut f) => {
                shift_rows_yuv(&mut f, shifts, interp)?;
                Ok(VideoFrame::Yuv16(f))
            }
            VideoFrame::Image(i) => {
                Ok(VideoFrame::Image(warp::try_shift_rows(&i, shifts, interp)?))
            }
        }
    }

    /// Resamples the rows vertically, `out(x, y) = in(x, sources[y])` with `sources` per (luma)
    /// row in (luma) rows: the correction of a vertical stretch or squeeze. YUV frames go
    /// through [`resample_rows_yuv`], images through [`warp::try_resample_rows`]; the size is
    /// kept.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when `sources.len()` is not the height or a source is not
    /// finite.
    pub fn resample_rows(self, sources: &[f64]) -> Result<VideoFrame> {
        match self {
            VideoFrame::Yuv(mut f) => {
                resample_rows_yuv(&mut f, sources)?;
                Ok(VideoFrame::Yuv(f))
            }
            VideoFrame::Yuv16(mut f) => {
                resample_rows_yuv(&mut f, sources)?;
                Ok(VideoFrame::Yuv16(f))
            }
            VideoFrame::Image(i) => Ok(VideoFrame::Image(warp::try_resample_rows(&i, sources)?)),
        }
    }
}

impl VideoFrame {
    /// Removes a horizontal motion blur of `lengths[y]` pixels from each (luma) row
    /// ([`crate::deblur::deblur_rows`], Wiener filter with `noise_to_signal`); chroma planes
    /// take their rows' lengths over their horizontal subsampling. Floating-point images are
    /// returned as they are.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when `lengths.len()` is not the height, a length is not
    /// finite or `noise_to_signal` is not positive.
    pub fn deblur_rows(self, lengths: &[f64], noise_to_signal: f64) -> Result<VideoFrame> {
        use crate::deblur::deblur_rows as rows;
        warp::check_rows(lengths, self.dimensions().1, "blur length")?;
        let nsr = noise_to_signal;
        fn planes<T: YuvSample + crate::deblur::Sample>(
            f: &mut YuvFrame<T>,
            lengths: &[f64],
            nsr: f64,
        ) -> Result<()> {
            let max = ((1u32 << f.bit_depth) - 1) as f32;
            let w = f.y.width() as usize;
            rows(&mut f.y, w, 1, lengths, nsr, max)?;
            if f.chroma != Chroma::Mono {
                let hs = f64::from(f.chroma.subsampling().0);
                let cl = chroma_rows(f.chroma, f.u.height(), lengths, |l| l / hs);
                let cw = f.u.width() as usize;
                rows(&mut f.u, cw, 1, &cl, nsr, max)?;
                rows(&mut f.v, cw, 1, &cl, nsr, max)?;
            }
            Ok(())
        }
        Ok(match self {
            VideoFrame::Yuv(mut f) => {
                planes(&mut f, lengths, nsr)?;
                VideoFrame::Yuv(f)
            }
            VideoFrame::Yuv16(mut f) => {
                planes(&mut f, lengths, nsr)?;
                VideoFrame::Yuv16(f)
            }
            VideoFrame::Image(mut img) => {
                crate::deblur::deblur_image(&mut img, lengths, nsr)?;
                VideoFrame::Image(img)
            }
        })
    }

    /// De-shears each face region by its own shear, the rest untouched (a subject moving in
    /// front of a still camera): `regions` holds each region (in luma pixels, already enlarged)
    /// and its `k`, undone about the region's middle row and feathered into its surroundings as
    /// `warp::remove_shear_in_region` does; chroma planes follow with their subsampling.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when a `k` is not finite.
    pub fn remove_shear_in_regions(
        self,
        regions: &[(crate::Rect, f64)],
        interp: Interpolation,
    ) -> Result<VideoFrame> {
        if let Some((_, k)) = regions.iter().find(|(_, k)| !k.is_finite()) {
            return Err(Error::InvalidArgument(format!("shear {k} is not finite")));
        }
        Ok(match self {
            VideoFrame::Image(mut img) => {
                for &(region, k) in regions {
                    let shear = Shear::new(k, region.center().y);
                    img = warp::remove_shear_in_region(&img, shear, region, interp);
                }
                VideoFrame::Image(img)
            }
            VideoFrame::Yuv(mut f) => {
                regions_yuv(&mut f, regions, interp);
                VideoFrame::Yuv(f)
            }
            VideoFrame::Yuv16(mut f) => {
                regions_yuv(&mut f, regions, interp);
                VideoFrame::Yuv16(f)
            }
        })
    }
}

/// [`VideoFrame::remove_shear_in_regions`] on each plane of a YUV frame: a chroma plane
/// subsampled by `(hs, vs)` takes the region scaled to its samples and `k vs / hs` about the
/// chroma row of the region's middle (as [`chroma_shear`] does for the whole frame).
fn regions_yuv<T: YuvSample>(
    frame: &mut YuvFrame<T>,
    regions: &[(crate::Rect, f64)],
    interp: Interpolation,
) {
    let (hs, vs) = frame.chroma.subsampling();
    let (hs, vs) = (f64::from(hs), f64::from(vs));
    let o = frame.chroma.chroma_row_offset();
    let warp_plane = |plane: Plane<T>, region: crate::Rect, shear: Shear| {
        let img = warp::remove_shear_in_region(&T::into_image(plane), shear, region, interp);
        T::from_image(img)
    };
    for &(region, k) in regions {
        let pivot = region.center().y;
        frame.y = warp_plane(std::mem::take(&mut frame.y), region, Shear::new(k, pivot));
        if frame.chroma == Chroma::Mono {
            continue;
        }
        let chroma_region = crate::Rect::new(
            region.x / hs,
            (region.y - o) / vs,
            region.width / hs,
            region.height / vs,
        );
        let shear = Shear::new(k * vs / hs, (pivot - o) / vs);
        frame.u = warp_plane(std::mem::take(&mut frame.u), chroma_region, shear);
        frame.v = warp_plane(std::mem::take(&mut frame.v), chroma_region, shear);
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
    let luma = RowOffsets::Shear(luma);
    frame.y = shift_plane(std::mem::take(&mut frame.y), luma, interp, black, depth)?;
    if frame.chroma != Chroma::Mono {
        let cs = RowOffsets::Shear(chroma_shear(frame.chroma, k, height));
        let neutral = chroma_neutral(depth);
        frame.u = shift_plane(std::mem::take(&mut frame.u), cs, interp, neutral, depth)?;
        frame.v = shift_plane(std::mem::take(&mut frame.v), cs, interp, neutral, depth)?;
    }
    Ok(())
}

/// Shifts every row of `frame` in place by its own amount: `out(x, y) = in(x + shifts[y], y)`,
/// `shifts` per luma row in luma pixels (the general form of [`remove_shear_yuv`], which is
/// this with `shifts[y] = k * (y - H / 2)`: a pan that changes speed during the readout offsets
/// the rows along a curve).
///
/// A chroma row `yc` is sampled at luma row `p = vs * yc + o` (see the module docs), so it is
/// shifted by the luma shift at `p` (linear between the two luma rows around it; odd-height
/// 4:2:0 reaches half a row past the last one, where the last two rows' line is extended)
/// divided by `hs`. Uncovered pixels become black luma and neutral chroma with the same fade
/// as [`remove_shear_yuv`]; the frame's own bit depth is kept.
///
/// # Errors
/// [`Error::InvalidArgument`] when `shifts.len()` is not the luma height or a shift is not
/// finite.
pub fn shift_rows_yuv<T: YuvSample>(
    frame: &mut YuvFrame<T>,
    shifts: &[f64],
    interp: Interpolation,
) -> Result<()> {
    warp::check_rows(shifts, frame.y.height(), "row shift")?;
    if shifts.iter().all(|&s| s == 0.0) {
        return Ok(());
    }
    let depth = frame.bit_depth;
    let black = luma_black(frame.full_range, depth);
    let luma = RowOffsets::Table(shifts);
    frame.y = shift_plane(std::mem::take(&mut frame.y), luma, interp, black, depth)?;
    if frame.chroma != Chroma::Mono {
        let hs = f64::from(frame.chroma.subsampling().0);
        let rows = chroma_rows(frame.chroma, frame.u.height(), shifts, |s| s / hs);
        let cs = RowOffsets::Table(&rows);
        let neutral = chroma_neutral(depth);
        frame.u = shift_plane(std::mem::take(&mut frame.u), cs, interp, neutral, depth)?;
        frame.v = shift_plane(std::mem::take(&mut frame.v), cs, interp, neutral, depth)?;
    }
    Ok(())
}

/// Resamples the rows of `frame` in place vertically: `out(x, y) = in(x, sources[y])`,
/// `sources` per luma row in luma rows (the correction of a vertical stretch or squeeze). See
/// [`warp::try_resample_rows`]: linear between the two nearest rows, integer sources copy.
///
/// A chroma row `yc` sits at luma position `p = vs * yc + o`; it takes the luma source there,
/// `s(p)` (linear between luma rows, extended past the last one as in [`shift_rows_yuv`]), which
/// is chroma row `(s(p) - o) / vs`. Rows from outside the frame become black luma and neutral
/// chroma, fading over one row.
///
/// # Errors
/// [`Error::InvalidArgument`] when `sources.len()` is not the luma height or a source is not
/// finite.
pub fn resample_rows_yuv<T: YuvSample>(frame: &mut YuvFrame<T>, sources: &[f64]) -> Result<()> {
    warp::check_rows(sources, frame.y.height(), "source row")?;
    if sources.iter().enumerate().all(|(y, &s)| s == y as f64) {
        return Ok(());
    }
    let depth = frame.bit_depth;
    let black = luma_black(frame.full_range, depth);
    frame.y = resample_plane(std::mem::take(&mut frame.y), sources, black)?;
    if frame.chroma != Chroma::Mono {
        let vs = f64::from(frame.chroma.subsampling().1);
        let o = frame.chroma.chroma_row_offset();
        let rows = chroma_rows(frame.chroma, frame.u.height(), sources, |s| (s - o) / vs);
        let neutral = chroma_neutral(depth);
        frame.u = resample_plane(std::mem::take(&mut frame.u), &rows, neutral)?;
        frame.v = resample_plane(std::mem::take(&mut frame.v), &rows, neutral)?;
    }
    Ok(())
}

/// A per-luma-row table carried to the `chroma_height` rows of a chroma plane: chroma row `yc`
/// gets `map(table(p))` at its luma position `p = vs * yc + o`, the table read linearly
/// between rows (and along the last two rows' line past the end).
fn chroma_rows(
    chroma: Chroma,
    chroma_height: u32,
    table: &[f64],
    map: impl Fn(f64) -> f64,
) -> Vec<f64> {
    let vs = f64::from(chroma.subsampling().1);
    let o = chroma.chroma_row_offset();
    (0..chroma_height)
        .map(|yc| {
            let p = vs * f64::from(yc) + o;
            map(table_at(table, p))
        })
        .collect()
}

/// `table` (one value per row, not empty) read at row `p >= 0`: linear between the rows
/// around `p`, an exact copy at whole rows, and along the last two rows' line beyond the last.
fn table_at(table: &[f64], p: f64) -> f64 {
    let last = table.len() - 1;
    if last == 0 {
        return table[0];
    }
    let i = (p.floor().max(0.0) as usize).min(last - 1);
    let t = p - i as f64;
    if t == 0.0 {
        return table[i];
    }
    let (a, b) = (table[i], table[i + 1]);
    a + t * (b - a)
}

/// Where each output row of a plane reads: `out(x, y) = in(x + d(y), y)`.
#[derive(Clone, Copy)]
enum RowOffsets<'a> {
    /// `d(y) = shear.row_shift(y)`, what [`warp::try_remove_shear`] reads.
    Shear(Shear),
    /// `d(y) = table[y]`, what [`warp::try_shift_rows`] reads.
    Table(&'a [f64]),
}

impl RowOffsets<'_> {
    fn at(&self, y: usize) -> f64 {
        match *self {
            RowOffsets::Shear(shear) => shear.row_shift(y as f64),
            RowOffsets::Table(table) => table[y],
        }
    }
}

/// One plane through [`warp::resample_rows_filled`], rows from outside filled with `fill`.
fn resample_plane<T: YuvSample>(plane: Plane<T>, sources: &[f64], fill: f64) -> Result<Plane<T>> {
    if plane.width() == 0 || plane.height() == 0 {
        return Ok(plane);
    }
    let out = warp::resample_rows_filled(&T::into_image(plane), sources, fill)?;
    Ok(T::from_image(out))
}

/// One plane through [`warp::try_remove_shear`] or [`warp::try_shift_rows`] (the AVX2 path for
/// 8 bits), then the uncovered pixels, which the warp fills with 0, re-filled with `fill` with
/// the same linear fade over the edge pixel; above 8 bits, values past the depth's largest
/// (cubic overshoot) are clamped.
fn shift_plane<T: YuvSample>(
    plane: Plane<T>,
    rows: RowOffsets<'_>,
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
    let image = T::into_image(plane);
    let out = match rows {
        RowOffsets::Shear(shear) => warp::try_remove_shear(&image, shear, interp, Canvas::Same)?.0,
        RowOffsets::Table(table) => warp::try_shift_rows(&image, table, interp)?,
    };
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
        refill_edges(&edges, &mut out, rows, fill, max);
    }
    Ok(out)
}

/// Rewrites the output pixels of a row-shifted plane whose source position `x + d(y)` lies
/// outside the input (`edges`: each input row's first and last pixel). Written by hand because
/// the warp's fill value is fixed at 0; it touches only the pixels beyond the edges, with the
/// warp's linear fade over the edge pixel, and leaves the interior as the warp made it.
fn refill_edges<T: YuvSample>(
    edges: &[(T, T)],
    out: &mut Plane<T>,
    rows: RowOffsets<'_>,
    fill: f64,
    max: u32,
) {
    let w = out.width() as usize;
    let last = (w - 1) as f64;
    for (y, (row_out, &(first, end))) in out.chunks_exact_mut(w).zip(edges).enumerate() {
        // Output x reads input position p = x + d.
        let d = rows.at(y);
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
    const LAYOUTS: [Chroma; 5] = [
        Chroma::Yuv420,
        Chroma::Yuv420CoSited,
        Chroma::Yuv422,
        Chroma::Yuv444,
        Chroma::Mono,
    ];

    fn format(w: u32, h: u32, chroma: Chroma, bit_depth: u32) -> VideoFormat {
        VideoFormat {
            width: w,
            height: h,
            chroma,
            full_range: false,
            frame_rate: (25, 1),
            bit_depth,
        }
    }

    /// A frame with different smooth texture in each plane, at 8 bits or (values times 4) at
    /// 10 bits.
    fn textured_frame<T: YuvSample>(w: u32, h: u32, chroma: Chroma, depth: u32) -> YuvFrame<T> {
        let mut f = YuvFrame::<T>::blank(&format(w, h, chroma, depth));
        let scale = depth_scale(depth);
        let fill = |p: &mut Plane<T>, phase: f64| {
            let (pw, ph) = p.dimensions();
            *p = Plane::from_fn(pw, ph, |x, y| {
                let (x, y) = (f64::from(x), f64::from(y));
                let v = 128.0 + 90.0 * (x / 5.0 + phase).sin() * (y / 7.0 - phase).cos();
                Luma([T::from_f64(v * scale, max_value(depth))])
            })
        };
        fill(&mut f.y, 0.0);
        fill(&mut f.u, 1.0);
        fill(&mut f.v, 2.0);
        f
    }

    fn ramp(k: f64, h: u32) -> Vec<f64> {
        let c = f64::from(h) / 2.0;
        (0..h).map(|y| k * (f64::from(y) - c)).collect()
    }

    #[test]
    fn a_ramp_of_row_shifts_is_remove_shear_bit_for_bit() {
        // remove_shear_yuv reads in(x + k (y - H / 2)) in luma (Shear::about_middle) and the
        // chroma_shear of it in chroma; shift_rows_yuv with the ramp must give the same planes,
        // in every layout, odd sizes included.
        for chroma in LAYOUTS {
            for (w, h) in [(48u32, 32u32), (47, 31)] {
                for k in [0.3, -0.137, 0.2113, -1.0] {
                    for interp in [Interpolation::Linear, Interpolation::Cubic] {
                        let f8: YuvFrame = textured_frame(w, h, chroma, 8);
                        let (mut a, mut b) = (f8.clone(), f8);
                        remove_shear_yuv(&mut a, k, interp).expect("finite");
                        shift_rows_yuv(&mut b, &ramp(k, h), interp).expect("finite");
                        assert!(a == b, "8-bit {chroma:?} {w}x{h} k={k} {interp:?}");
                        let f10: YuvFrame<u16> = textured_frame(w, h, chroma, 10);
                        let (mut a, mut b) = (f10.clone(), f10);
                        remove_shear_yuv(&mut a, k, interp).expect("finite");
                        shift_rows_yuv(&mut b, &ramp(k, h), interp).expect("finite");
                        assert!(a == b, "10-bit {chroma:?} {w}x{h} k={k} {interp:?}");
                    }
                }
            }
        }
    }

    /// The centroid of a bright vertical line in row `y` of `plane`, near column `around`.
    fn line_column<T: YuvSample>(plane: &Plane<T>, y: u32, around: f64, base: f64) -> f64 {
        let c = around.round() as i64;
        let (mut m0, mut m1) = (0.0, 0.0);
        for x in (c - 8).max(0)..=(c + 8).min(i64::from(plane.width()) - 1) {
            let v = plane.get_pixel(x as u32, y)[0].to_f64() - base;
            m0 += v;
            m1 += v * x as f64;
        }
        m1 / m0
    }

    #[test]
    fn curved_shifts_move_luma_and_chroma_lines_together() {
        // A vertical line (Gaussian, sigma 2 luma px) at x0 in every plane (x0 / hs in chroma);
        // a parabolic shift. Luma row y must put it at x0 - s(y); chroma row yc at
        // (x0 - s(p)) / hs with p = vs yc + o its luma position. Measured: < 0.02 px;
        // asserted < 0.05 (in each plane's own pixels).
        let (w, h, x0) = (160u32, 64u32, 80.4);
        let s = |y: f64| {
            let t = y / f64::from(h - 1);
            -15.0 + 40.0 * t - 28.0 * t * t
        };
        let shifts: Vec<f64> = (0..h).map(|y| s(f64::from(y))).collect();
        for chroma in LAYOUTS {
            for depth in [8, 10] {
                let (hs, vs) = chroma.subsampling();
                let (hs, vs) = (f64::from(hs), f64::from(vs));
                let scale = depth_scale(depth);
                let max = max_value(depth);
                let mut f: YuvFrame<u16> = YuvFrame::blank(&format(w, h, chroma, depth));
                let line = |p: &mut Plane<u16>, xc: f64, sigma: f64| {
                    for (x, _, v) in p.enumerate_pixels_mut() {
                        let d = (f64::from(x) - xc) / sigma;
                        v[0] = u16::from_f64((16.0 + 200.0 * (-0.5 * d * d).exp()) * scale, max);
                    }
                };
                line(&mut f.y, x0, 2.0);
                line(&mut f.u, x0 / hs, 2.0 / hs);
                shift_rows_yuv(&mut f, &shifts, Interpolation::Cubic).expect("finite");
                let base = 16.0 * scale;
                for y in 0..h {
                    let want = x0 - shifts[y as usize];
                    let got = line_column(&f.y, y, want, base);
                    assert!((got - want).abs() < 0.05, "{chroma:?} luma row {y}: {got}");
                }
                for yc in 0..f.u.height() {
                    let p = vs * f64::from(yc) + chroma.chroma_row_offset();
                    let want = (x0 - s(p)) / hs;
                    let got = line_column(&f.u, yc, want, base);
                    assert!(
                        (got - want).abs() < 0.05,
                        "{chroma:?} {depth}-bit chroma row {yc}: {got} vs {want}"
                    );
                }
            }
        }
    }

    #[test]
    fn shifted_rows_fill_with_black_and_neutral() {
        // Every row reads x + 10.5: the last 10 columns are uncovered, column W - 11 is the
        // half-covered fade pixel; chroma (4:2:0) reads x + 5.25.
        for depth in [8, 10] {
            let scale = depth_scale(depth);
            let mut f: YuvFrame<u16> = YuvFrame::blank(&format(40, 8, Chroma::Yuv420, depth));
            f.y = Plane::from_pixel(40, 8, Luma([(200.0 * scale) as u16]));
            f.u = Plane::from_pixel(20, 4, Luma([(60.0 * scale) as u16]));
            shift_rows_yuv(&mut f, &[10.5; 8], Interpolation::Linear).expect("finite");
            let row: Vec<f64> = (0..40).map(|x| f64::from(f.y.get_pixel(x, 3)[0])).collect();
            assert!(row[..29].iter().all(|&v| v == 200.0 * scale), "{row:?}");
            assert_eq!(row[29], 108.0 * scale, "half of 200 and half of 16");
            assert!(row[30..].iter().all(|&v| v == 16.0 * scale), "{row:?}");
            let row: Vec<f64> = (0..20).map(|x| f64::from(f.u.get_pixel(x, 1)[0])).collect();
            // x + 5.25 > 19 from x = 14 (fade: 3/4 of 60 + 1/4 of 128 = 77), 128 from x = 15.
            assert!(row[..14].iter().all(|&v| v == 60.0 * scale), "{row:?}");
            assert_eq!(row[14], 77.0 * scale);
            assert!(row[15..].iter().all(|&v| v == 128.0 * scale), "{row:?}");
            assert_eq!(f.v.get_pixel(19, 0)[0], (128.0 * scale) as u16);
        }
    }

    #[test]
    fn bad_tables_are_refused_and_zero_is_the_identity() {
        for chroma in LAYOUTS {
            let mut f: YuvFrame = textured_frame(16, 8, chroma, 8);
            let before = f.clone();
            shift_rows_yuv(&mut f, &[0.0; 8], Interpolation::Cubic).expect("zero");
            let rows: Vec<f64> = (0..8).map(f64::from).collect();
            resample_rows_yuv(&mut f, &rows).expect("identity");
            assert_eq!(f, before);
            let mut nan = [0.0; 8];
            nan[2] = f64::NAN;
            for bad in [&[0.0; 7][..], &[0.0; 9], &nan, &[f64::INFINITY; 8]] {
                assert!(shift_rows_yuv(&mut f, bad, Interpolation::Linear).is_err());
                assert!(resample_rows_yuv(&mut f, bad).is_err());
                let frame = VideoFrame::Yuv(f.clone());
                assert!(frame
                    .clone()
                    .shift_rows(bad, Interpolation::Linear)
                    .is_err());
                assert!(frame.resample_rows(bad).is_err());
            }
            assert_eq!(f, before, "a refused table leaves the frame alone");
        }
    }

    #[test]
    fn integer_sources_move_whole_rows_and_fill_with_black_and_neutral() {
        // Luma row y takes row y + 4; a 4:2:0 chroma row yc (luma 2 yc + 0.5) takes luma
        // source 2 yc + 4.5, chroma row yc + 2; 4:2:2 chroma row yc takes yc + 4.
        for chroma in LAYOUTS {
            let f: YuvFrame<u16> = textured_frame(20, 16, chroma, 10);
            let mut g = f.clone();
            let sources: Vec<f64> = (0..16).map(|y| f64::from(y) + 4.0).collect();
            resample_rows_yuv(&mut g, &sources).expect("finite");
            let rows = |p: &Plane<u16>, y: u32| -> Vec<u16> {
                (0..p.width()).map(|x| p.get_pixel(x, y)[0]).collect()
            };
            for y in 0..16 {
                let want = if y < 12 {
                    rows(&f.y, y + 4)
                } else {
                    vec![64; 20]
                };
                assert_eq!(rows(&g.y, y), want, "{chroma:?} luma row {y}");
            }
            let step = 4 / chroma.subsampling().1;
            for yc in 0..f.u.height() {
                let want = if yc + step < f.u.height() {
                    rows(&f.u, yc + step)
                } else {
                    vec![512; f.u.width() as usize]
                };
                assert_eq!(rows(&g.u, yc), want, "{chroma:?} chroma row {yc}");
            }
        }
    }

    /// The row where column `x` of `plane` crosses `level` going down (linear between rows).
    fn edge_row(plane: &GrayImage, x: u32, level: f64) -> f64 {
        let v = |y: u32| f64::from(plane.get_pixel(x, y)[0]);
        let y = (0..plane.height() - 1)
            .find(|&y| (v(y) - level) * (v(y + 1) - level) <= 0.0 && v(y) != v(y + 1))
            .expect("an edge");
        f64::from(y) + (level - v(y)) / (v(y + 1) - v(y))
    }

    #[test]
    fn a_vertical_stretch_keeps_chroma_edges_on_luma_edges() {
        // A horizontal edge between luma rows 27 and 28 (edge at 27.5) in luma; the chroma
        // planes are the luma plane averaged over each chroma sample's rows (so their edge sits
        // at the same height). Stretched by a about the middle row (sources c + (y - c) / a),
        // the luma edge lands at c + (27.5 - c) a, and chroma's, at its luma position, must be
        // within half a chroma pixel of it (measured: within 0.1 luma row).
        let (w, h) = (24u32, 96u32);
        let c = f64::from(h) / 2.0;
        for chroma in [
            Chroma::Yuv420,
            Chroma::Yuv420CoSited,
            Chroma::Yuv422,
            Chroma::Yuv444,
        ] {
            for a in [1.12, 0.9] {
                let (hs, vs) = chroma.subsampling();
                let o = chroma.chroma_row_offset();
                let mut f: YuvFrame = YuvFrame::blank(&VideoFormat {
                    full_range: true,
                    ..format(w, h, chroma, 8)
                });
                let level = |y: f64| if y < 27.5 { 40.0 } else { 220.0 };
                f.y = GrayImage::from_fn(w, h, |_, y| Luma([level(f64::from(y)) as u8]));
                let (cw, ch) = chroma.plane_size(w, h);
                // Chroma row yc covers luma rows around vs yc + o: average the luma there.
                f.u = GrayImage::from_fn(cw, ch, |_, yc| {
                    let p = f64::from(vs * yc) + o;
                    let rows: Vec<f64> = if o > 0.0 {
                        vec![p - 0.5, p + 0.5]
                    } else {
                        vec![p]
                    };
                    let m = rows.iter().map(|&y| level(y)).sum::<f64>() / rows.len() as f64;
                    Luma([m as u8])
                });
                let sources: Vec<f64> = (0..h).map(|y| c + (f64::from(y) - c) / a).collect();
                resample_rows_yuv(&mut f, &sources).expect("finite");
                let want = c + (27.5 - c) * a;
                let luma = edge_row(&f.y, 5, 130.0);
                assert!((luma - want).abs() < 0.1, "{chroma:?} a={a}: luma {luma}");
                let chroma_edge = f64::from(vs) * edge_row(&f.u, 5 / hs, 130.0) + o;
                assert!(
                    (chroma_edge - luma).abs() <= f64::from(vs) / 2.0,
                    "{chroma:?} a={a}: chroma edge at luma {chroma_edge}, luma {luma}"
                );
                // Top rows come from above the frame: full-range black, neutral chroma.
                if a < 1.0 {
                    assert_eq!(f.y.get_pixel(0, 0)[0], 0);
                    assert_eq!(f.v.get_pixel(0, 0)[0], 128);
                }
            }
        }
    }

    #[test]
    fn video_frames_of_every_kind_take_row_tables() {
        let shifts: Vec<f64> = (0..12).map(|y| 0.1 * f64::from(y * y) - 3.0).collect();
        let sources: Vec<f64> = (0..12).map(|y| 1.05 * f64::from(y) - 0.2).collect();
        let interp = Interpolation::Cubic;
        let f8: YuvFrame = textured_frame(20, 12, Chroma::Yuv420, 8);
        let mut want = f8.clone();
        shift_rows_yuv(&mut want, &shifts, interp).expect("finite");
        let got = VideoFrame::Yuv(f8.clone()).shift_rows(&shifts, interp);
        assert_eq!(got.expect("finite"), VideoFrame::Yuv(want));
        let mut want = f8;
        resample_rows_yuv(&mut want, &sources).expect("finite");
        let got =
            VideoFrame::Yuv(textured_frame(20, 12, Chroma::Yuv420, 8)).resample_rows(&sources);
        assert_eq!(got.expect("finite"), VideoFrame::Yuv(want));
        let f16: YuvFrame<u16> = textured_frame(20, 12, Chroma::Yuv422, 12);
        let mut want = f16.clone();
        shift_rows_yuv(&mut want, &shifts, interp).expect("finite");
        resample_rows_yuv(&mut want, &sources).expect("finite");
        let got = VideoFrame::Yuv16(f16)
            .shift_rows(&shifts, interp)
            .and_then(|f| f.resample_rows(&sources));
        assert_eq!(got.expect("finite"), VideoFrame::Yuv16(want));
        let img = DynamicImage::ImageRgb8(image::RgbImage::from_fn(20, 12, |x, y| {
            image::Rgb([(x * 12) as u8, (y * 20) as u8, 99])
        }));
        let want = warp::try_resample_rows(
            &warp::try_shift_rows(&img, &shifts, interp).expect("finite"),
            &sources,
        )
        .expect("finite");
        let got = VideoFrame::Image(img)
            .shift_rows(&shifts, interp)
            .and_then(|f| f.resample_rows(&sources));
        assert_eq!(got.expect("finite"), VideoFrame::Image(want));
    }
}

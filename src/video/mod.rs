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
//!
//! # Formats
//!
//! Supported y4m layouts: 8-bit `Cmono`, `C420`, `C420jpeg`, `C420mpeg2`, `C420paldv`, `C422`,
//! `C444` (a missing `C` tag means 4:2:0, as in FFmpeg). **Not supported** (refused with an
//! error naming the tag): 10-, 12- and 16-bit samples (`C420p10` and the like), `C411`,
//! `C444alpha`, interlaced material is processed as if progressive (the `I` tag is kept but
//! fields are not separated). Frame folders take every format [`crate::imageio`] reads.
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
//! limited-range luma, 0 for full range; 128 for chroma), not the 0 that still images get.

pub mod color;
pub mod frames;
pub mod process;
pub mod temporal;
pub mod tracker;
pub mod y4m;

pub use process::{
    run, FrameResult, FrameSink, FrameSource, KSource, ProcessOptions, RunStats, VideoProcessor,
};

use std::borrow::Cow;

use image::{DynamicImage, GrayImage};

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

    /// Bytes of one frame's samples (8-bit).
    pub fn frame_bytes(&self) -> u64 {
        let (cw, ch) = self.chroma.plane_size(self.width, self.height);
        u64::from(self.width) * u64::from(self.height) + 2 * u64::from(cw) * u64::from(ch)
    }
}

/// One 8-bit YUV frame: three planes (U and V empty for mono) and the y4m frame parameters.
#[derive(Debug, Clone, PartialEq)]
pub struct YuvFrame {
    /// Colour layout of the planes.
    pub chroma: Chroma,
    /// Whether samples are full range (decides the fill value of luma).
    pub full_range: bool,
    /// Luma.
    pub y: GrayImage,
    /// Blue-difference chroma (Cb).
    pub u: GrayImage,
    /// Red-difference chroma (Cr).
    pub v: GrayImage,
    /// The text after `FRAME ` in a y4m stream, kept for the output.
    pub params: Option<Vec<u8>>,
}

impl YuvFrame {
    /// A frame of constant planes (black for the range, neutral chroma).
    pub fn blank(format: &VideoFormat) -> Self {
        let (cw, ch) = format.chroma.plane_size(format.width, format.height);
        Self {
            chroma: format.chroma,
            full_range: format.full_range,
            y: GrayImage::from_pixel(
                format.width,
                format.height,
                image::Luma([luma_black(format.full_range)]),
            ),
            u: GrayImage::from_pixel(cw, ch, image::Luma([128])),
            v: GrayImage::from_pixel(cw, ch, image::Luma([128])),
            params: None,
        }
    }
}

/// A frame as it travels through the pipeline: YUV planes from y4m, or a decoded image from a
/// frame folder.
#[derive(Debug, Clone, PartialEq)]
pub enum VideoFrame {
    /// Planes from a y4m stream.
    Yuv(YuvFrame),
    /// An image from a frame folder (any channel layout [`crate::imageio`] reads).
    Image(DynamicImage),
}

impl VideoFrame {
    /// Width and height of the (luma) picture.
    pub fn dimensions(&self) -> (u32, u32) {
        match self {
            VideoFrame::Yuv(f) => f.y.dimensions(),
            VideoFrame::Image(i) => (i.width(), i.height()),
        }
    }

    /// The grey picture that faces are detected and measured on: the Y plane itself for YUV
    /// (borrowed, no copy), OpenCV's grey conversion for images.
    pub fn luma(&self) -> Cow<'_, GrayImage> {
        match self {
            VideoFrame::Yuv(f) => Cow::Borrowed(&f.y),
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
            VideoFrame::Image(i) => {
                let shear = Shear::about_middle(k, i.height());
                Ok(VideoFrame::Image(
                    warp::try_remove_shear(&i, shear, interp, Canvas::Same)?.0,
                ))
            }
        }
    }
}

/// Luma of black: 0 in full range, 16 in limited range.
fn luma_black(full_range: bool) -> u8 {
    if full_range {
        0
    } else {
        16
    }
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
/// [`chroma_shear`]); uncovered pixels become black luma and neutral chroma.
///
/// # Errors
/// [`Error::InvalidArgument`] when `k` is not finite.
pub fn remove_shear_yuv(frame: &mut YuvFrame, k: f64, interp: Interpolation) -> Result<()> {
    if !k.is_finite() {
        return Err(Error::InvalidArgument(format!("shear {k} is not finite")));
    }
    if k == 0.0 {
        return Ok(());
    }
    let height = frame.y.height();
    let luma = Shear::about_middle(k, height);
    frame.y = shift_plane(
        std::mem::take(&mut frame.y),
        luma,
        interp,
        luma_black(frame.full_range),
    )?;
    if frame.chroma != Chroma::Mono {
        let cs = chroma_shear(frame.chroma, k, height);
        frame.u = shift_plane(std::mem::take(&mut frame.u), cs, interp, 128)?;
        frame.v = shift_plane(std::mem::take(&mut frame.v), cs, interp, 128)?;
    }
    Ok(())
}

/// One plane through [`warp::try_remove_shear`] (the AVX2 8-bit path), then the uncovered
/// pixels, which the warp fills with 0, re-filled with `fill` with the same linear fade over the
/// edge pixel.
fn shift_plane(
    plane: GrayImage,
    shear: Shear,
    interp: Interpolation,
    fill: u8,
) -> Result<GrayImage> {
    let (w, h) = plane.dimensions();
    if w == 0 || h == 0 {
        return Ok(plane);
    }
    // The refill needs only each row's first and last input pixel.
    let edges: Vec<(u8, u8)> = if fill != 0 {
        plane
            .as_raw()
            .chunks_exact(w as usize)
            .map(|r| (r[0], r[r.len() - 1]))
            .collect()
    } else {
        Vec::new()
    };
    let (out, _) = warp::try_remove_shear(
        &DynamicImage::ImageLuma8(plane),
        shear,
        interp,
        Canvas::Same,
    )?;
    let mut out = match out {
        DynamicImage::ImageLuma8(g) => g,
        other => other.to_luma8(),
    };
    if fill != 0 {
        refill_edges(&edges, &mut out, shear, fill);
    }
    Ok(out)
}

/// Rewrites the output pixels of a de-sheared plane whose source position `x + k (y - c)` lies
/// outside the input (`edges`: each input row's first and last pixel). Written by hand because
/// the warp's fill value is fixed at 0; it touches only the pixels beyond the edges, with the
/// warp's linear fade over the edge pixel, and leaves the interior as the warp made it.
fn refill_edges(edges: &[(u8, u8)], out: &mut GrayImage, shear: Shear, fill: u8) {
    let w = out.width() as usize;
    let last = (w - 1) as f64;
    let fill_f = f64::from(fill);
    for (y, (row_out, &(first, end))) in out.chunks_exact_mut(w).zip(edges).enumerate() {
        // Output x reads input position p = x + d.
        let d = shear.row_shift(y as f64);
        let (first, end) = (f64::from(first), f64::from(end));
        // Left edge: p < 0.
        let left_end = (-d).ceil().clamp(0.0, w as f64) as usize;
        for (x, o) in row_out.iter_mut().enumerate().take(left_end) {
            let t = (x as f64 + d + 1.0).clamp(0.0, 1.0); // weight of the first pixel
            *o = (fill_f * (1.0 - t) + first * t).round() as u8;
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
            *o = (end * (1.0 - t) + fill_f * t).round() as u8;
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
}

//! Sub-pixel row shifts that apply or undo a horizontal shear (equation 6 of the paper).
//!
//! A shear moves every row sideways by a constant amount, `s(y) = k * (y - c)` (see
//! `crate::geometry` for the convention). Undoing it therefore needs no 2-D resampling: each
//! output row is the same input row shifted by a constant sub-pixel amount, so the interpolation
//! weights are computed once per row and the inner loop is a short, branch-free dot product over
//! contiguous samples that the compiler vectorises.
//!
//! The same machinery takes any offset per row (`try_shift_rows`): under a rolling shutter a
//! view whose speed changes during the readout offsets the rows along a curve rather than a
//! line. The vertical counterpart, [`try_resample_rows`], moves whole rows instead (a view
//! moving up or down during the readout stretches or squeezes the picture).
//!
//! Conventions used throughout this module:
//!
//! * **Fill.** Output pixels whose source lies outside the input are 0 in every channel (black,
//!   and fully transparent for images with alpha). At the border the last half pixel fades
//!   linearly to 0 (anti-aliased edge) rather than stepping.
//! * **Interpolation.** [`Interpolation::Linear`] (2 taps) or [`Interpolation::Cubic`]
//!   (Catmull-Rom / Keys with `a = -0.5`, 4 taps). Cubic results are clamped to the sample range of
//!   integer images (0..=255, 0..=65535); floating-point images are not clamped because they may
//!   hold values outside `[0, 1]`. Inside the image, cubic taps that fall off the edge repeat the
//!   edge pixel, so the image border is not darkened.
//! * **Precision.** 8-bit images use fixed-point weights (the sub-pixel phase is quantised to
//!   1/256 pixel, far below anything visible); 16-bit and float images are interpolated in `f32`.
//! * **Exactness.** A row shift that is an integer (to within 1e-9) copies pixels exactly, so
//!   `k = 0` is the identity and integer shears lose nothing.
//! * **Threads.** Rows are processed in parallel on the current rayon pool.
//!
//! Every [`DynamicImage`] variant is supported and the output keeps the input's variant (a variant
//! added to `image` in the future is processed as `Rgba32F`).

pub mod rotate;

use crate::{Error, Point, Rect, Result, Shear};
use image::{DynamicImage, GrayImage, ImageBuffer, Pixel};
use rayon::prelude::*;

/// Dispatch a generic buffer operation over every `DynamicImage` variant, keeping the variant.
macro_rules! per_variant {
    ($img:expr, |$buf:ident| $body:expr) => {
        match $img {
            DynamicImage::ImageLuma8($buf) => DynamicImage::ImageLuma8($body),
            DynamicImage::ImageLumaA8($buf) => DynamicImage::ImageLumaA8($body),
            DynamicImage::ImageRgb8($buf) => DynamicImage::ImageRgb8($body),
            DynamicImage::ImageRgba8($buf) => DynamicImage::ImageRgba8($body),
            DynamicImage::ImageLuma16($buf) => DynamicImage::ImageLuma16($body),
            DynamicImage::ImageLumaA16($buf) => DynamicImage::ImageLumaA16($body),
            DynamicImage::ImageRgb16($buf) => DynamicImage::ImageRgb16($body),
            DynamicImage::ImageRgba16($buf) => DynamicImage::ImageRgba16($body),
            DynamicImage::ImageRgb32F($buf) => DynamicImage::ImageRgb32F($body),
            DynamicImage::ImageRgba32F($buf) => DynamicImage::ImageRgba32F($body),
            // `DynamicImage` is non-exhaustive: process anything new at full precision.
            other => {
                let converted = other.to_rgba32f();
                let $buf = &converted;
                DynamicImage::ImageRgba32F($body)
            }
        }
    };
}

/// How sample values between pixel centres are reconstructed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Interpolation {
    /// Two-tap linear interpolation: fast, never overshoots, slightly soft.
    #[default]
    Linear,
    /// Four-tap Catmull-Rom (Keys, `a = -0.5`) cubic: sharper, may overshoot (clamped).
    Cubic,
}

/// Which rectangle of the warped result is returned.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Canvas {
    /// The input's size and position; content shifted out is lost, uncovered pixels are fill (0).
    #[default]
    Same,
    /// Wide enough to contain every (even partially) covered pixel of the warped result, so
    /// nothing is lost; the corners are fill (0).
    Expand,
    /// The largest-area axis-aligned rectangle containing only pixels whose source lies inside the
    /// input (no fill at all).
    Crop,
}

/// Where the returned image sits in the warped result.
///
/// The warped result is defined on the input's coordinate frame: output of the shear formula
/// `x' = x + s(y)`, `y' = y`, with pixel centres at integers. Output pixel `(X, Y)` of the returned
/// image is the point `(X + offset_x, Y + offset_y)` of that frame. For [`Canvas::Same`] both
/// offsets are 0; for [`Canvas::Expand`] `offset_x <= 0`; for [`Canvas::Crop`] both are usually
/// positive. The offsets are always whole numbers (no resampling is added by the placement).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[non_exhaustive]
pub struct Placement {
    /// Frame column of the returned image's column 0.
    pub offset_x: f64,
    /// Frame row of the returned image's row 0.
    pub offset_y: f64,
}

impl Placement {
    /// The frame point shown by output pixel `p` of the returned image.
    pub fn to_frame(&self, p: Point) -> Point {
        Point::new(p.x + self.offset_x, p.y + self.offset_y)
    }

    /// The returned image's pixel coordinates of frame point `p`.
    pub fn from_frame(&self, p: Point) -> Point {
        Point::new(p.x - self.offset_x, p.y - self.offset_y)
    }
}

/// Shifts within this distance of an integer are treated as that integer, so that shears which
/// are integral up to floating-point rounding copy pixels exactly and canvases are not a pixel off.
const SNAP_EPS: f64 = 1e-9;

/// The largest output (in pixels) that [`try_apply_shear`] will allocate for a canvas. Only an
/// absurd `k` with [`Canvas::Expand`] can reach it.
pub(crate) const MAX_OUTPUT_PIXELS: u64 = 1 << 32;

fn snap(v: f64) -> f64 {
    let r = v.round();
    if (v - r).abs() < SNAP_EPS {
        r
    } else {
        v
    }
}

/// Output size and placement of [`apply_shear`] for an input of `width` x `height` pixels.
///
/// The warped content of input row `y` covers frame columns `s(y) ..= s(y) + width - 1`, with
/// `s(y) = shear.row_shift(y)`. For [`remove_shear`] pass the shear with `-k`.
///
/// * `Same`: `width` x `height` at offset 0.
/// * `Expand`: every frame column touched by some row (including the partially covered
///   anti-aliased edge pixel), all rows.
/// * `Crop`: for each candidate height `h` the rows are centred on the pivot (moved inside the
///   image if needed) and the width is what every chosen row covers entirely, about
///   `width - |k| * (h - 1)`; the `h` of largest area wins (ties go to the taller rectangle).
///
/// # Errors
/// [`Error::InvalidArgument`] if the shear is not finite, the `Expand` canvas would exceed
/// [`MAX_OUTPUT_PIXELS`], or no `Crop` rectangle exists (an image 1 pixel wide with fractional
/// shifts).
pub(crate) fn sheared_canvas(
    width: u32,
    height: u32,
    shear: Shear,
    canvas: Canvas,
) -> Result<(u32, u32, Placement)> {
    if !shear.k.is_finite() || !shear.pivot_y.is_finite() {
        return Err(Error::InvalidArgument(format!(
            "shear must be finite (k = {}, pivot = {})",
            shear.k, shear.pivot_y
        )));
    }
    let shift = |y: u32| snap(shear.row_shift(f64::from(y)));
    // A line's extremes over rows y0..=y1 are at its ends.
    let span = |y0: u32, y1: u32| {
        let (a, b) = (shift(y0), shift(y1));
        (a.min(b), a.max(b))
    };
    canvas_of_rows(width, height, shear.pivot_y, canvas, &span)
        .map_err(|what| Error::InvalidArgument(format!("{what} under shear k = {}", shear.k)))
}

/// [`sheared_canvas`] for rows shifted by their own amounts, `out(x, y) = in(x + shifts[y], y)`
/// (input row `y` lands at frame columns from `-shifts[y]`); `Crop` centres its rows on `pivot`.
///
/// # Errors
/// As [`sheared_canvas`].
pub(crate) fn shifted_canvas(
    width: u32,
    height: u32,
    shifts: &[f64],
    pivot: f64,
    canvas: Canvas,
) -> Result<(u32, u32, Placement)> {
    check_rows(shifts, height, "row shift")?;
    let span = |y0: u32, y1: u32| {
        shifts[y0 as usize..=y1 as usize].iter().fold(
            (f64::INFINITY, f64::NEG_INFINITY),
            |(a, b), &v| {
                let s = snap(-v);
                (a.min(s), b.max(s))
            },
        )
    };
    let pivot = if pivot.is_finite() {
        pivot
    } else {
        f64::from(height) / 2.0
    };
    canvas_of_rows(width, height, pivot, canvas, &span)
        .map_err(|what| Error::InvalidArgument(format!("{what} with its rows shifted")))
}

/// The canvas of rows whose content lands at frame columns `s(y) ..= s(y) + width - 1`, where
/// `span(y0, y1)` gives the least and the greatest `s` over rows `y0..=y1` (see
/// [`sheared_canvas`]); the error is what went wrong, for the caller to complete.
fn canvas_of_rows(
    width: u32,
    height: u32,
    pivot: f64,
    canvas: Canvas,
    span: &dyn Fn(u32, u32) -> (f64, f64),
) -> std::result::Result<(u32, u32, Placement), String> {
    let same = (width, height, Placement::default());
    if width == 0 || height == 0 {
        return Ok(same);
    }
    let w = f64::from(width);
    match canvas {
        Canvas::Same => Ok(same),
        Canvas::Expand => {
            let (least, most) = span(0, height - 1);
            let left = least.floor();
            let right = (most + w - 1.0).ceil();
            let out_w = right - left + 1.0;
            if out_w * f64::from(height) > MAX_OUTPUT_PIXELS as f64 {
                return Err(format!("a {out_w}x{height} canvas would be needed"));
            }
            Ok((
                out_w as u32,
                height,
                Placement {
                    offset_x: left,
                    offset_y: 0.0,
                },
            ))
        }
        Canvas::Crop => {
            // (area, out_w, h, x0, y0)
            let mut best: Option<(u64, u32, u32, f64, u32)> = None;
            for h in (1..=height).rev() {
                if best.is_some_and(|b| u64::from(width) * u64::from(h) <= b.0) {
                    // No narrower-or-equal rectangle of fewer rows can beat it.
                    break;
                }
                // Centre the rows on the pivot; the width only depends on h (up to rounding).
                let ideal = pivot - f64::from(h - 1) / 2.0;
                let y0 = ideal.round().clamp(0.0, f64::from(height - h)) as u32;
                let y1 = y0 + h - 1;
                let (least, most) = span(y0, y1);
                let x0 = most.ceil();
                let x1 = (least + w - 1.0).floor();
                if x1 < x0 {
                    continue;
                }
                let out_w = (x1 - x0 + 1.0) as u32;
                let area = u64::from(out_w) * u64::from(h);
                if best.is_none_or(|b| area > b.0) {
                    best = Some((area, out_w, h, x0, y0));
                }
            }
            let (_, out_w, h, x0, y0) = best
                .ok_or_else(|| format!("no pixel of a {width}x{height} image stays inside it"))?;
            Ok((
                out_w,
                h,
                Placement {
                    offset_x: x0,
                    offset_y: f64::from(y0),
                },
            ))
        }
    }
}

/// Produce the sheared image, `out(x, y) = in(x - k * (y - c), y)`: what a rolling shutter would
/// record of the undistorted `img`. Used to synthesise test data (`distort`).
///
/// # Panics
/// If the shear is not finite or the canvas is impossible (see [`try_apply_shear`], which returns
/// these as errors; use it for values that come from users).
pub fn apply_shear(
    img: &DynamicImage,
    shear: Shear,
    interp: Interpolation,
    canvas: Canvas,
) -> (DynamicImage, Placement) {
    match try_apply_shear(img, shear, interp, canvas) {
        Ok(v) => v,
        Err(e) => panic!("apply_shear: {e}"),
    }
}

/// Undo a shear (equation 6): `out(x, y) = in(x + k * (y - c), y)`. Exactly [`apply_shear`] with
/// `-k`; the [`Placement`] refers to the corrected frame.
///
/// # Panics
/// As [`apply_shear`]; see [`try_remove_shear`].
pub fn remove_shear(
    img: &DynamicImage,
    shear: Shear,
    interp: Interpolation,
    canvas: Canvas,
) -> (DynamicImage, Placement) {
    apply_shear(img, negate(shear), interp, canvas)
}

/// [`apply_shear`] that reports a non-finite shear or an impossible canvas as
/// [`Error::InvalidArgument`] instead of panicking.
pub fn try_apply_shear(
    img: &DynamicImage,
    shear: Shear,
    interp: Interpolation,
    canvas: Canvas,
) -> Result<(DynamicImage, Placement)> {
    let (plan, placement) = plan(img.width(), img.height(), shear, canvas)?;
    let out = per_variant!(img, |buf| warp_buffer(buf, &plan, interp));
    Ok((out, placement))
}

/// [`remove_shear`] that reports a non-finite shear or an impossible canvas as
/// [`Error::InvalidArgument`] instead of panicking.
pub fn try_remove_shear(
    img: &DynamicImage,
    shear: Shear,
    interp: Interpolation,
    canvas: Canvas,
) -> Result<(DynamicImage, Placement)> {
    try_apply_shear(img, negate(shear), interp, canvas)
}

/// `img` with its rows and columns swapped (`(x, y)` to `(y, x)`): a vertical shear becomes a
/// horizontal one, which the row warps above undo.
pub(crate) fn transpose(img: &DynamicImage) -> DynamicImage {
    img.rotate90().fliph()
}

/// [`try_remove_shear`] for a grey image, without wrapping it in a [`DynamicImage`] (which
/// would take a copy of it: the face search warps the grey photo many times).
pub fn try_remove_shear_gray(
    gray: &GrayImage,
    shear: Shear,
    interp: Interpolation,
    canvas: Canvas,
) -> Result<(GrayImage, Placement)> {
    let (plan, placement) = plan(gray.width(), gray.height(), negate(shear), canvas)?;
    Ok((warp_buffer(gray, &plan, interp), placement))
}

/// Shift every row by its own amount: `out(x, y) = in(x + shifts[y], y)`, same size and variant.
///
/// The general form of [`try_remove_shear`] (which is this with `shifts[y] = k * (y - c)`, and
/// gives the same pixels bit for bit): when the view's speed changes during a frame's readout
/// the rows' offsets follow a curve rather than a line. The module's conventions hold (fill 0
/// with the anti-aliased edge, integer shifts copy exactly, cubic clamped for integer samples).
///
/// # Errors
/// [`Error::InvalidArgument`] when `shifts.len()` is not the image's height or a shift is not
/// finite.
pub(crate) fn try_shift_rows(
    img: &DynamicImage,
    shifts: &[f64],
    interp: Interpolation,
) -> Result<DynamicImage> {
    let plan = offsets_plan(img.width(), img.height(), shifts)?;
    Ok(per_variant!(img, |buf| warp_buffer(buf, &plan, interp)))
}

/// Shift every row by its own amount on `canvas`: `out(x, y) = in(x + shifts[y], y)` placed as
/// [`try_remove_shear`] places a shear's result (`Crop` centring its rows on `pivot`), so a
/// whole-image correction whose shear changes down the rows
/// ([`RowShear`](crate::RowShear)) keeps the canvas the user asked for. With
/// `shifts[y] = k (y - pivot)` it gives [`try_remove_shear`]'s pixels and placement.
///
/// # Errors
/// [`Error::InvalidArgument`] when `shifts.len()` is not the image's height, a shift is not
/// finite, or the canvas is impossible.
pub fn try_shift_rows_on(
    img: &DynamicImage,
    shifts: &[f64],
    pivot: f64,
    interp: Interpolation,
    canvas: Canvas,
) -> Result<(DynamicImage, Placement)> {
    let (out_w, out_h, placement) =
        shifted_canvas(img.width(), img.height(), shifts, pivot, canvas)?;
    let plan = Plan {
        out_w: out_w as usize,
        out_h: out_h as usize,
        ox: placement.offset_x,
        oy: placement.offset_y as usize,
        rows: RowSource::Offsets {
            table: shifts,
            limit: 2.0 * f64::from(img.width().max(out_w)) + 8.0,
        },
    };
    Ok((
        per_variant!(img, |buf| warp_buffer(buf, &plan, interp)),
        placement,
    ))
}

/// `try_shift_rows` for a grey image, without wrapping it in a [`DynamicImage`] (which would
/// take a copy of it).
///
/// # Errors
/// As `try_shift_rows`.
pub fn try_shift_rows_gray(
    gray: &GrayImage,
    shifts: &[f64],
    interp: Interpolation,
) -> Result<GrayImage> {
    let plan = offsets_plan(gray.width(), gray.height(), shifts)?;
    Ok(warp_buffer(gray, &plan, interp))
}

/// Resample the rows vertically: `out(x, y) = in(x, sources[y])`, same size and variant.
///
/// Undoes a vertical stretch or squeeze (a view moving up or down during the readout spreads
/// the rows apart or packs them together). Each output row is a linear blend of the two input
/// rows nearest its source (an integer source copies its row exactly); sources outside
/// `[0, H - 1]` fade linearly to 0 over one row, as the horizontal edge does, and are 0 beyond.
/// No cubic option: one blend per row keeps it a memory-speed pass, and a readout stretch is a
/// few percent, so the rows' phases vary slowly.
///
/// # Errors
/// [`Error::InvalidArgument`] when `sources.len()` is not the image's height or a source is not
/// finite.
pub fn try_resample_rows(img: &DynamicImage, sources: &[f64]) -> Result<DynamicImage> {
    resample_rows_filled(img, sources, 0.0)
}

/// [`try_resample_rows`] with `fill` (in sample units) instead of 0 for the rows outside the
/// input, e.g. black luma and neutral chroma for video planes.
pub(crate) fn resample_rows_filled(
    img: &DynamicImage,
    sources: &[f64],
    fill: f64,
) -> Result<DynamicImage> {
    check_rows(sources, img.height(), "source row")?;
    Ok(per_variant!(img, |buf| resample_buffer(buf, sources, fill)))
}

/// The output canvas of `shear` applied to a `width x height` image, and where the input lands.
fn plan(
    width: u32,
    height: u32,
    shear: Shear,
    canvas: Canvas,
) -> Result<(Plan<'static>, Placement)> {
    let (out_w, out_h, placement) = sheared_canvas(width, height, shear, canvas)?;
    let plan = Plan {
        out_w: out_w as usize,
        out_h: out_h as usize,
        ox: placement.offset_x,
        oy: placement.offset_y as usize,
        rows: RowSource::Shear(shear),
    };
    Ok((plan, placement))
}

/// The same-size plan of [`try_shift_rows`]: row `y` reads `x_in = X + shifts[y]`.
fn offsets_plan(width: u32, height: u32, shifts: &[f64]) -> Result<Plan<'_>> {
    check_rows(shifts, height, "row shift")?;
    Ok(Plan {
        out_w: width as usize,
        out_h: height as usize,
        ox: 0.0,
        oy: 0,
        rows: RowSource::Offsets {
            table: shifts,
            // Beyond this distance every output pixel is fill anyway; clamping keeps the integer
            // tap positions far from overflow for absurd (but finite) shifts.
            limit: 2.0 * f64::from(width) + 8.0,
        },
    })
}

/// Checks a per-row table (row shifts or source rows): one finite value per row.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `what` when the length is not `height` or a value is not
/// finite.
pub(crate) fn check_rows(values: &[f64], height: u32, what: &str) -> Result<()> {
    if values.len() != height as usize {
        return Err(Error::InvalidArgument(format!(
            "{} {what} values for an image of {height} rows",
            values.len()
        )));
    }
    if let Some((y, v)) = values.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(Error::InvalidArgument(format!(
            "{what} of row {y} is not finite ({v})"
        )));
    }
    Ok(())
}

fn negate(shear: Shear) -> Shear {
    Shear::new(-shear.k, shear.pivot_y)
}

/// The width of the band around `region` across which [`remove_shear_in_region`] fades the
/// correction to zero: the larger of 20 % of the region's smaller side, twice the largest shift
/// inside the region (which keeps the warp one-to-one: the shift never changes faster than half a
/// pixel per pixel) and 2 pixels.
pub(crate) fn feather_margin(shear: Shear, region: Rect) -> f64 {
    let (y0, y1) = (region.y, region.y + region.height.max(0.0));
    let max_shift = shear.k.abs() * (y0 - shear.pivot_y).abs().max((y1 - shear.pivot_y).abs());
    (0.2 * region.width.min(region.height).max(0.0))
        .max(2.0 * max_shift)
        .max(2.0)
}

/// Undo the shear only inside `region` (a face box, already enlarged by the caller).
///
/// `out(x, y) = in(x + w(x, y) * k * (y' - c), y)` where `y'` is `y` clamped to the region's rows
/// (so the shift does not keep growing in the band above and below), and the weight `w` is 1
/// inside the region and falls smoothly (smoothstep, separately in x and y) to 0 across a band of
/// [`feather_margin`] pixels around it, so there are no seams and the warp never folds. Pixels
/// outside region + margin are copied unchanged, bit for bit. Same size and variant as the input.
/// Positions past the image border take the edge pixel (this warp never introduces fill).
/// A non-finite shear or an empty region returns an unchanged copy.
pub(crate) fn remove_shear_in_region(
    img: &DynamicImage,
    shear: Shear,
    region: Rect,
    interp: Interpolation,
) -> DynamicImage {
    let finite = [
        shear.k,
        shear.pivot_y,
        region.x,
        region.y,
        region.width,
        region.height,
    ]
    .iter()
    .all(|v| v.is_finite());
    if !finite || region.width <= 0.0 || region.height <= 0.0 || shear.k == 0.0 {
        return img.clone();
    }
    let local = LocalWarp {
        k: shear.k,
        pivot: shear.pivot_y,
        region,
        margin: feather_margin(shear, region),
    };
    per_variant!(img, |buf| warp_region_buffer(buf, &local, interp))
}

/// A whole-image warp: output row `Y` is input row `y = Y + oy`, read at
/// `x_in = X + Plan::source_offset(y)`.
struct Plan<'a> {
    out_w: usize,
    out_h: usize,
    ox: f64,
    oy: usize,
    rows: RowSource<'a>,
}

/// Where the horizontal offset of each row of a [`Plan`] comes from.
#[derive(Clone, Copy)]
enum RowSource<'a> {
    /// A shear: input row `y` lands at `x + s(y)`, so it is read at `x_in = X + ox - s(y)`.
    Shear(Shear),
    /// One offset per input row: `x_in = X + ox + table[y]`, clamped to `±limit`.
    Offsets { table: &'a [f64], limit: f64 },
}

impl Plan<'_> {
    /// `x_in - X` for input row `y` (not yet snapped to an integer).
    #[inline]
    fn source_offset(&self, y: usize) -> f64 {
        match self.rows {
            RowSource::Shear(shear) => self.ox - shear.row_shift(y as f64),
            RowSource::Offsets { table, limit } => (self.ox + table[y]).clamp(-limit, limit),
        }
    }
}

/// One sample type (u8, u16, f32) and its row kernels.
trait Sample: Copy + Default + Send + Sync + 'static {
    fn to_f32(self) -> f32;
    /// Round and clamp to the type's range (no clamping for floats).
    fn from_f32(v: f32) -> Self;

    /// Fill `dst` (one output row, `channels` interleaved) with `src` (one input row) sampled at
    /// `x_in = X + n + f`, `0 <= f < 1`.
    fn shift_row(
        src: &[Self],
        dst: &mut [Self],
        channels: usize,
        n: i64,
        f: f64,
        interp: Interpolation,
    ) {
        shift_row_generic(src, dst, channels, n, f as f32, interp);
    }

    /// `dst = (1 - f) a + f b` sample by sample, `0 <= f < 1`; `f == 0` copies `a` exactly.
    fn lerp_rows(dst: &mut [Self], a: &[Self], b: &[Self], f: f64) {
        if f == 0.0 {
            dst.copy_from_slice(a);
            return;
        }
        let f = f as f32;
        let w0 = 1.0 - f;
        for ((o, &p0), &p1) in dst.iter_mut().zip(a).zip(b) {
            *o = Self::from_f32(w0 * p0.to_f32() + f * p1.to_f32());
        }
    }
}

impl Sample for u8 {
    #[inline]
    fn to_f32(self) -> f32 {
        f32::from(self)
    }
    #[inline]
    fn from_f32(v: f32) -> Self {
        v.round().clamp(0.0, 255.0) as u8
    }
    fn shift_row(
        src: &[u8],
        dst: &mut [u8],
        channels: usize,
        n: i64,
        f: f64,
        interp: Interpolation,
    ) {
        shift_row_u8(src, dst, channels, n, f, interp);
    }
    /// The fixed-point blend of [`shift_row_u8`] (phase quantised to 1/256).
    fn lerp_rows(dst: &mut [u8], a: &[u8], b: &[u8], f: f64) {
        let q = (f * 256.0).round() as u16;
        match q {
            0 => dst.copy_from_slice(a),
            256.. => dst.copy_from_slice(b),
            _ => linear_u8_dispatch(dst, a, b, 256 - q, q),
        }
    }
}

impl Sample for u16 {
    #[inline]
    fn to_f32(self) -> f32 {
        f32::from(self)
    }
    #[inline]
    fn from_f32(v: f32) -> Self {
        v.round().clamp(0.0, 65535.0) as u16
    }
}

impl Sample for f32 {
    #[inline]
    fn to_f32(self) -> f32 {
        self
    }
    #[inline]
    fn from_f32(v: f32) -> Self {
        v
    }
}

/// Keys cubic weights (a = -0.5) for taps at offsets -1, 0, 1, 2 from the floor position.
#[inline]
fn keys_weights(t: f32) -> [f32; 4] {
    let t2 = t * t;
    let t3 = t2 * t;
    [
        -0.5 * t3 + t2 - 0.5 * t,
        1.5 * t3 - 2.5 * t2 + 1.0,
        -1.5 * t3 + 2.0 * t2 + 0.5 * t,
        0.5 * t3 - 0.5 * t2,
    ]
}

/// The output pixels `[lo, hi)` of a row whose taps all lie inside the input row, for the
/// position `X + n + f`.
fn interior_range(
    n: i64,
    f_is_zero: bool,
    interp: Interpolation,
    w_in: i64,
    w_out: i64,
) -> (usize, usize) {
    // Taps used relative to the floor position: [first, last].
    let (first, last) = match (f_is_zero, interp) {
        (true, _) => (0, 0),
        (false, Interpolation::Linear) => (0, 1),
        (false, Interpolation::Cubic) => (-1, 2),
    };
    let lo = (-n - first).clamp(0, w_out);
    let hi = (w_in - last - n).clamp(lo, w_out);
    (lo as usize, hi as usize)
}

/// One output pixel at position `i + f` (`i` the floor tap) with the border rules of the module:
/// zero outside, linear fade over the last half pixel, cubic with repeated edge taps inside.
#[inline]
fn edge_pixel<T: Sample>(
    src: &[T],
    out: &mut [T],
    channels: usize,
    i: i64,
    f: f32,
    interp: Interpolation,
) {
    let w_in = (src.len() / channels) as i64;
    let tap = |j: i64, c: usize| -> f32 {
        if (0..w_in).contains(&j) {
            src[j as usize * channels + c].to_f32()
        } else {
            0.0
        }
    };
    if f == 0.0 {
        for (c, o) in out.iter_mut().enumerate() {
            *o = if (0..w_in).contains(&i) {
                src[i as usize * channels + c]
            } else {
                T::default()
            };
        }
    } else if interp == Interpolation::Cubic && i >= 0 && i + 1 < w_in {
        let w = keys_weights(f);
        for (c, o) in out.iter_mut().enumerate() {
            let mut acc = 0.0;
            for (t, wt) in w.iter().enumerate() {
                let j = (i + t as i64 - 1).clamp(0, w_in - 1);
                acc += wt * src[j as usize * channels + c].to_f32();
            }
            *o = T::from_f32(acc);
        }
    } else {
        for (c, o) in out.iter_mut().enumerate() {
            *o = T::from_f32((1.0 - f) * tap(i, c) + f * tap(i + 1, c));
        }
    }
}

fn shift_edges<T: Sample>(
    src: &[T],
    dst: &mut [T],
    channels: usize,
    n: i64,
    f: f32,
    interp: Interpolation,
    (lo, hi): (usize, usize),
) {
    let w_out = dst.len() / channels;
    let w_in = (src.len() / channels) as i64;
    // Pixels whose position `x + n + f` is at or beyond a full pixel outside the input are pure
    // fill: write them as a block (this is most of the edge work for large shears).
    let first_covered = (-1 - n + i64::from(f == 0.0)).clamp(0, w_out as i64) as usize;
    let end_covered = (w_in - n).clamp(first_covered as i64, w_out as i64) as usize;
    dst[..first_covered.min(lo) * channels].fill(T::default());
    dst[end_covered.max(hi) * channels..].fill(T::default());
    let left = first_covered.min(lo)..lo;
    let right = hi..end_covered.max(hi);
    for x in left.chain(right) {
        edge_pixel(
            src,
            &mut dst[x * channels..(x + 1) * channels],
            channels,
            x as i64 + n,
            f,
            interp,
        );
    }
}

/// The float row kernel for 16-bit and float images (and the reference for the u8 one).
fn shift_row_generic<T: Sample>(
    src: &[T],
    dst: &mut [T],
    channels: usize,
    n: i64,
    f: f32,
    interp: Interpolation,
) {
    let w_in = (src.len() / channels) as i64;
    let w_out = (dst.len() / channels) as i64;
    let range = interior_range(n, f == 0.0, interp, w_in, w_out);
    shift_edges(src, dst, channels, n, f, interp, range);
    let (lo, hi) = range;
    if lo == hi {
        return;
    }
    let len = (hi - lo) * channels;
    let out = &mut dst[lo * channels..hi * channels];
    // Start of the floor tap for output pixel `lo`, in samples.
    let base = ((lo as i64 + n) as usize) * channels;
    if f == 0.0 {
        out.copy_from_slice(&src[base..base + len]);
        return;
    }
    match interp {
        Interpolation::Linear => {
            let (w0, w1) = (1.0 - f, f);
            let a = &src[base..base + len];
            let b = &src[base + channels..base + channels + len];
            for ((o, &p0), &p1) in out.iter_mut().zip(a).zip(b) {
                *o = T::from_f32(w0 * p0.to_f32() + w1 * p1.to_f32());
            }
        }
        Interpolation::Cubic => {
            let w = keys_weights(f);
            let start = base - channels;
            let a = &src[start..start + len];
            let b = &src[start + channels..start + channels + len];
            let c = &src[start + 2 * channels..start + 2 * channels + len];
            let d = &src[start + 3 * channels..start + 3 * channels + len];
            for ((((o, &p0), &p1), &p2), &p3) in out.iter_mut().zip(a).zip(b).zip(c).zip(d) {
                *o = T::from_f32(
                    w[0] * p0.to_f32()
                        + w[1] * p1.to_f32()
                        + w[2] * p2.to_f32()
                        + w[3] * p3.to_f32(),
                );
            }
        }
    }
}

/// The 8-bit row kernel: phase quantised to 1/256 pixel, integer weights.
fn shift_row_u8(
    src: &[u8],
    dst: &mut [u8],
    channels: usize,
    n: i64,
    f: f64,
    interp: Interpolation,
) {
    let q = (f * 256.0).round() as i64;
    let (n, q) = if q >= 256 { (n + 1, 0) } else { (n, q) };
    // Exactly representable, so the float edge pixels agree with the fixed-point interior.
    let fq = q as f32 / 256.0;
    let w_in = (src.len() / channels) as i64;
    let w_out = (dst.len() / channels) as i64;
    let range = interior_range(n, q == 0, interp, w_in, w_out);
    shift_edges(src, dst, channels, n, fq, interp, range);
    let (lo, hi) = range;
    if lo == hi {
        return;
    }
    let len = (hi - lo) * channels;
    let out = &mut dst[lo * channels..hi * channels];
    let base = ((lo as i64 + n) as usize) * channels;
    if q == 0 {
        out.copy_from_slice(&src[base..base + len]);
        return;
    }
    match interp {
        Interpolation::Linear => {
            let w1 = q as u16;
            let w0 = 256 - w1;
            linear_u8_dispatch(
                out,
                &src[base..base + len],
                &src[base + channels..base + channels + len],
                w0,
                w1,
            );
        }
        Interpolation::Cubic => {
            let scale = f32::from(1u16 << CUBIC_BITS);
            let wf = keys_weights(fq);
            let w0 = (wf[0] * scale).round() as i16;
            let w2 = (wf[2] * scale).round() as i16;
            let w3 = (wf[3] * scale).round() as i16;
            // The weights sum to exactly 1.0 in fixed point, so flat areas stay exactly flat.
            let w1 = (1i16 << CUBIC_BITS) - w0 - w2 - w3;
            let start = base - channels;
            let tap = |t: usize| &src[start + t * channels..start + t * channels + len];
            cubic_u8_dispatch(out, [tap(0), tap(1), tap(2), tap(3)], [w0, w1, w2, w3]);
        }
    }
}

#[inline(always)]
fn linear_u8(out: &mut [u8], a: &[u8], b: &[u8], w0: u16, w1: u16) {
    // u16 lanes: 255 * 256 + 128 fits, so this vectorises to 16-bit multiplies.
    for ((o, &p0), &p1) in out.iter_mut().zip(a).zip(b) {
        *o = ((u16::from(p0) * w0 + u16::from(p1) * w1 + 128) >> 8) as u8;
    }
}

/// Fixed-point scale of the 8-bit cubic weights (1/4096; every weight fits an `i16`).
const CUBIC_BITS: u32 = 12;

/// The 8-bit cubic kernel: `u8 x i16` products summed in pairs in `i32`, the shape of SSE2's
/// `pmaddwd`, which LLVM selects (about 3x faster than generic 32-bit multiplies, which SSE2
/// lacks). Equal-length re-slicing up front removes the bounds checks from the loop.
#[inline(always)]
fn cubic_u8(out: &mut [u8], taps: [&[u8]; 4], w: [i16; 4]) {
    let n = out.len();
    let [a, b, c, d] = taps;
    let (a, b, c, d) = (&a[..n], &b[..n], &c[..n], &d[..n]);
    let [w0, w1, w2, w3] = w.map(i32::from);
    let round = 1i32 << (CUBIC_BITS - 1);
    for i in 0..n {
        let v = (i32::from(a[i]) * w0 + i32::from(b[i]) * w1)
            + (i32::from(c[i]) * w2 + i32::from(d[i]) * w3);
        out[i] = ((v + round) >> CUBIC_BITS).clamp(0, 255) as u8;
    }
}

/// Copies of the 8-bit kernels compiled for AVX2 (twice the lanes of the SSE2 baseline that
/// `x86_64` builds target), chosen at run time. The kernels themselves are safe code; only the
/// instruction set differs.
#[cfg(target_arch = "x86_64")]
mod avx2 {
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn linear_u8(out: &mut [u8], a: &[u8], b: &[u8], w0: u16, w1: u16) {
        super::linear_u8(out, a, b, w0, w1);
    }

    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn cubic_u8(out: &mut [u8], taps: [&[u8]; 4], w: [i16; 4]) {
        super::cubic_u8(out, taps, w);
    }
}

/// [`linear_u8`] through the fastest instruction set this CPU has.
fn linear_u8_dispatch(out: &mut [u8], a: &[u8], b: &[u8], w0: u16, w1: u16) {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2 (checked just above), the only precondition of the
        // `target_feature` function.
        unsafe { avx2::linear_u8(out, a, b, w0, w1) };
        return;
    }
    linear_u8(out, a, b, w0, w1);
}

/// [`cubic_u8`] through the fastest instruction set this CPU has.
fn cubic_u8_dispatch(out: &mut [u8], taps: [&[u8]; 4], w: [i16; 4]) {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") {
        // SAFETY: as in `linear_u8_dispatch`.
        unsafe { avx2::cubic_u8(out, taps, w) };
        return;
    }
    cubic_u8(out, taps, w);
}

type Buffer<P> = ImageBuffer<P, Vec<<P as Pixel>::Subpixel>>;

fn warp_buffer<P>(buf: &Buffer<P>, plan: &Plan, interp: Interpolation) -> Buffer<P>
where
    P: Pixel,
    P::Subpixel: Sample,
{
    let channels = usize::from(P::CHANNEL_COUNT);
    let in_row = buf.width() as usize * channels;
    let out_row = plan.out_w * channels;
    let src: &[P::Subpixel] = buf.as_raw();
    let mut out = vec![P::Subpixel::default(); out_row * plan.out_h];
    if out_row > 0 {
        out.par_chunks_mut(out_row)
            .enumerate()
            .with_min_len(8)
            .for_each(|(y, row)| {
                let yi = y + plan.oy;
                let d = snap(plan.source_offset(yi));
                let n = d.floor();
                let src_row = &src[yi * in_row..(yi + 1) * in_row];
                P::Subpixel::shift_row(src_row, row, channels, n as i64, d - n, interp);
            });
    }
    ImageBuffer::from_raw(plan.out_w as u32, plan.out_h as u32, out)
        .expect("output buffer has exactly out_w * out_h * channels samples")
}

fn resample_buffer<P>(buf: &Buffer<P>, sources: &[f64], fill: f64) -> Buffer<P>
where
    P: Pixel,
    P::Subpixel: Sample,
{
    let channels = usize::from(P::CHANNEL_COUNT);
    let row_len = buf.width() as usize * channels;
    let h = buf.height() as usize;
    let src: &[P::Subpixel] = buf.as_raw();
    let fill = P::Subpixel::from_f32(fill as f32);
    let fill_row = vec![fill; row_len];
    let mut out = vec![P::Subpixel::default(); row_len * h];
    // Input row `i` (a whole number), or the fill row outside the input.
    let row_at = |i: f64| -> Option<&[P::Subpixel]> {
        (i >= 0.0 && i < h as f64).then(|| {
            let i = i as usize;
            &src[i * row_len..(i + 1) * row_len]
        })
    };
    if row_len > 0 {
        out.par_chunks_mut(row_len)
            .zip(sources)
            .with_min_len(8)
            .for_each(|(dst, &s)| {
                let p = snap(s);
                let n = p.floor();
                match (row_at(n), row_at(n + 1.0)) {
                    (None, None) => dst.copy_from_slice(&fill_row),
                    (a, b) => P::Subpixel::lerp_rows(
                        dst,
                        a.unwrap_or(&fill_row),
                        b.unwrap_or(&fill_row),
                        p - n,
                    ),
                }
            });
    }
    ImageBuffer::from_raw(buf.width(), buf.height(), out)
        .expect("output buffer has exactly width * height * channels samples")
}

/// Parameters of [`remove_shear_in_region`].
struct LocalWarp {
    k: f64,
    pivot: f64,
    region: Rect,
    margin: f64,
}

impl LocalWarp {
    /// Smoothstep weight of coordinate `v` for the interval `[a, b]` feathered by the margin.
    fn weight(&self, v: f64, a: f64, b: f64) -> f64 {
        let dist = if v < a {
            a - v
        } else if v > b {
            v - b
        } else {
            return 1.0;
        };
        if dist >= self.margin {
            return 0.0;
        }
        let t = 1.0 - dist / self.margin;
        t * t * (3.0 - 2.0 * t)
    }
}

fn warp_region_buffer<P>(buf: &Buffer<P>, warp: &LocalWarp, interp: Interpolation) -> Buffer<P>
where
    P: Pixel,
    P::Subpixel: Sample,
{
    let mut out = buf.clone();
    let (w, h) = (buf.width() as usize, buf.height() as usize);
    if w == 0 || h == 0 {
        return out;
    }
    let channels = usize::from(P::CHANNEL_COUNT);
    let row_len = w * channels;
    let r = warp.region;
    let (rx0, rx1, ry0, ry1) = (r.x, r.x + r.width, r.y, r.y + r.height);
    let m = warp.margin;
    // Pixels strictly inside the feathered box; everything else keeps weight 0 and is untouched.
    let clamp_idx = |v: f64, max: usize| v.clamp(0.0, max as f64) as usize;
    let (x_lo, x_hi) = (
        clamp_idx((rx0 - m).floor(), w),
        clamp_idx((rx1 + m).ceil() + 1.0, w),
    );
    let (y_lo, y_hi) = (
        clamp_idx((ry0 - m).floor(), h),
        clamp_idx((ry1 + m).ceil() + 1.0, h),
    );
    if x_lo >= x_hi || y_lo >= y_hi {
        return out;
    }
    let src: &[P::Subpixel] = buf.as_raw();
    let dst: &mut [P::Subpixel] = &mut out;
    dst[y_lo * row_len..y_hi * row_len]
        .par_chunks_mut(row_len)
        .enumerate()
        .for_each(|(i, row)| {
            let y = (y_lo + i) as f64;
            let wy = warp.weight(y, ry0, ry1);
            if wy == 0.0 {
                return;
            }
            let shift = warp.k * (y.clamp(ry0, ry1) - warp.pivot) * wy;
            let src_row = &src[(y_lo + i) * row_len..(y_lo + i + 1) * row_len];
            for x in x_lo..x_hi {
                let s = shift * warp.weight(x as f64, rx0, rx1);
                if s == 0.0 {
                    continue;
                }
                let p = snap((x as f64 + s).clamp(0.0, (w - 1) as f64));
                let fl = p.floor();
                edge_pixel(
                    src_row,
                    &mut row[x * channels..(x + 1) * channels],
                    channels,
                    fl as i64,
                    (p - fl) as f32,
                    interp,
                );
            }
        });
    out
}

#[cfg(test)]
mod tests;

#[cfg(test)]
mod rows_tests;

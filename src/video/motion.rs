//! Image motion between consecutive frames, band by band: the ruler of the rolling-shutter
//! model (issue 58), where a frame's shear is `k = rho * v / H` for an image velocity `v`.
//!
//! Under a rolling shutter row `y` of frame `n` is read at `n + rho * y / H`, so the displacement
//! of the rows around `y` between frames `n - 1` and `n` is the mean image velocity over
//! `[n - 1 + rho y / H, n + rho y / H]`: the frame is cut into horizontal bands and each band
//! reports its own displacement and centre row. With a constant pan all bands agree (both frames
//! carry the same shear, which does not bias the displacement); with a pan that changes speed
//! they differ, and the caller fits the velocity through them. Bands are never forced to agree.
//!
//! Method, per band (see [`MotionEstimator`]):
//!
//! 1. Both frames are reduced by an integer factor `f` (block means; at most
//!    [`MotionParams::max_width`] columns), so that a displacement scales by exactly `f`.
//! 2. **Phase correlation** of the band (a window of twice the band spacing, 50 % overlap,
//!    a Hann taper across its rows and a Tukey taper along them, mean removed): the cross-power
//!    spectrum `F_cur conj(F_prev) / (|F_cur||F_prev| + eps)`, whose regulariser `eps` (a
//!    fraction of the mean cross-power) leaves the frequencies where a motion blur's box spectrum
//!    has its zeros, or where noise dominates, with little weight instead of a random phase of
//!    full weight. The highest peak within the search range gives the displacement to a pixel of
//!    the reduced frame; its height against the plane's spread (the peak-to-sidelobe ratio) and
//!    the next local maximum (repetitive texture) decide whether the band is reliable.
//! 3. **Refinement** by Gauss-Newton (Lucas-Kanade for a translation) on the reduced band from
//!    the correlation peak, with Tukey biweights on the residuals, so pixels of a subject moving
//!    otherwise than the band's dominant content drop out. The parabola through a correlation
//!    peak is biased towards whole pixels by up to ~0.1 px of the reduced frame (0.4 px of a
//!    1920-wide frame); the least-squares step is not. Its covariance (residual variance
//!    through the normal equations, with the weights' sandwich) gives the band's `sigma`,
//!    calibrated on the tests below to be a fair 1-sigma.
//!
//! The frame's displacement ([`FrameShift`]) is the inverse-variance mean of the bands that agree
//! with a robust line through all of them (dx against the row, so a speed change is not taken
//! for an outlier); bands that disagree (a subject crossing in front of the background) are
//! kept apart in [`FrameShift::rejected`].

use std::cell::RefCell;
use std::ops::Range;
use std::sync::Arc;

use image::GrayImage;
use rayon::prelude::*;
use rustfft::num_complex::Complex32;
use rustfft::{Fft, FftPlanner};
use serde::{Deserialize, Serialize};

#[cfg(any(test, feature = "dev"))]
use crate::geometry::Rect;
use crate::{Error, Result};

/// The regulariser of the whitened cross-power, as a fraction of its mean magnitude.
const WHITEN_EPS: f32 = 0.1;
/// Smallest peak-to-sidelobe ratio of a reliable band (a noise plane of ~30 000 values reaches
/// about 4.5).
const MIN_PSR: f64 = 6.0;
/// Smallest normalised peak height of a reliable band: below it the peak, though above the
/// plane's noise, is mostly noise (heavy noise on a blurred frame: noise 30 grey levels and a
/// 16 px blur gave peaks of 0.04-0.055 and errors up to 3.6 px; good bands measured 0.15 and
/// more).
const MIN_STRENGTH: f64 = 0.08;
/// Largest ratio of the second local maximum to the peak of a reliable band, unless the
/// second's alignment explains clearly less of the band than the peak's.
const MAX_AMBIGUITY: f64 = 0.75;
/// Smallest ratio of the second local maximum to the peak for the second to be refined too
/// (another motion in the band).
const MIN_RIVAL: f64 = 0.2;
/// Half-size of the square around the peak left out of the sidelobe and of the second-peak
/// search (reduced pixels).
const PEAK_EXCLUSION: isize = 3;
/// Fewest rows of a band's window in the reduced frame.
const MIN_WINDOW_ROWS: usize = 16;
/// Fewest columns of the reduced frame.
const MIN_COLUMNS: usize = 16;
/// Fraction of the width tapered at each side of a band (Tukey window).
const TAPER: f64 = 0.15;
/// Largest distance, in reduced pixels, the refinement may move from the correlation peak.
const MAX_REFINE_STEP: f64 = 1.5;
/// Most Gauss-Newton passes of a refinement (it stops earlier once a step is under 0.005 px).
const PASSES: usize = 6;
/// Independent sums kept per accumulated quantity in the refinement (SIMD lanes).
const LANES: usize = 8;
/// Tukey biweight constant (times the residuals' robust scale).
const BIWEIGHT_C: f32 = 3.0;
/// Scale from the least-squares covariance to a fair 1-sigma (calibrated by the tests'
/// noisy trials: residual correlation from the bilinear sampling and the reduction).
const SIGMA_SCALE: f64 = 1.0;
/// Smallest 1-sigma of a band, in pixels of the level it was refined at (model error: the
/// texture's aliasing in the reduced frame, the interpolation).
const SIGMA_FLOOR: f64 = 0.02;

/// Settings of the frame-to-frame motion measurement.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MotionParams {
    /// Reduce frames to at most this many columns before correlating (by a whole factor, so
    /// possibly fewer); 0: full size. Fewer columns are faster; the refinement keeps the
    /// reduced frame's sub-pixel accuracy, so the error in full-resolution pixels grows with the
    /// factor. Default 480.
    pub max_width: u32,
    /// Horizontal bands the frame is cut into, each giving its own displacement (0: one band
    /// per 32 rows of the reduced frame, 2 to 16). Capped so a band's window keeps at least 16
    /// rows of the reduced frame. Default 8.
    pub bands: u32,
    /// Largest displacement searched, as a fraction of the width (at most 0.45: beyond, the
    /// overlap of the two frames is too small). Default 0.35.
    pub max_shift: f64,
}

impl Default for MotionParams {
    fn default() -> Self {
        Self {
            max_width: 480,
            bands: 8,
            max_shift: 0.35,
        }
    }
}

impl MotionParams {
    /// Checks the settings: `max_width` 0 or at least 32, `bands` at most 64, `max_shift` in
    /// `(0, 0.45]`.
    pub fn validate(&self) -> Result<()> {
        if self.max_width != 0 && self.max_width < 32 {
            return Err(Error::InvalidArgument(format!(
                "motion max_width {} (0 or at least 32)",
                self.max_width
            )));
        }
        if self.bands > 64 {
            return Err(Error::InvalidArgument(format!(
                "motion bands {} (at most 64)",
                self.bands
            )));
        }
        if !(self.max_shift > 0.0 && self.max_shift <= 0.45) {
            return Err(Error::InvalidArgument(format!(
                "motion max_shift {} (in (0, 0.45])",
                self.max_shift
            )));
        }
        Ok(())
    }

    /// The settings brought into their valid ranges (a NaN `max_shift` takes the default).
    fn sanitized(self) -> Self {
        let max_width = if self.max_width == 0 {
            0
        } else {
            self.max_width.max(32)
        };
        let max_shift = if self.max_shift.is_nan() {
            Self::default().max_shift
        } else {
            self.max_shift.clamp(0.01, 0.45)
        };
        Self {
            max_width,
            bands: self.bands.min(64),
            max_shift,
        }
    }
}

/// The displacement of one band of rows (or of a region) between two frames.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BandShift {
    /// Centre row of the band in full-resolution pixels: the row its texture is centred on
    /// (weighted by the horizontal gradients that measure `dx`), where a displacement varying
    /// with the row is best taken to apply.
    pub row: f64,
    /// Horizontal displacement of the content, full-resolution pixels (> 0: moved right).
    pub dx: f64,
    /// Vertical displacement (> 0: moved down).
    pub dy: f64,
    /// 1-sigma uncertainty of each of `dx`, `dy` (the rms of the two), full-resolution pixels.
    pub sigma: f64,
    /// Height of the normalised correlation peak, 0 to 1 (1: the same content, no noise).
    pub strength: f64,
}

/// The displacement of a frame's content since the previous frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameShift {
    /// The reliable bands that agree with the others (a line through them against the row),
    /// top to bottom.
    pub bands: Vec<BandShift>,
    /// Reliable bands that disagree with the others (a subject moving in front of the
    /// background, for example), top to bottom.
    pub rejected: Vec<BandShift>,
    /// Inverse-variance mean of `bands`' `dx`, full-resolution pixels.
    pub dx: f64,
    /// Inverse-variance mean of `bands`' `dy`.
    pub dy: f64,
    /// 1-sigma of `dx` and `dy` (inflated when the bands scatter beyond their own sigmas, as
    /// with a pan changing speed).
    pub sigma: f64,
}

/// Measures the displacement between consecutive frames, band by band.
///
/// FFT plans and work buffers are made for a frame size on its first frame and reused; each
/// frame's band spectra are kept for the next frame, so a frame costs one reduction, one
/// forward and one inverse FFT per band and the refinement. Bands run in parallel (rayon).
pub struct MotionEstimator {
    params: MotionParams,
    state: Option<State>,
}

impl std::fmt::Debug for MotionEstimator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MotionEstimator")
            .field("params", &self.params)
            .field("frame", &self.state.as_ref().map(|s| s.size))
            .finish()
    }
}

impl Default for MotionEstimator {
    fn default() -> Self {
        Self::new(MotionParams::default())
    }
}

/// What the estimator keeps for one frame size.
struct State {
    size: (u32, u32),
    layout: Layout,
    bands: Vec<BandWork>,
    prev: Vec<f32>,
    cur: Vec<f32>,
    has_prev: bool,
}

impl MotionEstimator {
    /// An estimator with `params` brought into their valid ranges (see
    /// [`MotionParams::validate`]; [`MotionEstimator::try_new`] refuses them instead).
    pub fn new(params: MotionParams) -> Self {
        Self {
            params: params.sanitized(),
            state: None,
        }
    }

    /// An estimator, or an error when `params` are outside their valid ranges.
    #[cfg_attr(not(feature = "dev"), allow(dead_code))]
    pub fn try_new(params: MotionParams) -> Result<Self> {
        params.validate()?;
        Ok(Self::new(params))
    }

    /// The settings in force.
    #[cfg_attr(not(feature = "dev"), allow(dead_code))]
    pub fn params(&self) -> MotionParams {
        self.params
    }

    /// Displacement of the image content from the previously pushed frame to this one
    /// (full-resolution pixels; `dx > 0`: content moved right, `dy > 0`: moved down).
    ///
    /// `None` for the first frame, after a size change (the frame starts a new sequence), for a
    /// frame too small to measure (under 16 rows or columns once reduced), and when no band is
    /// reliable (flat or repetitive texture, a cut).
    pub fn push(&mut self, luma: &GrayImage) -> Option<FrameShift> {
        let size = luma.dimensions();
        if self.state.as_ref().map(|s| s.size) != Some(size) {
            self.state = Layout::new(&self.params, size.0, size.1).map(|layout| State {
                size,
                bands: (0..layout.starts.len())
                    .map(|_| BandWork::new(&layout))
                    .collect(),
                layout,
                prev: Vec::new(),
                cur: Vec::new(),
                has_prev: false,
            });
        }
        let state = self.state.as_mut()?;
        let layout = &state.layout;
        reduce_into(luma, layout.f, &mut state.cur);
        let has_prev = state.has_prev;
        let (cur, prev) = (&state.cur, &state.prev);
        let found: Vec<Option<BandShift>> = state
            .bands
            .par_iter_mut()
            .enumerate()
            .map(|(b, work)| work.push(layout, b, cur, prev, has_prev))
            .collect();
        std::mem::swap(&mut state.prev, &mut state.cur);
        state.has_prev = true;
        if !has_prev {
            return None;
        }
        combine(found.into_iter().flatten().collect())
    }

    /// Forgets the previous frame (the next push starts a new sequence; buffers are kept).
    #[cfg_attr(not(feature = "dev"), allow(dead_code))]
    pub fn reset(&mut self) {
        if let Some(s) = self.state.as_mut() {
            s.has_prev = false;
        }
    }
}

/// Geometry of the bands for one frame size.
struct Layout {
    /// Reduction factor.
    f: usize,
    /// Reduced frame size.
    w: usize,
    h: usize,
    /// FFT size (at least the band window, 5-smooth).
    fw: usize,
    fh: usize,
    /// Rows of a band's window.
    hw: usize,
    /// First row of each band's window.
    starts: Vec<usize>,
    /// Search half-ranges (reduced pixels).
    rx: usize,
    ry: usize,
    /// Window weights along and across the rows.
    wx: Vec<f32>,
    wy: Vec<f32>,
    plans: Plans,
}

impl Layout {
    fn new(params: &MotionParams, width: u32, height: u32) -> Option<Self> {
        let (width, height) = (width as usize, height as usize);
        let f = if params.max_width == 0 {
            1
        } else {
            width.div_ceil(params.max_width as usize).max(1)
        };
        let (w, h) = (width / f, height / f);
        if w < MIN_COLUMNS || h < MIN_WINDOW_ROWS {
            return None;
        }
        let wanted = if params.bands == 0 {
            (h / 32).clamp(2, 16)
        } else {
            params.bands as usize
        };
        let n = wanted.min(2 * h / MIN_WINDOW_ROWS - 1).max(1);
        let step = h as f64 / (n + 1) as f64;
        let hw = ((2.0 * step).round() as usize).clamp(MIN_WINDOW_ROWS.min(h), h);
        let starts = (0..n)
            .map(|b| ((b as f64 * step).round() as usize).min(h - hw))
            .collect();
        let (fw, fh) = (smooth_size(w), smooth_size(hw));
        let rx = ((params.max_shift * w as f64) as usize).min(fw / 2 - 2);
        let ry = (hw / 3).min(fh / 2 - 2);
        Some(Self {
            f,
            w,
            h,
            fw,
            fh,
            hw,
            starts,
            rx,
            ry,
            wx: tukey(w),
            wy: hann(hw),
            plans: Plans::new(fw, fh),
        })
    }
}

/// The four FFT plans of a 2-D size.
#[derive(Clone)]
struct Plans {
    row_fwd: Arc<dyn Fft<f32>>,
    row_inv: Arc<dyn Fft<f32>>,
    col_fwd: Arc<dyn Fft<f32>>,
    col_inv: Arc<dyn Fft<f32>>,
}

impl Plans {
    fn new(fw: usize, fh: usize) -> Self {
        thread_local! {
            static PLANNER: RefCell<FftPlanner<f32>> = RefCell::new(FftPlanner::new());
        }
        PLANNER.with(|p| {
            let mut p = p.borrow_mut();
            Self {
                row_fwd: p.plan_fft_forward(fw),
                row_inv: p.plan_fft_inverse(fw),
                col_fwd: p.plan_fft_forward(fh),
                col_inv: p.plan_fft_inverse(fh),
            }
        })
    }

    fn scratch_len(&self) -> usize {
        [&self.row_fwd, &self.row_inv, &self.col_fwd, &self.col_inv]
            .iter()
            .map(|p| p.get_inplace_scratch_len())
            .max()
            .unwrap_or(0)
    }
}

/// A 2-D FFT of `fw x fh` with its buffers. Spectra are kept transposed (`fw` rows of `fh`),
/// which the element-wise cross-power does not mind and which saves a transpose each way.
struct Fft2 {
    fw: usize,
    fh: usize,
    plans: Plans,
    /// Spatial plane, `fh` rows of `fw`.
    buf: Vec<Complex32>,
    scratch: Vec<Complex32>,
}

impl Fft2 {
    fn new(fw: usize, fh: usize, plans: Plans) -> Self {
        let scratch = vec![Complex32::default(); plans.scratch_len()];
        Self {
            fw,
            fh,
            plans,
            buf: vec![Complex32::default(); fw * fh],
            scratch,
        }
    }

    /// The spectrum of `buf` (whose rows from `rows` on are zero) into `out` (transposed).
    fn forward(&mut self, rows: usize, out: &mut [Complex32]) {
        let fw = self.fw;
        self.plans
            .row_fwd
            .process_with_scratch(&mut self.buf[..rows * fw], &mut self.scratch);
        transpose::transpose(&self.buf, out, fw, self.fh);
        self.plans
            .col_fwd
            .process_with_scratch(out, &mut self.scratch);
    }

    /// The inverse of the transposed spectrum `spec` (overwritten) into `buf`, unnormalised,
    /// computing only the rows whose vertical lag is within `ry` (and one more for the
    /// sub-pixel fit).
    fn inverse(&mut self, spec: &mut [Complex32], ry: usize) {
        let (fw, fh) = (self.fw, self.fh);
        self.plans
            .col_inv
            .process_with_scratch(spec, &mut self.scratch);
        transpose::transpose(spec, &mut self.buf, fh, fw);
        let low = (ry + 2).min(fh);
        let high = fh.saturating_sub(ry + 2).max(low);
        for rows in [0..low, high..fh] {
            if !rows.is_empty() {
                self.plans.row_inv.process_with_scratch(
                    &mut self.buf[rows.start * fw..rows.end * fw],
                    &mut self.scratch,
                );
            }
        }
    }
}

/// One band's FFT, its spectrum of the previous frame and of this one.
struct BandWork {
    fft: Fft2,
    prev: Vec<Complex32>,
    cur: Vec<Complex32>,
    cross: Vec<Complex32>,
}

impl BandWork {
    fn new(layout: &Layout) -> Self {
        let n = layout.fw * layout.fh;
        Self {
            fft: Fft2::new(layout.fw, layout.fh, layout.plans.clone()),
            prev: vec![Complex32::default(); n],
            cur: vec![Complex32::default(); n],
            cross: vec![Complex32::default(); n],
        }
    }

    /// Takes band `b` of the reduced frame `cur` and measures its displacement from `prev`.
    fn push(
        &mut self,
        layout: &Layout,
        b: usize,
        cur: &[f32],
        prev: &[f32],
        has_prev: bool,
    ) -> Option<BandShift> {
        let (w, fw) = (layout.w, layout.fw);
        let y0 = layout.starts[b];
        let rows = &cur[y0 * w..(y0 + layout.hw) * w];
        load_windowed(rows, w, &layout.wx, &layout.wy, fw, &mut self.fft.buf);
        self.fft.forward(layout.hw, &mut self.cur);
        std::mem::swap(&mut self.prev, &mut self.cur);
        if !has_prev {
            return None;
        }
        // `prev` now holds this frame's spectrum, `cur` the previous frame's.
        let total = whiten(&self.prev, &self.cur, &mut self.cross);
        if total <= 0.0 {
            return None;
        }
        self.fft.inverse(&mut self.cross, layout.ry);
        let peaks = find_peak(&self.fft.buf, fw, layout.fh, layout.rx, layout.ry, total)?;
        let level = Level {
            data: cur,
            w,
            h: layout.h,
        };
        let prev_level = Level {
            data: prev,
            w,
            h: layout.h,
        };
        let (fit, peak) = refine_peaks(&peaks, |d0, passes| {
            refine(
                &prev_level,
                &level,
                0..w,
                y0..y0 + layout.hw,
                &layout.wx,
                &layout.wy,
                (0.0, 0.0),
                d0,
                passes,
            )
        })?;
        band_shift(&fit, &peak, layout.f as f64, (0.0, 0.0))
    }
}

/// A peak of a correlation plane.
#[derive(Debug, Clone, Copy)]
struct PeakInfo {
    /// Sub-pixel displacement (parabola through the neighbours).
    dx: f64,
    dy: f64,
    /// Peak over the ideal peak (the sum of the cross-power's weights).
    strength: f64,
}

/// Refined displacement of a window and its covariance, in pixels of the level it was refined
/// at.
#[derive(Debug, Clone, Copy)]
struct Fit {
    dx: f64,
    dy: f64,
    /// Covariance (xx, xy, yy).
    cov: [f64; 3],
    /// Centre row (weighted by the horizontal gradients' energy), in the level's rows.
    row: f64,
    /// Robust scale of the residuals at the start (grey levels, from the first pass, before
    /// any step: comparable between candidate peaks).
    scale: f32,
    /// Window weight of the residuals by magnitude at the start, in quarters of a grey level.
    hist: [f32; 256],
}

impl Fit {
    /// Window weight of the pixels whose residual is under `t` grey levels.
    fn support(&self, t: f32) -> f32 {
        let bins = ((t * 4.0) as usize).min(256);
        self.hist[..bins].iter().sum()
    }
}

/// The band's result in full-resolution pixels (the level reduced by `f`; `origin` the
/// level's top-left corner), when the refinement stayed near the correlation peak.
fn band_shift(fit: &Fit, peak: &PeakInfo, f: f64, origin: (f64, f64)) -> Option<BandShift> {
    if (fit.dx - peak.dx).hypot(fit.dy - peak.dy) > MAX_REFINE_STEP || peak.strength < MIN_STRENGTH
    {
        return None;
    }
    let var = 0.5 * (fit.cov[0] + fit.cov[2]);
    let sigma = (SIGMA_SCALE * var.max(0.0).sqrt()).hypot(SIGMA_FLOOR) * f;
    let shift = BandShift {
        row: origin.1 + f * (fit.row + 0.5) - 0.5,
        dx: f * fit.dx,
        dy: f * fit.dy,
        sigma,
        strength: peak.strength.clamp(0.0, 1.0),
    };
    [shift.row, shift.dx, shift.dy, shift.sigma]
        .iter()
        .all(|v| v.is_finite())
        .then_some(shift)
}

/// The next size at least `n` whose only prime factors are 2, 3 and 5 (fast FFTs).
fn smooth_size(n: usize) -> usize {
    let mut m = n.max(1);
    loop {
        let mut r = m;
        for p in [2, 3, 5] {
            while r.is_multiple_of(p) {
                r /= p;
            }
        }
        if r == 1 {
            return m;
        }
        m += 1;
    }
}

/// A Hann window of `n` values (none zero: the centres of `n` cells).
fn hann(n: usize) -> Vec<f32> {
    (0..n)
        .map(|i| {
            let t = (i as f64 + 0.5) / n as f64;
            (0.5 - 0.5 * (std::f64::consts::TAU * t).cos()) as f32
        })
        .collect()
}

/// A Tukey window of `n` values: flat in the middle, a half cosine over [`TAPER`] of `n` at
/// each end.
fn tukey(n: usize) -> Vec<f32> {
    let edge = (TAPER * n as f64).max(1.0);
    (0..n)
        .map(|i| {
            let d = (i as f64 + 0.5).min(n as f64 - i as f64 - 0.5);
            if d >= edge {
                1.0
            } else {
                (0.5 - 0.5 * (std::f64::consts::PI * d / edge).cos()) as f32
            }
        })
        .collect()
}

/// `rows` (`w` columns) less their weighted mean, times the window, into the first rows of the
/// `fw`-wide plane `out`; the rest of `out` zero.
fn load_windowed(rows: &[f32], w: usize, wx: &[f32], wy: &[f32], fw: usize, out: &mut [Complex32]) {
    let (mut sum, mut weight) = (0.0f64, 0.0f64);
    for (row, &ry) in rows.chunks_exact(w).zip(wy) {
        let s: f32 = row.iter().zip(wx).map(|(&v, &x)| v * x).sum();
        sum += f64::from(s * ry);
        weight += f64::from(ry);
    }
    let wx_sum: f64 = wx.iter().map(|&v| f64::from(v)).sum();
    let mean = (sum / (weight * wx_sum).max(f64::MIN_POSITIVE)) as f32;
    out.fill(Complex32::default());
    for ((row, &ry), o) in rows.chunks_exact(w).zip(wy).zip(out.chunks_exact_mut(fw)) {
        for ((o, &v), &x) in o.iter_mut().zip(row).zip(wx) {
            o.re = (v - mean) * x * ry;
        }
    }
}

/// The regularised whitened cross-power `a conj(b) / (|a||b| + eps)` into `out`; returns the
/// sum of its magnitudes (the height of a perfect peak; 0 when either spectrum is empty).
fn whiten(a: &[Complex32], b: &[Complex32], out: &mut [Complex32]) -> f32 {
    let mut sum = 0.0f64;
    for ((o, x), y) in out.iter_mut().zip(a).zip(b) {
        let c = x * y.conj();
        let m = c.norm();
        o.re = c.re;
        o.im = m;
        sum += f64::from(m);
    }
    if sum.is_nan() || sum <= 0.0 || !sum.is_finite() {
        return 0.0;
    }
    let eps = (WHITEN_EPS as f64 * sum / out.len() as f64) as f32;
    let mut total = 0.0f64;
    for (o, (x, y)) in out.iter_mut().zip(a.iter().zip(b)) {
        let m = o.im;
        let scale = 1.0 / (m + eps);
        *o = x * y.conj() * scale;
        total += f64::from(m * scale);
    }
    total as f32
}

/// `i` modulo `n` for `i` within one period either side.
#[inline]
fn wrap(i: isize, n: usize) -> usize {
    let n = n as isize;
    (if i < 0 {
        i + n
    } else if i >= n {
        i - n
    } else {
        i
    }) as usize
}

/// The two highest local maxima of a correlation plane.
#[derive(Debug, Clone, Copy)]
struct Peaks {
    best: PeakInfo,
    /// The highest other local maximum (outside the square around the best) and its height
    /// over the best's.
    second: Option<(PeakInfo, f64)>,
}

/// The highest peak of the unnormalised plane (`fh` rows of `fw`, real parts) within `rx`,
/// `ry` of zero lag, when it stands out: its peak-to-sidelobe ratio at least [`MIN_PSR`]; and
/// the next local maximum. `total` is the height of a perfect peak.
fn find_peak(
    plane: &[Complex32],
    fw: usize,
    fh: usize,
    rx: usize,
    ry: usize,
    total: f32,
) -> Option<Peaks> {
    let (rx, ry) = (rx as isize, ry as isize);
    let at = |dx: isize, dy: isize| plane[wrap(dy, fh) * fw + wrap(dx, fw)].re;
    let mut best = (f32::NEG_INFINITY, 0isize, 0isize);
    for dy in -ry..=ry {
        let row = &plane[wrap(dy, fh) * fw..][..fw];
        for dx in -rx..=rx {
            let v = row[wrap(dx, fw)].re;
            if v > best.0 {
                best = (v, dx, dy);
            }
        }
    }
    let (peak, px, py) = best;
    if peak.is_nan() || peak <= 0.0 {
        return None;
    }
    let (mut sum, mut sum_sq, mut count) = (0.0f64, 0.0f64, 0usize);
    let mut second = (0.0f32, 0isize, 0isize);
    for dy in -ry..=ry {
        for dx in -rx..=rx {
            if (dx - px).abs() <= PEAK_EXCLUSION && (dy - py).abs() <= PEAK_EXCLUSION {
                continue;
            }
            let v = at(dx, dy);
            sum += f64::from(v);
            sum_sq += f64::from(v) * f64::from(v);
            count += 1;
            if v > second.0
                && v >= at(dx - 1, dy)
                && v >= at(dx + 1, dy)
                && v >= at(dx, dy - 1)
                && v >= at(dx, dy + 1)
            {
                second = (v, dx, dy);
            }
        }
    }
    if count >= 2 {
        let mean = sum / count as f64;
        let sd = (sum_sq / count as f64 - mean * mean).max(0.0).sqrt();
        let psr = (f64::from(peak) - mean) / sd.max(1e-12 * f64::from(total));
        if psr < MIN_PSR {
            return None;
        }
    }
    let vertex = |a: f32, b: f32, c: f32| {
        let den = a - 2.0 * b + c;
        if den < 0.0 {
            f64::from((0.5 * (a - c) / den).clamp(-0.5, 0.5))
        } else {
            0.0
        }
    };
    let info = |v: f32, x: isize, y: isize| PeakInfo {
        dx: x as f64 + vertex(at(x - 1, y), v, at(x + 1, y)),
        dy: y as f64 + vertex(at(x, y - 1), v, at(x, y + 1)),
        strength: f64::from(v / total),
    };
    Some(Peaks {
        best: info(peak, px, py),
        second: (second.0 > 0.0).then(|| {
            (
                info(second.0, second.1, second.2),
                f64::from(second.0 / peak),
            )
        }),
    })
}

/// Refines the best peak, and weighs the second when it is high enough to be another motion
/// (a subject in front of the background) or a repeat of the texture: the alignment that
/// explains more of the window (residuals within 3 robust sigmas, both read at their peaks
/// before any step) is refined; a window whose peaks are close in height and explain about as
/// much is refused (repetitive texture). `run(d0, passes)` refines from `d0`.
fn refine_peaks(
    peaks: &Peaks,
    run: impl Fn((f64, f64), usize) -> Option<Fit>,
) -> Option<(Fit, PeakInfo)> {
    let best = run((peaks.best.dx, peaks.best.dy), PASSES).map(|f| (f, peaks.best));
    let Some((second, ratio)) = peaks.second.filter(|s| s.1 >= MIN_RIVAL) else {
        return best;
    };
    let other = run((second.dx, second.dy), 1);
    match (best, other) {
        (Some(a), Some(b)) => {
            let t = 3.0 * a.0.scale.min(b.scale);
            let (sa, sb) = (a.0.support(t), b.support(t));
            if ratio > MAX_AMBIGUITY && sa.max(sb) < 1.25 * sa.min(sb) {
                return None;
            }
            if sb > sa {
                run((second.dx, second.dy), PASSES).map(|f| (f, second))
            } else {
                Some(a)
            }
        }
        (Some(a), None) => (ratio <= MAX_AMBIGUITY).then_some(a),
        (None, Some(_)) if ratio > MAX_AMBIGUITY => {
            run((second.dx, second.dy), PASSES).map(|f| (f, second))
        }
        _ => None,
    }
}

/// A grey image as `f32`, row-major.
struct Level<'a> {
    data: &'a [f32],
    w: usize,
    h: usize,
}

/// Refines the displacement `d0` of the window `xs x ys` of `prev` in `cur` by Gauss-Newton
/// with Tukey biweights: minimises `sum w (cur(p + off + d) - prev(p))^2` over the window's
/// pixels `p` (bilinear in `cur`; `off` is `cur`'s offset, the position in `cur` of `prev`'s
/// origin less its own origin), weighted by `wx`, `wy` (indexed from the window's start).
#[allow(clippy::too_many_arguments)]
fn refine(
    prev: &Level,
    cur: &Level,
    xs: Range<usize>,
    ys: Range<usize>,
    wx: &[f32],
    wy: &[f32],
    off: (f64, f64),
    d0: (f64, f64),
    passes: usize,
) -> Option<Fit> {
    let (mut dx, mut dy) = d0;
    let mut scale: Option<f32> = None;
    let mut fit = None;
    let mut first: Option<(f32, [f32; 256])> = None;
    for iteration in 0..passes {
        let sx = off.0 + dx;
        let sy = off.1 + dy;
        let (ix, iy) = (sx.floor(), sy.floor());
        let (fx, fy) = ((sx - ix) as f32, (sy - iy) as f32);
        let (ix, iy) = (ix as isize, iy as isize);
        // Pixels with both neighbours in `prev` and a 2 x 2 cell in `cur`.
        let lo = |start: usize, i: isize| (start as isize).max(1).max(-i);
        let hi = |end: usize, n: usize, i: isize| {
            (end as isize).min(n as isize - 1).min(n as isize - 1 - i)
        };
        let (x0, x1) = (
            lo(xs.start, ix),
            hi(xs.end, prev.w, 0).min(hi(xs.end, cur.w, ix)),
        );
        let (y0, y1) = (
            lo(ys.start, iy),
            hi(ys.end, prev.h, 0).min(hi(ys.end, cur.h, iy)),
        );
        if x1 - x0 < 4 || y1 - y0 < 4 {
            return None;
        }
        let (x0, x1, y0, y1) = (x0 as usize, x1 as usize, y0 as usize, y1 as usize);
        let (w00, w10, w01, w11) = (
            (1.0 - fx) * (1.0 - fy),
            fx * (1.0 - fy),
            (1.0 - fx) * fy,
            fx * fy,
        );
        // 1 / the biweight's cut-off (0 on the first pass: all weights 1).
        let inv_c = scale.map_or(0.0, |s| 1.0 / (BIWEIGHT_C * s));
        let mut hist = [0f32; 256];
        let mut s = Sums::default();
        for y in y0..y1 {
            let wyv = wy[y - ys.start];
            if wyv <= 0.0 {
                continue;
            }
            let p = &prev.data[y * prev.w..][..prev.w];
            let pu = &prev.data[(y - 1) * prev.w..][..prev.w];
            let pd = &prev.data[(y + 1) * prev.w..][..prev.w];
            let cy = (y as isize + iy) as usize;
            let c0 = &cur.data[cy * cur.w..][..cur.w];
            let c1 = &cur.data[(cy + 1) * cur.w..][..cur.w];
            let n = x1 - x0;
            let cx0 = (x0 as isize + ix) as usize;
            let (pc, pl, pr) = (&p[x0..x1], &p[x0 - 1..x1 - 1], &p[x0 + 1..x1 + 1]);
            let (pu, pd) = (&pu[x0..x1], &pd[x0..x1]);
            let (a0, a1) = (&c0[cx0..cx0 + n], &c0[cx0 + 1..cx0 + 1 + n]);
            let (b0, b1) = (&c1[cx0..cx0 + n], &c1[cx0 + 1..cx0 + 1 + n]);
            let wxs = &wx[x0 - xs.start..x1 - xs.start];
            // The residuals' magnitudes, on every other pixel of every other row (the robust
            // scale and the support need only their distribution).
            if y % 2 == 0 {
                for i in (0..n).step_by(4) {
                    let v = w00 * a0[i] + w10 * a1[i] + w01 * b0[i] + w11 * b1[i];
                    hist[(((v - pc[i]).abs() * 4.0) as usize).min(255)] += wxs[i] * wyv;
                }
            }
            // Lanes of independent sums, which the compiler vectorises.
            let mut acc = [[0f32; LANES]; 10];
            let rows = RowSlices {
                a0,
                a1,
                b0,
                b1,
                pc,
                pl,
                pr,
                pu,
                pd,
                wx: wxs,
            };
            let coef = [w00, w10, w01, w11, inv_c];
            let whole = n - n % LANES;
            for k in (0..whole).step_by(LANES) {
                accumulate_lanes(&rows, k, &coef, &mut acc);
            }
            for i in whole..n {
                let mut one = [[0f32; LANES]; 10];
                accumulate_one(&rows, i, &coef, &mut one);
                for (a, o) in acc.iter_mut().zip(&one) {
                    a[0] += o[0];
                }
            }
            let total = |q: usize| acc[q].iter().sum::<f32>();
            let row = RowSums {
                hxx: total(0),
                hxy: total(1),
                hyy: total(2),
                bx: total(3),
                by: total(4),
                gxx: total(5),
                gxy: total(6),
                gyy: total(7),
                rr: total(8),
                w: total(9),
            };
            s.add_row(&row, wyv, y as f64);
        }
        let robust_scale = median_of_histogram(&hist).max(0.5) * 1.4826;
        scale = Some(robust_scale);
        let det = s.hxx * s.hyy - s.hxy * s.hxy;
        let trace = s.hxx + s.hyy;
        if det.is_nan() || det <= 1e-9 * trace * trace || s.w.is_nan() || s.w <= 0.0 {
            return None;
        }
        let inv = [s.hyy / det, -s.hxy / det, s.hxx / det];
        // The first pass only measures the residuals' scale (its unweighted step would follow
        // a subject moving otherwise as much as the background).
        let (step_x, step_y) = if iteration == 0 && passes > 1 {
            (0.0, 0.0)
        } else {
            (
                -(inv[0] * s.bx + inv[1] * s.by),
                -(inv[1] * s.bx + inv[2] * s.by),
            )
        };
        // Covariance: residual variance through the sandwich of the weights.
        let var = s.rr / s.w;
        let g = [s.gxx, s.gxy, s.gyy];
        let m = sandwich(&inv, &g);
        fit = Some(Fit {
            dx: dx + step_x,
            dy: dy + step_y,
            cov: [var * m[0], var * m[1], var * m[2]],
            row: if s.hxx > 0.0 {
                s.row / s.hxx
            } else {
                (ys.start + ys.end) as f64 / 2.0
            },
            scale: first.map_or(robust_scale, |f| f.0),
            hist: first.map_or(hist, |f| f.1),
        });
        if first.is_none() {
            first = Some((robust_scale, hist));
        }
        dx += step_x;
        dy += step_y;
        if !(dx.is_finite() && dy.is_finite())
            || (dx - d0.0).hypot(dy - d0.1) > 2.0 * MAX_REFINE_STEP
        {
            return None;
        }
        if iteration >= 2 && step_x.hypot(step_y) < 5e-3 {
            break;
        }
    }
    fit
}

/// The rows a refinement pass reads for one row of its window, cut to the same length.
struct RowSlices<'a> {
    /// `cur`'s two rows under the shifted row, at the left and right columns of each cell.
    a0: &'a [f32],
    a1: &'a [f32],
    b0: &'a [f32],
    b1: &'a [f32],
    /// `prev`'s row, its left and right neighbours, the rows above and below.
    pc: &'a [f32],
    pl: &'a [f32],
    pr: &'a [f32],
    pu: &'a [f32],
    pd: &'a [f32],
    /// Window weights along the row.
    wx: &'a [f32],
}

/// Adds pixels `k..k + LANES` to the lanes of `acc` (`coef`: the bilinear weights and 1 / the
/// biweight cut-off).
#[inline(always)]
fn accumulate_lanes(s: &RowSlices, k: usize, coef: &[f32; 5], acc: &mut [[f32; LANES]; 10]) {
    let lane = |v: &[f32]| -> [f32; LANES] { v[k..k + LANES].try_into().unwrap_or([0.0; LANES]) };
    let (a0, a1, b0, b1) = (lane(s.a0), lane(s.a1), lane(s.b0), lane(s.b1));
    let (pc, pl, pr, pu, pd, wx) = (
        lane(s.pc),
        lane(s.pl),
        lane(s.pr),
        lane(s.pu),
        lane(s.pd),
        lane(s.wx),
    );
    let [w00, w10, w01, w11, inv_c] = *coef;
    for l in 0..LANES {
        let v = w00 * a0[l] + w10 * a1[l] + w01 * b0[l] + w11 * b1[l];
        let r = v - pc[l];
        let gx = 0.5 * (pr[l] - pl[l]);
        let gy = 0.5 * (pd[l] - pu[l]);
        let u = r * inv_c;
        let t = (1.0 - u * u).max(0.0);
        let w = wx[l] * t * t;
        let (wgx, wgy) = (w * gx, w * gy);
        acc[0][l] += wgx * gx;
        acc[1][l] += wgx * gy;
        acc[2][l] += wgy * gy;
        acc[3][l] += wgx * r;
        acc[4][l] += wgy * r;
        acc[5][l] += wgx * wgx;
        acc[6][l] += wgx * wgy;
        acc[7][l] += wgy * wgy;
        acc[8][l] += w * r * r;
        acc[9][l] += w;
    }
}

/// Adds pixel `i` to lane 0 of `acc` (the row's last few pixels).
fn accumulate_one(s: &RowSlices, i: usize, coef: &[f32; 5], acc: &mut [[f32; LANES]; 10]) {
    let [w00, w10, w01, w11, inv_c] = *coef;
    let v = w00 * s.a0[i] + w10 * s.a1[i] + w01 * s.b0[i] + w11 * s.b1[i];
    let r = v - s.pc[i];
    let gx = 0.5 * (s.pr[i] - s.pl[i]);
    let gy = 0.5 * (s.pd[i] - s.pu[i]);
    let u = r * inv_c;
    let t = (1.0 - u * u).max(0.0);
    let w = s.wx[i] * t * t;
    let (wgx, wgy) = (w * gx, w * gy);
    let add = [
        wgx * gx,
        wgx * gy,
        wgy * gy,
        wgx * r,
        wgy * r,
        wgx * wgx,
        wgx * wgy,
        wgy * wgy,
        w * r * r,
        w,
    ];
    for (a, v) in acc.iter_mut().zip(add) {
        a[0] += v;
    }
}

/// `A G A` for symmetric 2 x 2 matrices given as (xx, xy, yy).
fn sandwich(a: &[f64; 3], g: &[f64; 3]) -> [f64; 3] {
    // A G
    let ag = [
        a[0] * g[0] + a[1] * g[1],
        a[0] * g[1] + a[1] * g[2],
        a[1] * g[0] + a[2] * g[1],
        a[1] * g[1] + a[2] * g[2],
    ];
    [
        ag[0] * a[0] + ag[1] * a[1],
        ag[0] * a[1] + ag[1] * a[2],
        ag[2] * a[1] + ag[3] * a[2],
    ]
}

/// The weighted median of the values binned by quarters (`hist[i]`: the weight of the values
/// in `[i/4, (i+1)/4)`).
fn median_of_histogram(hist: &[f32; 256]) -> f32 {
    let total: f64 = hist.iter().map(|&h| f64::from(h)).sum();
    let mut acc = 0f64;
    for (i, &h) in hist.iter().enumerate() {
        acc += f64::from(h);
        if 2.0 * acc >= total {
            return (i as f32 + 0.5) / 4.0;
        }
    }
    64.0
}

/// One row's weighted sums (in `f32`; rows are short).
struct RowSums {
    hxx: f32,
    hxy: f32,
    hyy: f32,
    bx: f32,
    by: f32,
    gxx: f32,
    gxy: f32,
    gyy: f32,
    rr: f32,
    w: f32,
}

/// The window's sums (rows weighted by `wy`).
#[derive(Default)]
struct Sums {
    hxx: f64,
    hxy: f64,
    hyy: f64,
    bx: f64,
    by: f64,
    gxx: f64,
    gxy: f64,
    gyy: f64,
    rr: f64,
    w: f64,
    row: f64,
}

impl Sums {
    fn add_row(&mut self, r: &RowSums, wy: f32, y: f64) {
        let (a, a2) = (f64::from(wy), f64::from(wy) * f64::from(wy));
        self.hxx += a * f64::from(r.hxx);
        self.hxy += a * f64::from(r.hxy);
        self.hyy += a * f64::from(r.hyy);
        self.bx += a * f64::from(r.bx);
        self.by += a * f64::from(r.by);
        self.gxx += a2 * f64::from(r.gxx);
        self.gxy += a2 * f64::from(r.gxy);
        self.gyy += a2 * f64::from(r.gyy);
        self.rr += a * f64::from(r.rr);
        self.w += a * f64::from(r.w);
        self.row += a * f64::from(r.hxx) * y;
    }
}

/// `gray` reduced by the whole factor `f` (block means of `f x f`, the last partial blocks
/// dropped) into `out`.
fn reduce_into(gray: &GrayImage, f: usize, out: &mut Vec<f32>) {
    let (iw, ih) = (gray.width() as usize, gray.height() as usize);
    let (w, h) = (iw / f, ih / f);
    out.clear();
    out.resize(w * h, 0.0);
    let raw = gray.as_raw();
    if f == 1 {
        for (o, &v) in out.iter_mut().zip(raw) {
            *o = f32::from(v);
        }
        return;
    }
    let norm = 1.0 / (f * f) as f32;
    let rows_per_task = (16384 / w.max(1)).max(1);
    out.par_chunks_mut(w * rows_per_task)
        .enumerate()
        .for_each_init(
            || vec![0u32; w * f],
            |acc, (task, chunk)| {
                for (j, o) in chunk.chunks_exact_mut(w).enumerate() {
                    let y = task * rows_per_task + j;
                    acc.fill(0);
                    for r in 0..f {
                        let row = &raw[(y * f + r) * iw..][..w * f];
                        for (a, &v) in acc.iter_mut().zip(row) {
                            *a += u32::from(v);
                        }
                    }
                    for (o, block) in o.iter_mut().zip(acc.chunks_exact(f)) {
                        *o = block.iter().sum::<u32>() as f32 * norm;
                    }
                }
            },
        );
}

/// The frame's displacement from its bands: a robust line `dx = a + b row` (repeated medians)
/// and the median `dy` decide which bands agree; the agreeing ones' inverse-variance mean is
/// the frame's.
fn combine(mut bands: Vec<BandShift>) -> Option<FrameShift> {
    if bands.is_empty() {
        return None;
    }
    bands.sort_by(|a, b| a.row.total_cmp(&b.row));
    let n = bands.len();
    let (a, b) = robust_line(&bands);
    let my = median(bands.iter().map(|s| s.dy).collect());
    let resid: Vec<f64> = bands
        .iter()
        .map(|s| (s.dx - a - b * s.row).hypot(s.dy - my))
        .collect();
    let spread = 1.4826 * median(resid.clone());
    let (mut kept, mut rejected) = (Vec::with_capacity(n), Vec::new());
    for (s, r) in bands.into_iter().zip(resid) {
        if r <= 4.0 * s.sigma.max(spread).max(0.25) {
            kept.push(s);
        } else {
            rejected.push(s);
        }
    }
    if kept.is_empty() {
        return None;
    }
    let (mut sw, mut sx, mut sy) = (0.0, 0.0, 0.0);
    for s in &kept {
        let w = 1.0 / (s.sigma * s.sigma).max(1e-12);
        sw += w;
        sx += w * s.dx;
        sy += w * s.dy;
    }
    let (dx, dy) = (sx / sw, sy / sw);
    let chi2: f64 = kept
        .iter()
        .map(|s| {
            ((s.dx - dx).powi(2) + (s.dy - dy).powi(2)) / (2.0 * (s.sigma * s.sigma).max(1e-12))
        })
        .sum();
    let dof = kept.len().saturating_sub(1).max(1) as f64;
    let sigma = (1.0 / sw).sqrt() * (chi2 / dof).max(1.0).sqrt();
    Some(FrameShift {
        bands: kept,
        rejected,
        dx,
        dy,
        sigma,
    })
}

/// Intercept and slope of `dx` against `row` by repeated medians (Siegel); the median `dx`
/// and slope 0 for a single band.
fn robust_line(bands: &[BandShift]) -> (f64, f64) {
    if bands.len() < 3 {
        return (median(bands.iter().map(|s| s.dx).collect()), 0.0);
    }
    let slopes: Vec<f64> = bands
        .iter()
        .map(|p| {
            median(
                bands
                    .iter()
                    .filter(|q| q.row != p.row)
                    .map(|q| (q.dx - p.dx) / (q.row - p.row))
                    .collect(),
            )
        })
        .collect();
    let b = median(slopes);
    let a = median(bands.iter().map(|s| s.dx - b * s.row).collect());
    (a, b)
}

/// The median of `v` (the mean of the middle two for an even count; 0 when empty).
fn median(mut v: Vec<f64>) -> f64 {
    v.retain(|x| x.is_finite());
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Largest side, in pixels, of the correlated patches of [`region_shift`]: larger regions are
/// reduced by a whole factor first (the refinement then runs at full resolution).
#[cfg(any(test, feature = "dev"))]
const REGION_MAX_SIDE: usize = 128;

/// Displacement of the content of `region` (e.g. a face box, full-resolution pixels of `prev`)
/// between `prev` and `cur`, searched within `radius` pixels of `guess` (`(dx, dy)`, e.g. the
/// last known velocity).
///
/// Phase correlation of the region with the same box moved by `guess` in `cur`, then the
/// refinement at full resolution; `row` of the result is the region's textured centre row.
/// `None` when the images differ in size, the region lies (mostly) outside `prev`, an argument
/// is not finite, or the peak is not clear.
#[cfg(any(test, feature = "dev"))]
pub fn region_shift(
    prev: &GrayImage,
    cur: &GrayImage,
    region: Rect,
    guess: (f64, f64),
    radius: f64,
) -> Option<BandShift> {
    if prev.dimensions() != cur.dimensions()
        || ![
            region.x,
            region.y,
            region.width,
            region.height,
            guess.0,
            guess.1,
            radius,
        ]
        .iter()
        .all(|v| v.is_finite())
        || radius < 0.0
    {
        return None;
    }
    let (iw, ih) = (prev.width() as f64, prev.height() as f64);
    let x0 = region.x.max(1.0).floor();
    let y0 = region.y.max(1.0).floor();
    let x1 = (region.x + region.width).min(iw - 1.0).ceil();
    let y1 = (region.y + region.height).min(ih - 1.0).ceil();
    if !(x1 - x0 >= 16.0 && y1 - y0 >= 16.0) {
        return None;
    }
    let (x0, y0, rw, rh) = (
        x0 as usize,
        y0 as usize,
        (x1 - x0) as usize,
        (y1 - y0) as usize,
    );
    let g = (guess.0.round(), guess.1.round());
    if g.0.abs() > iw || g.1.abs() > ih {
        return None;
    }
    let (gx, gy) = (g.0 as isize, g.1 as isize);
    // Coarse: phase correlation of the (reduced) region and the box moved by the guess.
    let f = rw.max(rh).div_ceil(REGION_MAX_SIDE).max(1);
    let (pw, ph) = (rw / f, rh / f);
    if pw < 8 || ph < 8 {
        return None;
    }
    let a = crop_reduced(prev, x0 as isize, y0 as isize, pw, ph, f);
    let b = crop_reduced(cur, x0 as isize + gx, y0 as isize + gy, pw, ph, f);
    let (fw, fh) = (smooth_size(pw), smooth_size(ph));
    let plans = Plans::new(fw, fh);
    let mut fft = Fft2::new(fw, fh, plans);
    let (wx, wy) = (hann(pw), hann(ph));
    let n = fw * fh;
    let mut spec_a = vec![Complex32::default(); n];
    let mut spec_b = vec![Complex32::default(); n];
    let mut cross = vec![Complex32::default(); n];
    load_windowed(&a, pw, &wx, &wy, fw, &mut fft.buf);
    fft.forward(ph, &mut spec_a);
    load_windowed(&b, pw, &wx, &wy, fw, &mut fft.buf);
    fft.forward(ph, &mut spec_b);
    let total = whiten(&spec_b, &spec_a, &mut cross);
    if total <= 0.0 {
        return None;
    }
    let reach = (radius / f as f64).ceil() as usize + 1;
    let rx = reach.min(fw / 2 - 2);
    let ry = reach.min(fh / 2 - 2);
    fft.inverse(&mut cross, ry);
    let peaks = find_peak(&fft.buf, fw, fh, rx, ry, total)?;
    if peaks.second.is_some_and(|s| s.1 > MAX_AMBIGUITY) {
        return None;
    }
    let peak = peaks.best;
    let coarse = (g.0 + f as f64 * peak.dx, g.1 + f as f64 * peak.dy);
    if (coarse.0 - guess.0).hypot(coarse.1 - guess.1) > radius + f as f64 {
        return None;
    }
    // Fine: Gauss-Newton at full resolution, `cur` cut around the coarse position.
    let margin = 2 * (MAX_REFINE_STEP.ceil() as usize + 2);
    let (cx0, cy0) = (
        x0 as isize + coarse.0.round() as isize - margin as isize,
        y0 as isize + coarse.1.round() as isize - margin as isize,
    );
    let (pa, pbw, pbh) = (
        crop_reduced(prev, x0 as isize - 1, y0 as isize - 1, rw + 2, rh + 2, 1),
        rw + 2 * margin,
        rh + 2 * margin,
    );
    let pb = crop_reduced(cur, cx0, cy0, pbw, pbh, 1);
    let prev_level = Level {
        data: &pa,
        w: rw + 2,
        h: rh + 2,
    };
    let cur_level = Level {
        data: &pb,
        w: pbw,
        h: pbh,
    };
    // `prev_level`'s origin is (x0 - 1, y0 - 1); `cur_level`'s is (cx0, cy0).
    let off = (
        (x0 as isize - 1 - cx0) as f64,
        (y0 as isize - 1 - cy0) as f64,
    );
    let (fwx, fwy) = (hann(rw + 2), hann(rh + 2));
    let fit = refine(
        &prev_level,
        &cur_level,
        0..rw + 2,
        0..rh + 2,
        &fwx,
        &fwy,
        off,
        coarse,
        PASSES,
    )?;
    let peak_full = PeakInfo {
        dx: coarse.0,
        dy: coarse.1,
        strength: peak.strength,
    };
    band_shift(&fit, &peak_full, 1.0, (0.0, y0 as f64 - 1.0))
        .filter(|s| (s.dx - guess.0).hypot(s.dy - guess.1) <= radius + 1.0)
}

/// The `w x h` window of `gray` at `(x0, y0)` reduced by `f` (block means), as `f32`, with
/// pixels outside the image replaced by the nearest edge pixel.
#[cfg(any(test, feature = "dev"))]
fn crop_reduced(gray: &GrayImage, x0: isize, y0: isize, w: usize, h: usize, f: usize) -> Vec<f32> {
    let (iw, ih) = (gray.width() as isize, gray.height() as isize);
    let raw = gray.as_raw();
    let mut out = vec![0.0f32; w * h];
    let norm = 1.0 / (f * f) as f32;
    for (j, o_row) in out.chunks_exact_mut(w).enumerate() {
        for r in 0..f {
            let y = (y0 + (j * f + r) as isize).clamp(0, ih - 1) as usize;
            let row = &raw[y * iw as usize..][..iw as usize];
            for (i, o) in o_row.iter_mut().enumerate() {
                for c in 0..f {
                    let x = (x0 + (i * f + c) as isize).clamp(0, iw - 1) as usize;
                    *o += f32::from(row[x]);
                }
            }
        }
        for o in o_row.iter_mut() {
            *o *= norm;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;
    use image::Luma;

    /// A textured scene: blobs of many sizes and a fine grain, `w x h`, sampled bicubically.
    struct Scene {
        w: usize,
        h: usize,
        data: Vec<f32>,
    }

    impl Scene {
        fn new(w: usize, h: usize, seed: u64) -> Self {
            let mut rng = SplitMix64::new(seed);
            let mut data = vec![128.0f32; w * h];
            for _ in 0..(w * h / 500) {
                let (cx, cy) = (rng.next_f64() * w as f64, rng.next_f64() * h as f64);
                let s = 2.0 + 18.0 * rng.next_f64().powi(2);
                let a = rng.symmetric(45.0) as f32;
                let r = (3.0 * s).ceil() as isize;
                for y in (cy as isize - r).max(0)..(cy as isize + r).min(h as isize) {
                    for x in (cx as isize - r).max(0)..(cx as isize + r).min(w as isize) {
                        let d2 = (x as f64 - cx).powi(2) + (y as f64 - cy).powi(2);
                        data[y as usize * w + x as usize] += a * (-d2 / (2.0 * s * s)).exp() as f32;
                    }
                }
            }
            // A fine grain: white noise smoothed by a 3 x 3 box.
            let grain: Vec<f32> = (0..w * h).map(|_| rng.symmetric(30.0) as f32).collect();
            for y in 1..h - 1 {
                for x in 1..w - 1 {
                    let mut s = 0.0;
                    for j in 0..3 {
                        for i in 0..3 {
                            s += grain[(y + j - 1) * w + x + i - 1];
                        }
                    }
                    data[y * w + x] += s / 9.0;
                }
            }
            Self { w, h, data }
        }

        /// Catmull-Rom at `(x, y)`, edges clamped.
        fn sample(&self, x: f64, y: f64) -> f32 {
            let (ix, iy) = (x.floor() as isize, y.floor() as isize);
            let (tx, ty) = ((x - x.floor()) as f32, (y - y.floor()) as f32);
            let k = |t: f32| {
                [
                    ((-0.5 * t + 1.0) * t - 0.5) * t,
                    (1.5 * t - 2.5) * t * t + 1.0,
                    ((-1.5 * t + 2.0) * t + 0.5) * t,
                    (0.5 * t - 0.5) * t * t,
                ]
            };
            let (kx, ky) = (k(tx), k(ty));
            let mut v = 0.0;
            for (j, wy) in ky.iter().enumerate() {
                let yy = (iy + j as isize - 1).clamp(0, self.h as isize - 1) as usize;
                let row = &self.data[yy * self.w..][..self.w];
                let mut s = 0.0;
                for (i, wx) in kx.iter().enumerate() {
                    s += wx * row[(ix + i as isize - 1).clamp(0, self.w as isize - 1) as usize];
                }
                v += wy * s;
            }
            v
        }
    }

    /// Gaussian noise of standard deviation `sd`.
    fn gauss(rng: &mut SplitMix64, sd: f64) -> f64 {
        let u = rng.next_f64().max(1e-300);
        let v = rng.next_f64();
        sd * (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    }

    /// A `w x h` frame whose pixel `(x, y)` shows the scene at `at(x, y)` (scene coordinates),
    /// box-blurred along the rows over `blur` pixels (the mean of `scene(at - t, ..)`,
    /// `t < blur`), plus noise.
    fn render(
        scene: &Scene,
        (w, h): (u32, u32),
        blur: usize,
        noise: f64,
        seed: u64,
        at: impl Fn(f64, f64) -> (f64, f64),
    ) -> GrayImage {
        let mut rng = SplitMix64::new(seed);
        let blur = blur.max(1);
        GrayImage::from_fn(w, h, |x, y| {
            let (sx, sy) = at(f64::from(x), f64::from(y));
            let mut v = 0.0;
            for t in 0..blur {
                v += scene.sample(sx - t as f64 + (blur as f64 - 1.0) / 2.0, sy);
            }
            let v = f64::from(v) / blur as f64
                + if noise > 0.0 {
                    gauss(&mut rng, noise)
                } else {
                    0.0
                };
            Luma([v.round().clamp(0.0, 255.0) as u8])
        })
    }

    const W: u32 = 960;
    const H: u32 = 540;
    const MARGIN: f64 = 400.0;

    fn scene() -> Scene {
        Scene::new(W as usize + 2 * MARGIN as usize, H as usize + 60, 7)
    }

    /// Frames `(prev, cur)` of the scene whose rows are displaced by `shift(y)` from `prev`
    /// to `cur`, both sheared by `k` about the middle row.
    fn pair(
        scene: &Scene,
        k: f64,
        blur: usize,
        noise: f64,
        seed: u64,
        shift: impl Fn(f64) -> (f64, f64),
    ) -> (GrayImage, GrayImage) {
        let c = f64::from(H) / 2.0;
        let base = move |x: f64, y: f64| (x + MARGIN - k * (y - c) - 150.0, y + 30.0);
        let a = render(scene, (W, H), blur, noise, seed, base);
        let b = render(scene, (W, H), blur, noise, seed + 1, |x, y| {
            let (dx, dy) = shift(y);
            let (sx, sy) = base(x - dx, y - dy);
            (sx, sy)
        });
        (a, b)
    }

    fn measure(a: &GrayImage, b: &GrayImage) -> Option<FrameShift> {
        let mut m = MotionEstimator::default();
        assert!(m.push(a).is_none());
        m.push(b)
    }

    #[test]
    fn pure_translations_are_measured_within_a_quarter_pixel() {
        let scene = scene();
        let mut worst = 0.0f64;
        for (i, &(dx, dy)) in [
            (0.0, 0.0),
            (3.3, -1.7),
            (57.25, 4.6),
            (-140.8, 2.2),
            (288.4, -3.1),
            (-0.45, 0.8),
        ]
        .iter()
        .enumerate()
        {
            let (a, b) = pair(&scene, 0.0, 1, 0.0, 10 + i as u64, |_| (dx, dy));
            let s = measure(&a, &b).expect("shift");
            assert!(s.bands.len() >= 6, "{dx} {dy}: {} bands", s.bands.len());
            for band in &s.bands {
                let e = (band.dx - dx).abs().max((band.dy - dy).abs());
                worst = worst.max(e);
            }
            eprintln!(
                "translation ({dx}, {dy}): frame ({:.3}, {:.3}) sigma {:.3}, bands {:?}",
                s.dx,
                s.dy,
                s.sigma,
                s.bands
                    .iter()
                    .map(|b| (b.dx - dx, b.dy - dy, b.sigma))
                    .collect::<Vec<_>>()
            );
            assert!((s.dx - dx).abs() < 0.25 && (s.dy - dy).abs() < 0.25);
        }
        eprintln!("worst band error {worst:.3}");
        assert!(worst < 0.25, "worst band error {worst}");
    }

    #[test]
    fn a_sheared_constant_pan_gives_the_same_shift_in_every_band() {
        let scene = scene();
        let (dx, dy) = (100.6, 0.0);
        let (a, b) = pair(&scene, 0.3, 1, 0.0, 20, |_| (dx, dy));
        let s = measure(&a, &b).expect("shift");
        let worst = s
            .bands
            .iter()
            .map(|b| (b.dx - dx).abs().max((b.dy - dy).abs()))
            .fold(0.0, f64::max);
        eprintln!(
            "sheared pan: {} bands, worst error {worst:.3}, frame ({:.3}, {:.3})",
            s.bands.len(),
            s.dx,
            s.dy
        );
        assert!(s.bands.len() >= 7 && s.rejected.is_empty());
        assert!(worst < 0.25);
    }

    #[test]
    fn motion_blur_and_noise_keep_the_error_within_half_a_pixel() {
        let scene = scene();
        for (i, &(dx, dy, blur)) in [(75.3, -2.4, 24), (-31.7, 1.2, 30), (160.2, 0.4, 20)]
            .iter()
            .enumerate()
        {
            let (a, b) = pair(&scene, 0.0, blur, 3.0, 30 + 2 * i as u64, |_| (dx, dy));
            let s = measure(&a, &b).expect("shift");
            let worst = s
                .bands
                .iter()
                .map(|b| (b.dx - dx).abs().max((b.dy - dy).abs()))
                .fold(0.0, f64::max);
            eprintln!(
                "blur {blur} + noise: {} bands, worst band error {worst:.3}, frame error ({:.3}, {:.3}) sigma {:.3}, band sigmas {:?}",
                s.bands.len(), s.dx - dx, s.dy - dy, s.sigma,
                s.bands.iter().map(|b| (b.sigma * 1000.0).round() / 1000.0).collect::<Vec<_>>()
            );
            assert!(s.bands.len() >= 6);
            assert!(worst < 0.5);
        }
    }

    #[test]
    fn a_speed_change_is_recovered_band_by_band() {
        let scene = scene();
        let (a0, b0) = (20.0, 0.06);
        let (a, b) = pair(&scene, 0.1, 1, 1.0, 40, |y| (a0 + b0 * y, 0.0));
        let s = measure(&a, &b).expect("shift");
        let mut worst = 0.0f64;
        for band in &s.bands {
            let want = a0 + b0 * band.row;
            worst = worst.max((band.dx - want).abs());
        }
        eprintln!(
            "speed change: {} bands (+{} rejected), worst {worst:.3}: {:?}",
            s.bands.len(),
            s.rejected.len(),
            s.bands
                .iter()
                .map(|b| (b.row.round(), b.dx - a0 - b0 * b.row))
                .collect::<Vec<_>>()
        );
        assert_eq!(s.bands.len(), 8);
        assert!(worst < 0.3, "{worst}");
    }

    /// A frame pair whose background moves by `bg` and whose face (a Yale fixture, at
    /// `face_at` in the first frame) moves by `fg`.
    fn face_pair(
        bg: (f64, f64),
        fg: (f64, f64),
        face_at: (f64, f64),
    ) -> (GrayImage, GrayImage, Rect) {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/fixtures/faces/subject01.normal.jpeg"
        );
        let face = crate::imageio::read_image(path.as_ref(), 1 << 24)
            .expect("fixture")
            .to_luma8();
        let (fw, fh) = (face.width() as f64, face.height() as f64);
        let face = Scene {
            w: face.width() as usize,
            h: face.height() as usize,
            data: face.as_raw().iter().map(|&v| f32::from(v)).collect(),
        };
        let scene = scene();
        let frame = |shift_bg: (f64, f64), shift_fg: (f64, f64), seed| {
            let mut rng = SplitMix64::new(seed);
            GrayImage::from_fn(W, H, |x, y| {
                let (x, y) = (f64::from(x), f64::from(y));
                let (u, v) = (x - face_at.0 - shift_fg.0, y - face_at.1 - shift_fg.1);
                let value = if (0.0..fw - 1.0).contains(&u) && (0.0..fh - 1.0).contains(&v) {
                    face.sample(u, v)
                } else {
                    scene.sample(x - shift_bg.0 + MARGIN, y - shift_bg.1 + 30.0)
                };
                let value = f64::from(value) + gauss(&mut rng, 1.0);
                Luma([value.round().clamp(0.0, 255.0) as u8])
            })
        };
        let a = frame((0.0, 0.0), (0.0, 0.0), 50);
        let b = frame(bg, fg, 51);
        (a, b, Rect::new(face_at.0, face_at.1, fw, fh))
    }

    #[test]
    fn the_frame_follows_the_background_and_a_region_its_own_motion() {
        let (bg, fg) = ((30.3, 0.0), (-12.4, 3.2));
        let (a, b, face) = face_pair(bg, fg, (320.0, 150.0));
        let s = measure(&a, &b).expect("shift");
        eprintln!(
            "background ({:.3}, {:.3}) sigma {:.3}; bands {:?}; rejected {:?}",
            s.dx - bg.0,
            s.dy - bg.1,
            s.sigma,
            s.bands
                .iter()
                .map(|b| (b.row.round(), b.dx, b.dy))
                .collect::<Vec<_>>(),
            s.rejected
                .iter()
                .map(|b| (b.row.round(), b.dx, b.dy))
                .collect::<Vec<_>>()
        );
        assert!((s.dx - bg.0).abs() < 0.25 && (s.dy - bg.1).abs() < 0.25);
        let r = region_shift(&a, &b, face, (0.0, 0.0), 40.0).expect("region");
        eprintln!(
            "region error ({:.3}, {:.3}) sigma {:.3} strength {:.2}",
            r.dx - fg.0,
            r.dy - fg.1,
            r.sigma,
            r.strength
        );
        assert!((r.dx - fg.0).abs() < 0.25 && (r.dy - fg.1).abs() < 0.25);
        // From a guess near the answer, with a tight radius.
        let r2 = region_shift(&a, &b, face, (-10.0, 2.0), 6.0).expect("region");
        assert!((r2.dx - fg.0).abs() < 0.25 && (r2.dy - fg.1).abs() < 0.25);
        // The background box moves with the background.
        let bgbox = Rect::new(700.0, 300.0, 200.0, 160.0);
        let r3 = region_shift(&a, &b, bgbox, (25.0, 0.0), 20.0).expect("background region");
        assert!((r3.dx - bg.0).abs() < 0.25 && (r3.dy - bg.1).abs() < 0.25);
    }

    #[test]
    fn flat_frames_noise_and_odd_sizes_give_nothing_and_never_panic() {
        let flat = GrayImage::from_pixel(W, H, Luma([100]));
        assert!(measure(&flat, &flat).is_none());
        let mut rng = SplitMix64::new(3);
        let noise = |rng: &mut SplitMix64| {
            GrayImage::from_fn(W, H, |_, _| {
                Luma([(128.0 + gauss(rng, 20.0)).clamp(0.0, 255.0) as u8])
            })
        };
        let (n1, n2) = (noise(&mut rng), noise(&mut rng));
        if let Some(s) = measure(&n1, &n2) {
            eprintln!("noise: {s:?}");
            assert!(s.bands.len() <= 1 && s.sigma > 1.0);
        }
        let mut m = MotionEstimator::default();
        for (w, h) in [
            (0, 0),
            (1, 1),
            (0, 50),
            (15, 15),
            (40, 17),
            (40, 17),
            (5000, 16),
            (960, 540),
            (640, 480),
            (640, 480),
        ] {
            let img = GrayImage::from_pixel(w, h, Luma([7]));
            let _ = m.push(&img);
        }
        m.reset();
        assert!(m.push(&flat).is_none());
        let scene = scene();
        let (a, b) = pair(&scene, 0.0, 1, 0.0, 60, |_| (5.0, 0.0));
        assert!(m.push(&a).is_none(), "a size change starts over");
        assert!(m.push(&b).is_some());
        m.reset();
        assert!(m.push(&b).is_none());
        // Extreme settings are clamped or refused.
        let bad = MotionParams {
            max_width: 3,
            bands: 1000,
            max_shift: f64::NAN,
        };
        assert!(bad.validate().is_err() && MotionEstimator::try_new(bad).is_err());
        let mut m = MotionEstimator::new(bad);
        assert!(m.push(&a).is_none());
        let _ = m.push(&b);
        let full = MotionParams {
            max_width: 0,
            bands: 0,
            max_shift: 0.45,
        };
        assert!(full.validate().is_ok());
        // Regions: sizes, boxes outside, non-finite arguments.
        let small = GrayImage::from_pixel(100, 100, Luma([1]));
        let r = Rect::new(10.0, 10.0, 50.0, 50.0);
        assert!(region_shift(&a, &small, r, (0.0, 0.0), 5.0).is_none());
        assert!(region_shift(&small, &small, r, (0.0, 0.0), 5.0).is_none());
        assert!(region_shift(
            &a,
            &b,
            Rect::new(-500.0, -500.0, 10.0, 10.0),
            (0.0, 0.0),
            5.0
        )
        .is_none());
        assert!(region_shift(
            &a,
            &b,
            Rect::new(950.0, 530.0, 400.0, 400.0),
            (0.0, 0.0),
            5.0
        )
        .is_none());
        assert!(region_shift(&a, &b, r, (f64::NAN, 0.0), 5.0).is_none());
        assert!(region_shift(&a, &b, r, (0.0, 0.0), -1.0).is_none());
        assert!(region_shift(&a, &b, r, (1e300, 0.0), 1e300).is_none());
        let empty = GrayImage::new(0, 0);
        assert!(region_shift(&empty, &empty, r, (0.0, 0.0), 5.0).is_none());
        let _ = region_shift(&a, &b, Rect::new(0.0, 0.0, 960.0, 540.0), (0.0, 0.0), 500.0);
    }

    #[test]
    fn sigma_is_a_fair_one_sigma() {
        // Four conditions: light noise, blur and noise, heavy noise, heavy noise and blur.
        let scene = scene();
        let mut rng = SplitMix64::new(99);
        let (mut z2, mut n, mut e2, mut s2) = (0.0, 0usize, 0.0, 0.0);
        for trial in 0..16 {
            let (dx, dy) = (rng.symmetric(60.0), rng.symmetric(3.0));
            let (blur, noise) = [(1, 3.0), (16, 6.0), (1, 20.0), (16, 30.0)][trial as usize % 4];
            let (a, b) = pair(&scene, 0.0, blur, noise, 100 + 2 * trial, |_| (dx, dy));
            // Heavy noise and blur may leave no reliable band.
            let Some(s) = measure(&a, &b) else {
                continue;
            };
            if noise < 10.0 {
                assert_eq!(s.bands.len(), 8);
            }
            for band in &s.bands {
                for e in [band.dx - dx, band.dy - dy] {
                    z2 += (e / band.sigma).powi(2);
                    e2 += e * e;
                    s2 += band.sigma * band.sigma;
                    n += 1;
                }
            }
        }
        let z = (z2 / n as f64).sqrt();
        eprintln!(
            "sigma check: {n} values, rms error {:.3}, rms sigma {:.3}, rms(error / sigma) {z:.2}",
            (e2 / n as f64).sqrt(),
            (s2 / n as f64).sqrt()
        );
        assert!((0.5..2.0).contains(&z), "{z}");
    }
}

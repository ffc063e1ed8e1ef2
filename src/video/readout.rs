//! The rolling-shutter camera model of video: rows read one after another, so a frame's shear is
//! the image velocity times the line time, and the readout fraction calibrated from the faces.
//!
//! A CMOS sensor reads row `y` of frame `n` (of `H` rows) at `t = n + rho * y / H`, in frame
//! intervals, with `rho` in `(0, 1.2]` the readout fraction (the sensor's readout time over the
//! frame interval). Content moving across the image at `v` pixels per frame therefore lands in
//! row `y` displaced by `u(t(y)) - u(t(c))` against the middle row `c = H / 2`, where `u` is the
//! content's position over time: a shear `k = rho * v / H` when `v` is constant, a curve when
//! the pan changes speed during the readout.
//!
//! * [`VelocityCurve`]: the image velocity through one frame's readout, fitted to displacements
//!   measured between consecutive frames band by band (each band's displacement is the mean
//!   velocity over one frame interval starting at the band's own row time).
//! * [`RowMotion`]: what the curve means for one frame: `k` at the middle row, and the offset of
//!   every row (and, with vertical motion, the row each output row is read from).
//! * [`ReadoutCalibrator`]: `rho` fitted over a clip to the pairs (a face's measured shear, its
//!   image velocity), jointly with one bias per face track (a face's own asymmetry and pose read
//!   as shear, constant along the track), robust to outliers, with its uncertainty.

use serde::{Deserialize, Serialize};

use crate::{Error, Result};

/// The largest readout fraction accepted: a sensor reads its rows within the frame interval
/// (`rho <= 1`), with some room for clips whose frame rate was changed after recording.
pub const MAX_READOUT_FRACTION: f64 = 1.2;

/// Checks a readout fraction given by a user: finite, in `(0, 1.2]`.
///
/// # Errors
/// [`Error::InvalidArgument`] otherwise.
pub fn check_readout_fraction(rho: f64) -> Result<f64> {
    if rho.is_finite() && rho > 0.0 && rho <= MAX_READOUT_FRACTION {
        Ok(rho)
    } else {
        Err(Error::InvalidArgument(format!(
            "readout fraction {rho} is outside (0, {MAX_READOUT_FRACTION}]: the sensor's readout \
             time over the frame interval (e.g. 0.8 for a 26.7 ms readout at 30 frames/s)"
        )))
    }
}

/// The time (in frame intervals) at which row `y` of frame `n` is read.
pub fn row_time(n: f64, y: f64, rho: f64, height: u32) -> f64 {
    n + rho * y / f64::from(height.max(1))
}

/// One measured displacement: the mean image velocity over the frame interval centred at `time`
/// (a band's displacement between consecutive frames), pixels per frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct VelocitySample {
    /// The middle of the interval, frame intervals.
    pub time: f64,
    /// Horizontal displacement over the interval (positive: content moved right), pixels.
    pub dx: f64,
    /// Vertical displacement (positive: content moved down), pixels.
    pub dy: f64,
    /// Its 1-sigma uncertainty, pixels.
    pub sigma: f64,
}

impl VelocitySample {
    /// The sample a band's displacement between frames `pair` and `pair + 1` gives, `row`
    /// being the band's row in the later frame, for readout `rho` and `height` rows. Content
    /// that moved down by `dy` was read `rho * dy / H` later in the later frame than it would
    /// have been in the same row, so the displacement spans `1 + rho * dy / H` frame intervals
    /// (exactly, for a constant velocity): it is scaled to one, and timed at the middle of the
    /// span.
    pub fn from_band(
        pair: f64,
        row: f64,
        dx: f64,
        dy: f64,
        sigma: f64,
        rho: f64,
        height: u32,
    ) -> Self {
        let before = row_time(pair, row - dy, rho, height);
        let after = row_time(pair + 1.0, row, rho, height);
        let span = (after - before).max(0.5);
        Self {
            time: (before + after) / 2.0,
            dx: dx / span,
            dy: dy / span,
            sigma: sigma / span,
        }
    }
}

/// The smallest uncertainty a displacement is given in the fit: below a fifth of a pixel the
/// correlation's own error is smaller than what the model (a quadratic in time) can follow.
const MIN_SAMPLE_SIGMA: f64 = 0.2;

/// Image velocity through one frame's readout: a polynomial of degree up to 3 in `s = t - t0`,
/// horizontally and vertically.
///
/// Fitted to [`VelocitySample`]s as box averages (a displacement between frames is the mean
/// velocity over one frame interval: `s^2` averages to `s^2 + 1/12`, `s^3` to `s^3 + s/4`), so
/// a pan accelerating steadily is followed exactly, and one whose speed swings within a frame
/// (a hand's shake) closely.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VelocityCurve {
    /// The reference time, frame intervals.
    pub t0: f64,
    /// Horizontal coefficients of `1, s, s^2, s^3`.
    pub x: [f64; 4],
    /// Vertical coefficients.
    pub y: [f64; 4],
}

/// How far from the reference time samples still count fully in [`VelocityCurve::fit`], frame
/// intervals: a Gaussian weight of this width, so the curve is local to the frame it serves.
const FIT_BANDWIDTH: f64 = 1.5;

impl VelocityCurve {
    /// A constant velocity.
    #[cfg(test)]
    pub fn constant(vx: f64, vy: f64) -> Self {
        Self {
            t0: 0.0,
            x: [vx, 0.0, 0.0, 0.0],
            y: [vy, 0.0, 0.0, 0.0],
        }
    }

    /// Least-squares fit to `samples` about `t0`, weighted by their uncertainty and by their
    /// distance in time from `t0` (a Gaussian 1.5 frame intervals wide); samples far off the first
    /// fit (4 sigma, and more than 3 px and 5% of their displacement: the motion estimator has
    /// already set apart bands that disagree) are dropped and the fit repeated. The terms the
    /// samples cannot determine are left out: the cubic when they span less than 2.5 frame
    /// intervals, the square below 1.5, the slope below a tenth. `None` without samples.
    pub fn fit(samples: &[VelocitySample], t0: f64) -> Option<Self> {
        let usable: Vec<&VelocitySample> = samples
            .iter()
            .filter(|s| s.time.is_finite() && s.dx.is_finite() && s.dy.is_finite())
            .filter(|s| s.sigma.is_finite() && s.sigma >= 0.0)
            .collect();
        if usable.is_empty() {
            return None;
        }
        let first = Self::fit_once(&usable, t0)?;
        let kept: Vec<&VelocitySample> = usable
            .iter()
            .copied()
            .filter(|s| {
                let (px, py) = first.mean_velocity(s.time);
                let sigma = s.sigma.max(MIN_SAMPLE_SIGMA);
                let off = (s.dx - px).hypot(s.dy - py);
                off <= 4.0 * sigma || off <= 3.0 + 0.05 * s.dx.hypot(s.dy)
            })
            .collect();
        if kept.len() == usable.len() || kept.is_empty() {
            return Some(first);
        }
        Self::fit_once(&kept, t0)
    }

    fn fit_once(samples: &[&VelocitySample], t0: f64) -> Option<Self> {
        let (lo, hi) = samples
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |a, s| {
                (a.0.min(s.time), a.1.max(s.time))
            });
        let span = hi - lo;
        let terms = match span {
            s if s >= 2.5 => 4,
            s if s >= 1.5 => 3,
            s if s >= 0.1 => 2,
            _ => 1,
        };
        // Normal equations of the box-averaged model; a tiny ridge keeps them regular.
        let mut m = [[0.0f64; 4]; 4];
        let mut rx = [0.0f64; 4];
        let mut ry = [0.0f64; 4];
        for s in samples {
            let d = s.time - t0;
            let w =
                (-0.5 * (d / FIT_BANDWIDTH).powi(2)).exp() / s.sigma.max(MIN_SAMPLE_SIGMA).powi(2);
            let basis = [1.0, d, d * d + 1.0 / 12.0, d * d * d + d / 4.0];
            for i in 0..terms {
                for j in 0..terms {
                    m[i][j] += w * basis[i] * basis[j];
                }
                rx[i] += w * basis[i] * s.dx;
                ry[i] += w * basis[i] * s.dy;
            }
        }
        let scale = (0..terms).map(|i| m[i][i]).fold(0.0f64, f64::max);
        for (i, row) in m.iter_mut().enumerate().take(terms) {
            row[i] += 1e-9 * scale.max(1e-12);
        }
        let x = solve(&m, &rx, terms)?;
        let y = solve(&m, &ry, terms)?;
        Some(Self { t0, x, y })
    }

    /// The velocity at time `t`, `(vx, vy)` pixels per frame.
    pub fn velocity(&self, t: f64) -> (f64, f64) {
        let s = t - self.t0;
        let v = |c: &[f64; 4]| c[0] + s * (c[1] + s * (c[2] + s * c[3]));
        (v(&self.x), v(&self.y))
    }

    /// The mean velocity over the frame interval centred at `t` (what a displacement between
    /// frames measures).
    pub fn mean_velocity(&self, t: f64) -> (f64, f64) {
        let s = t - self.t0;
        let v = |c: &[f64; 4]| {
            c[0] + c[1] * s + c[2] * (s * s + 1.0 / 12.0) + c[3] * (s * s * s + s / 4.0)
        };
        (v(&self.x), v(&self.y))
    }

    /// How far content moves from time `from` to time `to`, `(dx, dy)` pixels: the velocity
    /// integrated.
    pub fn displacement(&self, from: f64, to: f64) -> (f64, f64) {
        let integral = |c: &[f64; 4], t: f64| {
            let s = t - self.t0;
            s * (c[0] + s * (c[1] / 2.0 + s * (c[2] / 3.0 + s * c[3] / 4.0)))
        };
        (
            integral(&self.x, to) - integral(&self.x, from),
            integral(&self.y, to) - integral(&self.y, from),
        )
    }
}

/// Solves the leading `n` x `n` block of `m a = r` by Gaussian elimination with partial pivoting
/// (at most 4 x 4: not worth a linear-algebra crate). `None` when singular.
fn solve(m: &[[f64; 4]; 4], r: &[f64; 4], n: usize) -> Option<[f64; 4]> {
    let mut a = *m;
    let mut b = *r;
    for col in 0..n {
        let pivot = (col..n).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
        if a[pivot][col].abs() < 1e-300 {
            return None;
        }
        a.swap(col, pivot);
        b.swap(col, pivot);
        let pivot_row = a[col];
        for row in col + 1..n {
            let f = a[row][col] / pivot_row[col];
            for (v, p) in a[row].iter_mut().zip(&pivot_row).take(n).skip(col) {
                *v -= f * p;
            }
            b[row] -= f * b[col];
        }
    }
    let mut x = [0.0; 4];
    for row in (0..n).rev() {
        let tail: f64 = (row + 1..n).map(|j| a[row][j] * x[j]).sum();
        x[row] = (b[row] - tail) / a[row][row];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// The image velocity over time, what [`RowMotion`] integrates through a frame's readout: a
/// [`VelocityCurve`] about one frame, or the spline over several frame pairs
/// (`super::timing::VelocitySpline`).
pub trait VelocityModel {
    /// The velocity at time `t`, `(vx, vy)` pixels per frame.
    fn velocity(&self, t: f64) -> (f64, f64);
    /// How far content moves from time `from` to time `to`, `(dx, dy)` pixels.
    fn displacement(&self, from: f64, to: f64) -> (f64, f64);
}

impl VelocityModel for VelocityCurve {
    fn velocity(&self, t: f64) -> (f64, f64) {
        VelocityCurve::velocity(self, t)
    }

    fn displacement(&self, from: f64, to: f64) -> (f64, f64) {
        VelocityCurve::displacement(self, from, to)
    }
}

/// The rolling shutter's effect on one frame, from the image velocity through its readout.
#[derive(Debug, Clone, PartialEq)]
pub struct RowMotion {
    /// The shear at the middle row, `rho * vx(t(c)) / H`.
    pub k: f64,
    /// The image velocity at the middle row's time, `(vx, vy)` pixels per frame.
    pub velocity: (f64, f64),
    /// Per row: the horizontal displacement of its content against the middle row, pixels; the
    /// correction reads output pixel `(x, y)` from `(x + shifts[y], y)`.
    pub shifts: Vec<f64>,
    /// With vertical correction: the input row each output row is read from (content that moves
    /// down during the readout is spread over more rows); `None` without.
    pub sources: Option<Vec<f64>>,
    /// Per row: the horizontal image velocity at its read time, pixels per frame (its motion
    /// blur is this times the exposure).
    pub row_velocities: Vec<f64>,
}

impl RowMotion {
    /// The frame `n` of `height` rows read out over `rho` of the frame interval, seen through
    /// `curve`; `vertical` also works out the rows' vertical resampling.
    pub fn of(curve: &impl VelocityModel, n: f64, rho: f64, height: u32, vertical: bool) -> Self {
        let h = f64::from(height.max(1));
        let mid = row_time(n, h / 2.0, rho, height);
        let velocity = curve.velocity(mid);
        let at = |y: f64| curve.displacement(mid, row_time(n, y, rho, height));
        let shifts = (0..height).map(|y| at(f64::from(y)).0).collect();
        // Output row y shows the scene row that the middle row's time puts there: the input row
        // y' with y' - dy(y') = y, solved by a few fixed-point steps (|d dy / dy| = rho |vy| / H,
        // far below 1 for any real pan).
        let sources = vertical.then(|| {
            (0..height)
                .map(|y| {
                    let y = f64::from(y);
                    let mut src = y;
                    for _ in 0..8 {
                        src = y + at(src).1;
                    }
                    src
                })
                .collect()
        });
        let row_velocities = (0..height)
            .map(|y| curve.velocity(row_time(n, f64::from(y), rho, height)).0)
            .collect();
        Self {
            k: rho * velocity.0 / h,
            velocity,
            shifts,
            sources,
            row_velocities,
        }
    }

    /// The largest difference between these shifts and the straight line of a single shear
    /// `k` about the middle row, pixels: how much a per-row correction adds.
    #[cfg(test)]
    pub fn curvature(&self) -> f64 {
        let c = self.shifts.len() as f64 / 2.0;
        self.shifts
            .iter()
            .enumerate()
            .map(|(y, s)| (s - self.k * (y as f64 - c)).abs())
            .fold(0.0, f64::max)
    }
}

/// One face's reading for the calibration: its measured shear and its image velocity.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ShearSample {
    /// The face track it belongs to (its bias is shared along the track).
    pub track: u64,
    /// The frame it was read in.
    pub frame: u64,
    /// The face's measured shear.
    pub k: f64,
    /// Its image velocity at its rows' time over the frame height, `vx / H` (per frame).
    pub rate: f64,
    /// Weight (e.g. the estimate's confidence), `> 0`.
    pub weight: f64,
}

/// What the calibration found.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Calibration {
    /// The readout fraction `rho`.
    pub readout_fraction: f64,
    /// Its 1-sigma uncertainty.
    pub uncertainty: f64,
    /// Face readings used (after outliers were dropped).
    pub samples: usize,
    /// Face tracks they came from.
    pub tracks: usize,
    /// Distinct frames they came from.
    pub frames: usize,
    /// Frame pairs whose motion told the readout on its own (the speed changing within the
    /// readout; 0 when the motion said nothing and the faces alone found it).
    pub motion_pairs: usize,
}

impl Calibration {
    /// The readout time in milliseconds at `fps` frames per second.
    pub fn readout_ms(&self, fps: f64) -> f64 {
        self.readout_fraction / fps * 1000.0
    }
}

/// Frame pairs of changing motion that tell the readout without a face (see
/// [`CalibrationParams::is_known`]).
const MIN_MOTION_PAIRS: usize = 8;

/// Settings of the readout's calibration from the faces.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CalibrationParams {
    /// The typical error of one face's shear reading in one frame (1 sigma).
    pub reading_noise: f64,
    /// The typical spread of face tracks' biases (1 sigma): how far a face's own asymmetry and
    /// pose move its reading. Tracks whose velocity hardly changes tell `rho` only through this
    /// prior; tracks seen at several speeds (a pan that stops or turns) tell it on their own.
    pub bias_spread: f64,
    /// Readings whose residual is beyond this many `reading_noise` count less (Huber weights).
    pub huber: f64,
    /// `rho` counts as known (and motion takes over from the faces) when its uncertainty is at
    /// most this fraction of it: 10% of `rho` is an error of at most 0.03 in a shear of 0.3,
    /// what a face reads in one frame; the fit goes on improving it over the clip...
    pub max_relative_uncertainty: f64,
    /// ...from at least this many readings.
    pub min_samples: usize,
}

impl CalibrationParams {
    /// Whether a fit is good enough to correct by: enough readings, `rho` inside `(0, 1.2]` and
    /// known to [`Self::max_relative_uncertainty`].
    pub fn is_known(&self, c: &Calibration) -> bool {
        (c.samples >= self.min_samples || c.motion_pairs >= MIN_MOTION_PAIRS)
            && c.readout_fraction > 0.0
            && c.readout_fraction <= MAX_READOUT_FRACTION
            && c.uncertainty <= self.max_relative_uncertainty * c.readout_fraction
    }
}

impl Default for CalibrationParams {
    fn default() -> Self {
        Self {
            reading_noise: 0.015,
            bias_spread: 0.03,
            huber: 2.0,
            max_relative_uncertainty: 0.1,
            min_samples: 12,
        }
    }
}

/// Fits the readout fraction over a clip: `k_i = rho * rate_i + b_track + e_i`, each track's
/// bias `b` a random effect of spread [`CalibrationParams::bias_spread`] (estimated with the
/// tracks, shrunk towards 0 when a track is short), the residuals `e` weighted by Huber's rule
/// (iteratively reweighted least squares), so a mislocated face does not pull `rho`.
#[derive(Debug, Clone, Default)]
pub struct ReadoutCalibrator {
    params: CalibrationParams,
    samples: Vec<ShearSample>,
}

impl ReadoutCalibrator {
    /// An empty calibrator.
    pub fn new(params: CalibrationParams) -> Self {
        Self {
            params,
            samples: Vec::new(),
        }
    }

    /// Adds a reading (ignored when any number is not finite or the weight not positive).
    pub fn add(&mut self, sample: ShearSample) {
        if sample.k.is_finite()
            && sample.rate.is_finite()
            && sample.weight.is_finite()
            && sample.weight > 0.0
        {
            self.samples.push(sample);
        }
    }

    /// The fit over every reading so far; `None` with fewer than 3 readings or when the
    /// readings do not move enough to tell `rho` (no motion: every rate about 0).
    pub fn solve(&self) -> Option<Calibration> {
        let p = self.params;
        if self.samples.len() < 3 {
            return None;
        }
        // Per-reading weights in units of the reading noise; the bias prior in the same units.
        let lambda = (p.reading_noise / p.bias_spread).powi(2);
        let mut huber = vec![1.0f64; self.samples.len()];
        let mut tracks: Vec<u64> = self.samples.iter().map(|s| s.track).collect();
        tracks.sort_unstable();
        tracks.dedup();
        let index = |t: u64| tracks.binary_search(&t).unwrap_or(0);
        let mut rho = 0.0;
        for _ in 0..8 {
            // Per track: A = sum W + lambda, P = sum W rate, Q = sum W k.
            let mut sums = vec![(lambda, 0.0f64, 0.0f64); tracks.len()];
            let (mut wrk, mut wrr) = (0.0, 0.0);
            for (s, h) in self.samples.iter().zip(&huber) {
                let w = s.weight * h;
                let t = &mut sums[index(s.track)];
                t.0 += w;
                t.1 += w * s.rate;
                t.2 += w * s.k;
                wrk += w * s.rate * s.k;
                wrr += w * s.rate * s.rate;
            }
            let num = wrk - sums.iter().map(|t| t.1 * t.2 / t.0).sum::<f64>();
            let info = wrr - sums.iter().map(|t| t.1 * t.1 / t.0).sum::<f64>();
            if info <= 1e-12 {
                return None;
            }
            rho = num / info;
            // Residuals with each track's bias at its estimate; Huber weights from them.
            for (s, h) in self.samples.iter().zip(huber.iter_mut()) {
                let t = sums[index(s.track)];
                let bias = (t.2 - rho * t.1) / t.0;
                let r = (s.k - rho * s.rate - bias).abs() / p.reading_noise;
                *h = if r <= p.huber { 1.0 } else { p.huber / r };
            }
        }
        // The scale of the residuals (at least the stated noise's tenth, so a perfect synthetic
        // fit does not claim infinite precision).
        let sums = {
            let mut sums = vec![(lambda, 0.0f64, 0.0f64); tracks.len()];
            for (s, h) in self.samples.iter().zip(&huber) {
                let w = s.weight * h;
                let t = &mut sums[index(s.track)];
                t.0 += w;
                t.1 += w * s.rate;
                t.2 += w * s.k;
            }
            sums
        };
        let (mut ss, mut wsum, mut wrr) = (0.0, 0.0, 0.0);
        for (s, h) in self.samples.iter().zip(&huber) {
            let t = sums[index(s.track)];
            let bias = (t.2 - rho * t.1) / t.0;
            let w = s.weight * h;
            ss += w * (s.k - rho * s.rate - bias).powi(2);
            wsum += w;
            wrr += w * s.rate * s.rate;
        }
        let n = self.samples.len() as f64;
        let dof = (n - 1.0 - tracks.len() as f64 * (1.0 - lambda.min(1.0))).max(1.0);
        let variance = (ss / wsum.max(1e-12) * n / dof).max((0.1 * p.reading_noise).powi(2));
        // The information about `rho` with the biases marginalised, in units of the weights (a
        // reading of weight 1 and rate r adds r^2), the bias prior weighed against the readings'
        // noise as measured, not as assumed: when a track's readings agree closely, only the
        // prior on its bias tells its bias from `rho` (a steady pan), and the uncertainty must
        // stay that of the prior, bias_spread / rate / sqrt(tracks).
        let mean_weight = wsum / n;
        let lambda_seen = variance * mean_weight / p.bias_spread.powi(2);
        let shrunk: f64 = sums
            .iter()
            .map(|t| t.1 * t.1 / (t.0 - lambda + lambda_seen))
            .sum();
        let uncertainty = (variance * mean_weight / (wrr - shrunk).max(1e-12)).sqrt();
        let used = huber.iter().filter(|&&h| h > 0.5).count();
        let mut frames: Vec<u64> = self.samples.iter().map(|s| s.frame).collect();
        frames.sort_unstable();
        frames.dedup();
        Some(Calibration {
            readout_fraction: rho,
            uncertainty,
            samples: used,
            tracks: tracks.len(),
            frames: frames.len(),
            motion_pairs: 0,
        })
    }

    /// The fit, when it is good enough to correct by: enough readings, `rho` inside
    /// `(0, 1.2]` and known to [`CalibrationParams::max_relative_uncertainty`].
    #[cfg(test)]
    pub fn known(&self) -> Option<Calibration> {
        self.solve().filter(|c| self.params.is_known(c))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    #[test]
    fn readout_fractions_outside_the_range_are_refused() {
        assert!(check_readout_fraction(0.8).is_ok());
        assert!(check_readout_fraction(1.2).is_ok());
        for bad in [0.0, -0.5, 1.3, f64::NAN, f64::INFINITY] {
            assert!(check_readout_fraction(bad).is_err(), "{bad}");
        }
    }

    /// Displacement samples of a content position `u(t)`: 8 bands per frame pair, as the motion
    /// estimator reports them.
    fn samples(u: impl Fn(f64) -> f64, n: f64, rho: f64, h: u32) -> Vec<VelocitySample> {
        let mut out = Vec::new();
        for pair in [n - 1.0, n] {
            for b in 0..8 {
                let y = (f64::from(b) + 0.5) * f64::from(h) / 8.0;
                let t = row_time(pair, y, rho, h);
                out.push(VelocitySample {
                    time: t + 0.5,
                    dx: u(t + 1.0) - u(t),
                    dy: 0.0,
                    sigma: 0.3,
                });
            }
        }
        out
    }

    #[test]
    fn a_constant_pan_is_a_shear_of_rho_v_over_h() {
        let (rho, h, v) = (0.8, 720, 225.0);
        let curve = VelocityCurve::fit(&samples(|t| v * t, 10.0, rho, h), 10.0).unwrap();
        let m = RowMotion::of(&curve, 10.0, rho, h, false);
        assert!((m.k - rho * v / 720.0).abs() < 1e-9, "{}", m.k);
        // Row shifts are the shear's straight line about the middle row.
        assert!(m.curvature() < 1e-6, "{}", m.curvature());
        assert!((m.shifts[0] - m.k * -360.0).abs() < 1e-6);
    }

    #[test]
    fn a_pan_accelerating_within_the_frame_gives_curved_row_shifts() {
        // u(t) = 40 t^2: the velocity 80 t changes by 64 px/frame during a readout of 0.8.
        let (rho, h, n) = (0.8, 720, 3.0);
        let u = |t: f64| 40.0 * t * t;
        let curve = VelocityCurve::fit(&samples(u, n, rho, h), n).unwrap();
        let m = RowMotion::of(&curve, n, rho, h, false);
        let mid = row_time(n, 360.0, rho, h);
        for y in [0u32, 100, 500, 719] {
            let truth = u(row_time(n, f64::from(y), rho, h)) - u(mid);
            assert!(
                (m.shifts[y as usize] - truth).abs() < 1e-6,
                "row {y}: {} vs {truth}",
                m.shifts[y as usize]
            );
        }
        assert!((m.k - rho * 80.0 * mid / 720.0).abs() < 1e-6, "{}", m.k);
        // The curve departs from a straight line by 40 rho^2 / 4 = 6.4 px at the ends.
        assert!((m.curvature() - 6.4).abs() < 0.05, "{}", m.curvature());
    }

    #[test]
    fn vertical_motion_spreads_rows_apart() {
        // Content moving down at 72 px/frame with rho = 1: row y's content is 72 y / H lower
        // against the middle row's time, so output row y reads input row y + 0.1 (y - c) / (1 - 0.1).
        let (h, rho) = (720u32, 1.0);
        let curve = VelocityCurve::constant(0.0, 72.0);
        let m = RowMotion::of(&curve, 0.0, rho, h, true);
        let sources = m.sources.unwrap();
        for y in [0usize, 200, 360, 719] {
            let want = y as f64 + 0.1 * (y as f64 - 360.0) / 0.9;
            assert!(
                (sources[y] - want).abs() < 1e-3,
                "{y}: {} {want}",
                sources[y]
            );
        }
        assert!(m.shifts.iter().all(|s| s.abs() < 1e-12));
    }

    #[test]
    fn outlying_bands_are_dropped_from_the_curve() {
        let (rho, h) = (0.8, 720);
        let mut s = samples(|t| 100.0 * t, 5.0, rho, h);
        s[3].dx += 60.0; // a band dominated by a subject walking the other way
        let curve = VelocityCurve::fit(&s, 5.0).unwrap();
        let (vx, _) = curve.velocity(5.4);
        assert!((vx - 100.0).abs() < 0.5, "{vx}");
    }

    fn calibrator_with(
        rho: f64,
        rates: impl Fn(u64, u64) -> f64,
        tracks: u64,
        frames: u64,
        seed: u64,
    ) -> ReadoutCalibrator {
        let mut rng = SplitMix64::new(seed);
        let mut c = ReadoutCalibrator::new(CalibrationParams::default());
        for t in 0..tracks {
            let bias = rng.symmetric(0.05);
            for f in 0..frames {
                let rate = rates(t, f);
                c.add(ShearSample {
                    track: t,
                    frame: t * frames + f,
                    k: rho * rate + bias + rng.symmetric(0.02),
                    rate,
                    weight: 1.0,
                });
            }
        }
        c
    }

    #[test]
    fn rho_is_found_through_each_tracks_own_bias() {
        // Ten faces, each seen over 12 frames of a pan whose speed changes (0 to 0.3 / 0.8 of
        // the height per frame), each with its own bias up to 0.05.
        let rho = 0.8;
        let c = calibrator_with(
            rho,
            |t, f| (f as f64 / 11.0 - 0.3 * (t % 3) as f64) * 0.375,
            10,
            12,
            7,
        );
        let fit = c.known().expect("known");
        assert!((fit.readout_fraction - rho).abs() < 0.03 * rho, "{fit:?}");
        // A fair uncertainty: the error is within 3 sigma, and sigma is not absurdly small.
        assert!(
            (fit.readout_fraction - rho).abs() <= 3.0 * fit.uncertainty,
            "{fit:?}"
        );
        assert!(fit.uncertainty > 1e-4);
        assert_eq!(fit.tracks, 10);
    }

    #[test]
    fn a_mislocated_face_does_not_pull_rho() {
        let rho = 0.6;
        let mut c = calibrator_with(rho, |_, f| (f as f64 - 6.0) * 0.05, 4, 13, 3);
        for f in 0..4 {
            c.add(ShearSample {
                track: 99,
                frame: 1000 + f,
                k: 0.4,
                rate: 0.01,
                weight: 1.0,
            });
        }
        let fit = c.solve().unwrap();
        assert!((fit.readout_fraction - rho).abs() < 0.03, "{fit:?}");
    }

    #[test]
    fn without_motion_rho_is_unknown() {
        let c = calibrator_with(0.8, |_, _| 0.0, 5, 20, 1);
        assert!(c.solve().is_none() || c.known().is_none());
        assert!(ReadoutCalibrator::default().solve().is_none());
    }

    #[test]
    fn rho_from_constant_pans_leans_on_the_bias_prior_and_says_so() {
        // Every track at one speed: the biases cannot be told from rho within a track, so the
        // uncertainty is about bias_spread / rate / sqrt(tracks), not the reading noise.
        let c = calibrator_with(0.8, |_, _| 0.25 / 0.8, 6, 5, 11);
        let fit = c.solve().unwrap();
        assert!(fit.uncertainty > 0.02, "{fit:?}");
    }

    #[test]
    fn a_steady_pans_uncertainty_is_the_bias_priors_however_steady_the_readings() {
        // Six faces at one speed, each read almost without noise (0.002) along its track, as a
        // simulated pan gives: the readings' agreement must not shrink what the prior leaves
        // unknown, bias_spread / rate / sqrt(tracks).
        let (rho, rate, tracks) = (1.0, 0.3, 6);
        let mut rng = SplitMix64::new(3);
        let mut c = ReadoutCalibrator::new(CalibrationParams::default());
        for t in 0..tracks {
            let bias = rng.symmetric(0.04);
            for f in 0..15 {
                c.add(ShearSample {
                    track: t,
                    frame: t * 15 + f,
                    k: rho * rate + bias + rng.symmetric(0.002),
                    rate,
                    weight: 1.0,
                });
            }
        }
        let fit = c.solve().unwrap();
        let prior = CalibrationParams::default().bias_spread / rate / (tracks as f64).sqrt();
        assert!(
            fit.uncertainty > 0.7 * prior && fit.uncertainty < 1.3 * prior,
            "{fit:?} against {prior}"
        );
    }
}

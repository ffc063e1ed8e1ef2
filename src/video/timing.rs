//! The readout fraction from the motion alone, when the camera's speed changes.
//!
//! Under a rolling shutter a band of rows at row `y` measures, between frames `p` and `p + 1`,
//! the content's mean velocity over the frame interval starting when frame `p` reads that band,
//! at `p + rho * y / H`. So the bands of one frame pair sample the velocity at times spread over
//! `rho` of a frame interval: when the speed changes (a hand's shake, a pan easing to a stop),
//! the displacements change from band to band as much as `rho` stretches the time between them,
//! and only the true `rho` puts the bands of all frame pairs on one smooth velocity curve.
//! [`readout_from_motion`] finds the `rho` that does: no face needed. A steady pan says nothing
//! (every band measures the same velocity whatever `rho`), and says so through a wide
//! uncertainty.
//!
//! The curve is one cubic spline through each stretch of measured frame pairs, with a knot
//! every frame interval: one degree of freedom per frame pair, where a pair's bands tell two
//! (their level and their slope), so a pair's slope must agree with its neighbours' levels, the
//! test of `rho`. A cubic through a few frame pairs instead cannot follow a speed swinging within
//! a few frames through the gaps a short readout leaves (half of each frame interval at
//! `rho = 0.5`) and finds `rho` that makes the swing gentler: 10% high on a swing of 8 frames'
//! period, where the spline is exact to 0.1% (see the tests).

use super::readout::{VelocityModel, VelocitySample};

/// One band's displacement between frames `pair` and `pair + 1`, as the motion estimator
/// measured it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct BandReading {
    pub pair: u64,
    pub row: f64,
    pub dx: f64,
    pub dy: f64,
    pub sigma: f64,
}

/// What [`readout_from_motion`] found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct MotionTiming {
    pub readout_fraction: f64,
    /// 1-sigma: from the misfit's curvature scaled by its residual spread, widened by the
    /// difference between the two knot placements' answers.
    pub uncertainty: f64,
    /// Frame pairs that took part (in stretches of at least [`MIN_STRETCH`]), counted as 8
    /// bands each.
    pub pairs: usize,
}

/// Displacements this many sigmas off count less (Huber), so a band that a passing subject
/// pulled does not decide.
const HUBER: f64 = 3.0;
/// The smallest uncertainty given to one band: below it the smooth curve's own misfit dominates.
const MIN_SIGMA: f64 = 0.3;
/// The readout fractions searched.
const RHO_RANGE: (f64, f64) = (0.05, 1.2);
/// The spline's knots are this many frame intervals apart: one coefficient per frame pair.
const KNOT_SPACING: f64 = 1.0;
/// The weight of the spline's roughness (its coefficients' third differences squared, pixels
/// per frame) against the bands' misfit (squared, in sigmas): light, it only carries the curve
/// over an unmeasured frame pair. A swing of 8 frames' period at 432 px per frame costs about
/// 40 per knot, 5 per band.
const SMOOTHING: f64 = 1e-3;
/// Rounds of reweighting for Huber's rule.
const ROBUST_ROUNDS: usize = 3;
/// Measured frame pairs at most this many apart share a spline; a longer gap starts a new one.
const MAX_PAIR_STEP: u64 = 3;
/// Frame pairs a stretch needs to take part.
const MIN_STRETCH: usize = 3;

/// The uniform cubic B-spline centred at 0 (support `(-2, 2)`).
fn bspline(x: f64) -> f64 {
    let x = x.abs();
    if x < 1.0 {
        2.0 / 3.0 - x * x + x * x * x / 2.0
    } else if x < 2.0 {
        (2.0 - x).powi(3) / 6.0
    } else {
        0.0
    }
}

/// A symmetric positive definite matrix of half-bandwidth `width` (at most 4), its lower band
/// stored by row: `band[i][d]` is the entry `(i, i - d)`.
#[derive(Clone)]
struct Banded {
    band: Vec<[f64; 5]>,
    width: usize,
}

impl Banded {
    fn zeros(n: usize, width: usize) -> Self {
        debug_assert!(width <= 4);
        Self {
            band: vec![[0.0; 5]; n],
            width,
        }
    }

    /// Adds `v` at `(i, j)` (and `(j, i)`), `|i - j| <= width`.
    fn add(&mut self, i: usize, j: usize, v: f64) {
        let (i, j) = if i >= j { (i, j) } else { (j, i) };
        self.band[i][i - j] += v;
    }

    /// Solves `self x = r` by banded Cholesky; `None` when not positive definite.
    fn solve(mut self, r: &[f64]) -> Option<Vec<f64>> {
        let n = self.band.len();
        let w = self.width;
        for i in 0..n {
            for j in i.saturating_sub(w)..=i {
                let mut s = self.band[i][i - j];
                for k in i.saturating_sub(w)..j {
                    s -= self.band[i][i - k] * self.band[j][j - k];
                }
                if i == j {
                    if s <= 1e-12 * self.band[i][0].abs().max(1e-300) || !s.is_finite() {
                        return None;
                    }
                    self.band[i][0] = s.sqrt();
                } else {
                    self.band[i][i - j] = s / self.band[j][0];
                }
            }
        }
        let mut x = r.to_vec();
        for i in 0..n {
            let known: f64 = (i.saturating_sub(w)..i)
                .map(|k| self.band[i][i - k] * x[k])
                .sum();
            x[i] = (x[i] - known) / self.band[i][0];
        }
        for i in (0..n).rev() {
            let known: f64 = (i + 1..(i + w + 1).min(n))
                .map(|k| self.band[k][k - i] * x[k])
                .sum();
            x[i] = (x[i] - known) / self.band[i][0];
        }
        Some(x)
    }
}

/// Huber's cost of a residual of `e` sigmas.
fn huber(e: f64) -> f64 {
    if e <= HUBER {
        e * e
    } else {
        2.0 * HUBER * e - HUBER * HUBER
    }
}

/// The misfit of one stretch of bands (sorted by pair) to one cubic spline in time with knots at
/// `phase + KNOT_SPACING * k`, at readout `rho`: Huber's cost in sigmas plus the roughness, with
/// the number of spline coefficients; `None` when the fit is singular.
fn stretch_misfit(
    bands: &[BandReading],
    rho: f64,
    height: u32,
    phase: f64,
    samples: &mut Vec<VelocitySample>,
) -> Option<(f64, usize)> {
    samples.clear();
    samples.extend(bands.iter().map(|r| {
        VelocitySample::from_band(r.pair as f64, r.row, r.dx, r.dy, r.sigma, rho, height)
    }));
    let (lo, hi) = samples
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |a, s| {
            (a.0.min(s.time), a.1.max(s.time))
        });
    if !(lo.is_finite() && hi.is_finite()) {
        return None;
    }
    let u = |t: f64| (t - phase) / KNOT_SPACING;
    let first = u(lo).floor() as i64 - 1;
    let n = (u(hi).floor() as i64 + 2 - first + 1) as usize;
    // Each sample's 4 coefficients (the first's index) and basis values.
    let basis = |t: f64| {
        let x = u(t);
        let j = x.floor() as i64 - 1;
        let values: [f64; 4] = std::array::from_fn(|i| bspline(x - (j + i as i64) as f64));
        ((j - first) as usize, values)
    };
    let sigma = |s: &VelocitySample| s.sigma.max(MIN_SIGMA);
    let mut weights: Vec<f64> = samples.iter().map(|s| sigma(s).powi(-2)).collect();
    let mut coefficients = Vec::new();
    for round in 0..ROBUST_ROUNDS {
        let mut m = Banded::zeros(n, 3);
        let mut r = vec![0.0; n];
        for (s, &w) in samples.iter().zip(&weights) {
            let (j, b) = basis(s.time);
            for a in 0..4 {
                for c in 0..=a {
                    m.add(j + a, j + c, w * b[a] * b[c]);
                }
                r[j + a] += w * b[a] * s.dx;
            }
        }
        add_roughness(&mut m, n);
        coefficients = m.solve(&r)?;
        if round + 1 < ROBUST_ROUNDS {
            for (s, w) in samples.iter().zip(&mut weights) {
                let e = (s.dx - value(&coefficients, basis(s.time))).abs() / sigma(s);
                *w = (HUBER / e.max(1e-12)).min(1.0) / sigma(s).powi(2);
            }
        }
    }
    let misfit: f64 = samples
        .iter()
        .map(|s| huber((s.dx - value(&coefficients, basis(s.time))).abs() / sigma(s)))
        .sum();
    let roughness: f64 = coefficients
        .windows(4)
        .map(|c| (c[3] - 3.0 * c[2] + 3.0 * c[1] - c[0]).powi(2))
        .sum();
    Some((misfit + SMOOTHING * roughness, n))
}

/// The spline's value from a sample's coefficients' first index and basis values.
fn value(coefficients: &[f64], (j, b): (usize, [f64; 4])) -> f64 {
    (0..4).map(|i| coefficients[j + i] * b[i]).sum()
}

/// Adds the spline's roughness (its `n` coefficients' third differences squared, weighted by
/// [`SMOOTHING`]) to the normal equations `m`.
fn add_roughness(m: &mut Banded, n: usize) {
    const THIRD: [f64; 4] = [-1.0, 3.0, -3.0, 1.0];
    for i in 0..n.saturating_sub(3) {
        for (a, ta) in THIRD.iter().enumerate() {
            for (c, tc) in THIRD.iter().enumerate().take(a + 1) {
                m.add(i + a, i + c, SMOOTHING * ta * tc);
            }
        }
    }
}

/// The integral of the centred cubic B-spline [`bspline`] from -2 to `x`.
fn bspline_integral(x: f64) -> f64 {
    let a = x.abs();
    let half = if a >= 2.0 {
        0.5
    } else if a >= 1.0 {
        0.5 - (2.0 - a).powi(4) / 24.0
    } else {
        a * (2.0 / 3.0 + a * a * (a / 8.0 - 1.0 / 3.0))
    };
    if x >= 0.0 {
        0.5 + half
    } else {
        0.5 - half
    }
}

/// The image velocity (horizontal and vertical) as a cubic spline in time with a knot every
/// [`KNOT_SPACING`] frame intervals: the curve [`readout_from_motion`] tests `rho` with, here
/// fitted at a known `rho` to serve the correction of the frames (see
/// [`super::readout::RowMotion`]). Unlike the test's spline, this one is the velocity itself:
/// each displacement is fitted as the spline's mean over its frame interval (a box average,
/// exact for any speed changing within the interval), so integrating it through a frame's
/// readout gives the rows' offsets. Over a window of several frame pairs it follows a speed
/// swinging within a few frames through the part of each frame interval no row is read (half of
/// it at `rho = 0.5`), where a cubic through the frame pairs around one frame cannot.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct VelocitySpline {
    /// The knot index of the first coefficient (knot `j` at time `j * KNOT_SPACING`).
    first: i64,
    /// Horizontal coefficients, pixels per frame.
    x: Vec<f64>,
    /// Vertical coefficients.
    y: Vec<f64>,
}

/// Half a frame interval in knot intervals: the half-width of a displacement's box.
const BOX_HALF_WIDTH: f64 = 0.5 / KNOT_SPACING;

impl VelocitySpline {
    /// The robust (Huber) least-squares fit to `samples` (each the mean velocity over the frame
    /// interval centred at its time), with [`SMOOTHING`]'s light roughness penalty; `None`
    /// without samples or when they do not determine it (the caller wants three frame pairs or
    /// more).
    pub(crate) fn fit(samples: &[VelocitySample]) -> Option<Self> {
        let usable: Vec<&VelocitySample> = samples
            .iter()
            .filter(|s| s.time.is_finite() && s.dx.is_finite() && s.dy.is_finite())
            .filter(|s| s.sigma.is_finite() && s.sigma >= 0.0)
            .collect();
        let (lo, hi) = usable
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |a, s| {
                (a.0.min(s.time), a.1.max(s.time))
            });
        if !(lo.is_finite() && hi.is_finite()) {
            return None;
        }
        let reach = 2.0 + BOX_HALF_WIDTH;
        let first = (lo / KNOT_SPACING - reach).floor() as i64 + 1;
        let last = (hi / KNOT_SPACING + reach).ceil() as i64 - 1;
        let n = usize::try_from(last - first + 1).ok()?;
        let mut spline = Self {
            first,
            x: vec![0.0; n],
            y: vec![0.0; n],
        };
        let bases: Vec<(usize, [f64; 5])> =
            usable.iter().map(|s| spline.box_basis(s.time)).collect();
        let sigma = |s: &VelocitySample| s.sigma.max(MIN_SIGMA);
        let mut weights: Vec<f64> = usable.iter().map(|s| sigma(s).powi(-2)).collect();
        for round in 0..ROBUST_ROUNDS {
            let mut m = Banded::zeros(n, 4);
            let mut rx = vec![0.0; n];
            let mut ry = vec![0.0; n];
            for ((s, &w), (j, b)) in usable.iter().zip(&weights).zip(&bases) {
                for a in 0..5 {
                    if j + a >= n {
                        break;
                    }
                    for c in 0..=a {
                        m.add(j + a, j + c, w * b[a] * b[c]);
                    }
                    rx[j + a] += w * b[a] * s.dx;
                    ry[j + a] += w * b[a] * s.dy;
                }
            }
            add_roughness(&mut m, n);
            spline.x = m.clone().solve(&rx)?;
            spline.y = m.solve(&ry)?;
            if round + 1 < ROBUST_ROUNDS {
                for ((s, w), basis) in usable.iter().zip(&mut weights).zip(&bases) {
                    let (px, py) = spline.boxed(basis);
                    let e = (s.dx - px).hypot(s.dy - py) / sigma(s);
                    *w = (HUBER / e.max(1e-12)).min(1.0) / sigma(s).powi(2);
                }
            }
        }
        Some(spline)
    }

    /// The first coefficient's index and the 5 coefficients' weights in the mean over the frame
    /// interval centred at `t`.
    fn box_basis(&self, t: f64) -> (usize, [f64; 5]) {
        let x = t / KNOT_SPACING;
        let j = (x - 2.0 - BOX_HALF_WIDTH).floor() as i64 + 1;
        let values: [f64; 5] = std::array::from_fn(|i| {
            let d = x - (j + i as i64) as f64;
            (bspline_integral(d + BOX_HALF_WIDTH) - bspline_integral(d - BOX_HALF_WIDTH))
                / (2.0 * BOX_HALF_WIDTH)
        });
        ((j - self.first).max(0) as usize, values)
    }

    /// The mean velocity over the box `basis` (see [`Self::box_basis`]).
    fn boxed(&self, (j, b): &(usize, [f64; 5])) -> (f64, f64) {
        let mut v = (0.0, 0.0);
        for (i, w) in b.iter().enumerate() {
            if let (Some(cx), Some(cy)) = (self.x.get(j + i), self.y.get(j + i)) {
                v.0 += cx * w;
                v.1 += cy * w;
            }
        }
        v
    }
}

impl VelocityModel for VelocitySpline {
    fn velocity(&self, t: f64) -> (f64, f64) {
        let x = t / KNOT_SPACING;
        let j = x.floor() as i64 - 1;
        let mut v = (0.0, 0.0);
        for k in j..j + 4 {
            let Ok(i) = usize::try_from(k - self.first) else {
                continue;
            };
            if let (Some(cx), Some(cy)) = (self.x.get(i), self.y.get(i)) {
                let b = bspline(x - k as f64);
                v.0 += cx * b;
                v.1 += cy * b;
            }
        }
        v
    }

    fn displacement(&self, from: f64, to: f64) -> (f64, f64) {
        let (a, b) = (from / KNOT_SPACING, to / KNOT_SPACING);
        let mut d = (0.0, 0.0);
        for (i, (cx, cy)) in self.x.iter().zip(&self.y).enumerate() {
            let k = (self.first + i as i64) as f64;
            let w = (bspline_integral(b - k) - bspline_integral(a - k)) * KNOT_SPACING;
            d.0 += cx * w;
            d.1 += cy * w;
        }
        d
    }
}

/// The misfit of every stretch at readout `rho` (see [`stretch_misfit`]), with the displacements
/// and the spline coefficients it counted.
fn misfit(stretches: &[&[BandReading]], rho: f64, height: u32, phase: f64) -> (f64, usize, usize) {
    let mut samples = Vec::new();
    let (mut cost, mut scored, mut coefficients) = (0.0, 0, 0);
    for bands in stretches {
        if let Some((c, n)) = stretch_misfit(bands, rho, height, phase, &mut samples) {
            cost += c;
            scored += bands.len();
            coefficients += n;
        }
    }
    (cost, scored, coefficients)
}

/// The readout fraction that puts the measured band displacements on one smooth velocity curve
/// (see the module's comment), with its uncertainty; `None` without three measured frame pairs
/// close together. `bands` need not be sorted.
///
/// The search runs with the knots on the frames' starts and again halfway between: their mean
/// is the answer, and their difference (what the curve's own shape decides) widens the
/// uncertainty.
pub(crate) fn readout_from_motion(bands: &[BandReading], height: u32) -> Option<MotionTiming> {
    let mut sorted: Vec<BandReading> = bands
        .iter()
        .copied()
        .filter(|b| b.dx.is_finite() && b.dy.is_finite() && b.sigma.is_finite())
        .collect();
    sorted.sort_by(|a, b| a.pair.cmp(&b.pair).then(a.row.total_cmp(&b.row)));
    let stretches = stretches(&sorted);
    let (rho, uncertainty, n) = best_fit(&stretches, height, 0.0)?;
    let (other, other_uncertainty, _) = best_fit(&stretches, height, KNOT_SPACING / 2.0)?;
    let spread = jackknife(&sorted, height, rho).unwrap_or(0.0);
    Some(MotionTiming {
        readout_fraction: (rho + other) / 2.0,
        uncertainty: uncertainty
            .max(other_uncertainty)
            .max(spread)
            .hypot(rho - other),
        pairs: n / 8,
    })
}

/// The runs of `sorted` (sorted by pair) whose frame pairs are at most [`MAX_PAIR_STEP`] apart,
/// those of at least [`MIN_STRETCH`] frame pairs: each gets a spline of its own.
fn stretches(sorted: &[BandReading]) -> Vec<&[BandReading]> {
    sorted
        .chunk_by(|a, b| b.pair - a.pair <= MAX_PAIR_STEP)
        .filter(|s| s.chunk_by(|a, b| a.pair == b.pair).count() >= MIN_STRETCH)
        .collect()
}

/// Blocks of consecutive frame pairs left out in turn by [`jackknife`].
const JACKKNIFE_BLOCKS: usize = 16;

/// The delete-a-block jackknife's standard error of the readout found with the knots on the
/// frames' starts (`rho` over all of `sorted`, sorted by pair): the fit again with each of
/// [`JACKKNIFE_BLOCKS`] blocks of consecutive frame pairs left out. The misfit's curvature
/// counts every band as independent, but a frame pair's bands share its frames' content and
/// neighbouring pairs share a frame, so it claims several times the precision the clip holds;
/// the jackknife sees how far the answer moves with the data. `None` with too few frame pairs.
fn jackknife(sorted: &[BandReading], height: u32, rho: f64) -> Option<f64> {
    let pairs: Vec<u64> = {
        let mut p: Vec<u64> = sorted.iter().map(|b| b.pair).collect();
        p.dedup();
        p
    };
    if pairs.len() < 3 * JACKKNIFE_BLOCKS {
        return None;
    }
    let mut kept: Vec<BandReading> = Vec::with_capacity(sorted.len());
    let mut found = Vec::with_capacity(JACKKNIFE_BLOCKS);
    for g in 0..JACKKNIFE_BLOCKS {
        let (lo, hi) = (
            pairs[g * pairs.len() / JACKKNIFE_BLOCKS],
            pairs[((g + 1) * pairs.len() / JACKKNIFE_BLOCKS).min(pairs.len()) - 1],
        );
        kept.clear();
        kept.extend(sorted.iter().filter(|b| b.pair < lo || b.pair > hi));
        let stretches = stretches(&kept);
        let cost = |r: f64| misfit(&stretches, r, height, 0.0).0;
        found.push(golden_minimum(cost, rho - 0.1, rho + 0.1, 16)?);
    }
    let g = JACKKNIFE_BLOCKS as f64;
    let mean = found.iter().sum::<f64>() / g;
    let variance = (g - 1.0) / g * found.iter().map(|r| (r - mean).powi(2)).sum::<f64>();
    Some(variance.sqrt())
}

/// The minimum of `cost` on `[lo, hi]` (within [`RHO_RANGE`]) by golden-section search,
/// `rounds` times; `None` when the bracket is empty.
fn golden_minimum(cost: impl Fn(f64) -> f64, lo: f64, hi: f64, rounds: usize) -> Option<f64> {
    let (mut lo, mut hi) = (lo.max(RHO_RANGE.0), hi.min(RHO_RANGE.1));
    if lo >= hi {
        return None;
    }
    let g = (5f64.sqrt() - 1.0) / 2.0;
    for _ in 0..rounds {
        let (a, b) = (hi - g * (hi - lo), lo + g * (hi - lo));
        if cost(a) < cost(b) {
            hi = b;
        } else {
            lo = a;
        }
    }
    Some((lo + hi) / 2.0)
}

/// The readout fraction of least [`misfit`] (a grid, then golden-section search about its best
/// point), its uncertainty from the misfit's curvature, and the displacements scored.
fn best_fit(stretches: &[&[BandReading]], height: u32, phase: f64) -> Option<(f64, f64, usize)> {
    let cost = |rho: f64| misfit(stretches, rho, height, phase).0;
    let (_, n, _) = misfit(stretches, 0.8, height, phase);
    if n < 16 {
        return None;
    }
    let step = 0.05;
    let (best, _) = (0..)
        .map(|i| RHO_RANGE.0 + step * f64::from(i))
        .take_while(|&r| r <= RHO_RANGE.1 + 1e-9)
        .map(|r| (r, cost(r)))
        .min_by(|a, b| a.1.total_cmp(&b.1))?;
    let rho = golden_minimum(cost, best - step, best + step, 20)?;
    // The curvature of the misfit (a chi-square in the bands' sigmas) about its minimum, scaled
    // by the residual spread actually seen (the bands' sigmas are rough) over the degrees of
    // freedom the spline leaves.
    let h = 0.01;
    let (c0, n, coefficients) = misfit(stretches, rho, height, phase);
    let curvature = (cost(rho + h) - 2.0 * c0 + cost(rho - h)) / (h * h);
    let spread = (c0 / n.saturating_sub(coefficients).max(1) as f64).max(1.0);
    let uncertainty = if curvature > 1e-12 {
        (2.0 * spread / curvature).sqrt()
    } else {
        f64::INFINITY
    };
    Some((rho, uncertainty, n))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;
    use crate::video::readout::row_time;

    /// 8 bands per frame pair of a content position `u(t)` read out over `rho`, with noise.
    fn bands(
        u: impl Fn(f64) -> f64,
        frames: u64,
        rho: f64,
        h: u32,
        noise: f64,
    ) -> Vec<BandReading> {
        let mut rng = SplitMix64::new(7);
        let mut out = Vec::new();
        for pair in 0..frames {
            for b in 0..8 {
                let y = (f64::from(b) + 0.5) * f64::from(h) / 8.0;
                let t = row_time(pair as f64, y, rho, h);
                out.push(BandReading {
                    pair,
                    row: y,
                    dx: u(t + 1.0) - u(t) + noise * rng.symmetric(1.7),
                    dy: 0.0,
                    sigma: noise.max(0.1),
                });
            }
        }
        out
    }

    /// A hand's shake (1.5 and 3.5 Hz at 30 frames/s, up to about 200 px per frame): `rho`
    /// within 2%, half of each frame interval unread (0.5) or none, and the stated uncertainty
    /// covers the error.
    #[test]
    fn a_shake_tells_the_readout() {
        let h = 720;
        let u = |t: f64| {
            let w1 = 2.0 * std::f64::consts::PI * 1.5 / 30.0;
            let w2 = 2.0 * std::f64::consts::PI * 3.5 / 30.0;
            -150.0 / w1 * (w1 * t).cos() - 60.0 / w2 * (w2 * t + 1.0).cos()
        };
        for rho in [0.5, 0.8, 1.0] {
            let found = readout_from_motion(&bands(u, 40, rho, h, 0.2), h).expect("found");
            eprintln!("rho {rho}: {found:?}");
            let error = (found.readout_fraction - rho).abs();
            assert!(error <= 2.0 * found.uncertainty, "{rho}: {found:?}");
            assert!(error <= 0.02 * rho, "{rho}: {found:?}");
            assert!(found.uncertainty < 0.05, "{found:?}");
        }
    }

    /// Errors shared by a frame pair's bands (a slope across the rows that differs from pair to
    /// pair, as a subject or the frames' own content leave): the curvature of the misfit, which
    /// counts every band as independent, claims a third of the true spread (the errors of 12
    /// clips are 3.3 of its sigmas, root mean square); with the jackknife the stated uncertainty
    /// is fair: the errors' root mean square under 2 sigmas and none beyond 4 (the jackknife's
    /// own estimate varies by about a fifth from clip to clip).
    #[test]
    fn errors_shared_by_a_pairs_bands_widen_the_uncertainty() {
        let (h, rho) = (720, 0.8);
        let u = |t: f64| {
            let w1 = 2.0 * std::f64::consts::PI * 1.5 / 30.0;
            -150.0 / w1 * (w1 * t).cos()
        };
        let mut squares = 0.0;
        for seed in 0..12 {
            let mut rng = SplitMix64::new(100 + seed);
            let mut b = bands(u, 60, rho, h, 0.2);
            for pair in b.chunk_by_mut(|a, b| a.pair == b.pair) {
                let slope = rng.symmetric(3.0);
                for r in pair {
                    r.dx += slope * (r.row / f64::from(h) - 0.5);
                }
            }
            let found = readout_from_motion(&b, h).expect("found");
            let z = (found.readout_fraction - rho).abs() / found.uncertainty;
            eprintln!("seed {seed}: {found:?}, {z:.2} sigma");
            assert!(z < 4.0, "{found:?}");
            squares += z * z;
        }
        let rms = (squares / 12.0).sqrt();
        assert!(rms < 2.0, "{rms} sigma");
    }

    /// The speed swinging within a frame (`432 sin(2 pi t / 8)` px per frame, the simulator's
    /// swing at a peak shear of 0.3 on 720 rows) at `rho = 0.5`, noise-free: half of each frame
    /// interval is read by no row, and a cubic through three frame pairs put `rho` 10% high
    /// (0.548). The spline finds it within 0.1% whatever the swing's phase; 1% leaves room for
    /// the knots' placement and stays a third of the 3% the calibration is meant to reach. The
    /// same swing at 6 frames' period, and at `rho` 0.8 and 1, within 1% too.
    #[test]
    fn a_fast_swing_at_a_short_readout_tells_the_readout() {
        let h = 720;
        for (rho, period, phase) in [
            (0.5, 8.0, 0.0),
            (0.5, 8.0, 1.0),
            (0.5, 6.0, 0.0),
            (0.8, 8.0, 0.0),
            (1.0, 8.0, 0.0),
        ] {
            let v = 0.3 * f64::from(h) / rho;
            let w = 2.0 * std::f64::consts::PI / period;
            let u = |t: f64| -v / w * (w * t + phase).cos();
            let found = readout_from_motion(&bands(u, 60, rho, h, 0.0), h).expect("found");
            eprintln!("rho {rho}, period {period}, phase {phase}: {found:?}");
            assert!(
                (found.readout_fraction - rho).abs() <= 0.01 * rho,
                "{rho}: {found:?}"
            );
            assert!(found.uncertainty < 0.02, "{found:?}");
        }
    }

    /// The per-frame curve on the swing of 8 frames' period at `rho = 0.5` (432 px per frame,
    /// noise-free): the spline through the 8 frame pairs around a frame, as the correction fits
    /// it, gives every row's offset within 0.3 px of the truth (a hundredth of a shear of 0.01
    /// over 720 rows is 3.6 px; the rows-left p95 of the simulated clips is over 1 px), and `k`
    /// within 1e-3, at every phase of the swing; the cubic about the frame (`VelocityCurve`,
    /// the bands of four frame pairs) is several times further off.
    #[test]
    fn the_spline_follows_a_fast_swing_through_each_frames_readout() {
        use crate::video::readout::{RowMotion, VelocityCurve};
        let (rho, h) = (0.5, 720u32);
        let w = 2.0 * std::f64::consts::PI / 8.0;
        let v = 432.0;
        let u = |t: f64| -v / w * (w * t).cos();
        let all = bands(u, 40, rho, h, 0.0);
        let samples_of = |lo: u64, hi: u64| -> Vec<VelocitySample> {
            all.iter()
                .filter(|b| (lo..=hi).contains(&b.pair))
                .map(|b| VelocitySample::from_band(b.pair as f64, b.row, b.dx, b.dy, 0.3, rho, h))
                .collect()
        };
        let (mut worst_spline, mut worst_cubic) = (0.0f64, 0.0f64);
        for frame in 10..18u64 {
            let n = frame as f64;
            let spline = VelocitySpline::fit(&samples_of(frame - 4, frame + 3)).expect("fit");
            let m = RowMotion::of(&spline, n, rho, h, false);
            let cubic = VelocityCurve::fit(&samples_of(frame - 2, frame + 1), n + rho / 2.0)
                .expect("cubic");
            let c = RowMotion::of(&cubic, n, rho, h, false);
            let mid = row_time(n, 360.0, rho, h);
            for y in (0..h).step_by(8) {
                let truth = u(row_time(n, f64::from(y), rho, h)) - u(mid);
                worst_spline = worst_spline.max((m.shifts[y as usize] - truth).abs());
                worst_cubic = worst_cubic.max((c.shifts[y as usize] - truth).abs());
            }
            let k = rho * v * (w * mid).sin() / f64::from(h);
            assert!((m.k - k).abs() < 1e-3, "frame {frame}: k {} vs {k}", m.k);
        }
        eprintln!("worst row offset: spline {worst_spline:.3} px, cubic {worst_cubic:.3} px");
        assert!(worst_spline < 0.3, "{worst_spline}");
        assert!(
            worst_cubic > 3.0 * worst_spline,
            "{worst_cubic} {worst_spline}"
        );
    }

    /// The spline's mean over a frame interval is what a displacement measures: fitted to the
    /// displacements of a velocity that is itself a cubic spline with the same knots, it finds
    /// that velocity exactly.
    #[test]
    fn the_velocity_spline_is_fitted_as_box_averages() {
        let (rho, h) = (0.8, 720u32);
        // u(t) = t^3: the velocity 3 t^2, a cubic (one spline piece everywhere).
        let u = |t: f64| t * t * t / 10.0;
        let samples: Vec<VelocitySample> = bands(u, 12, rho, h, 0.0)
            .iter()
            .map(|b| VelocitySample::from_band(b.pair as f64, b.row, b.dx, b.dy, 0.3, rho, h))
            .collect();
        let spline = VelocitySpline::fit(&samples).expect("fit");
        for t in [2.0, 4.3, 7.9] {
            let (vx, vy) = spline.velocity(t);
            assert!((vx - 0.3 * t * t).abs() < 1e-3, "{t}: {vx}");
            assert!(vy.abs() < 1e-9);
            let (dx, _) = spline.displacement(t, t + 0.7);
            assert!((dx - (u(t + 0.7) - u(t))).abs() < 1e-3, "{t}: {dx}");
        }
    }

    /// Unmeasured frame pairs (one in seven, and a stretch of ten) cost nothing but their bands.
    #[test]
    fn gaps_in_the_motion_are_bridged_or_split() {
        let h = 720;
        let rho = 0.5;
        let w = 2.0 * std::f64::consts::PI / 8.0;
        let u = |t: f64| -432.0 / w * (w * t).cos();
        let all = bands(u, 80, rho, h, 0.2);
        let kept: Vec<BandReading> = all
            .into_iter()
            .filter(|b| b.pair % 7 != 3 && !(30..40).contains(&b.pair))
            .collect();
        let found = readout_from_motion(&kept, h).expect("found");
        assert!(
            (found.readout_fraction - rho).abs() <= 0.01 * rho,
            "{found:?}"
        );
    }

    /// A pan easing to a stop (a steady deceleration) is followed exactly by the curves.
    #[test]
    fn a_pan_easing_to_a_stop_tells_the_readout() {
        let h = 720;
        for rho in [0.5, 0.8, 1.0] {
            let u = |t: f64| 240.0 * t - 240.0 * t * t / 48.0;
            let found = readout_from_motion(&bands(u, 24, rho, h, 0.2), h).expect("found");
            assert!(
                (found.readout_fraction - rho).abs() <= 0.02 * rho,
                "{rho}: {found:?}"
            );
        }
    }

    #[test]
    fn a_steady_pan_tells_nothing() {
        let h = 720;
        let found = readout_from_motion(&bands(|t| 200.0 * t, 40, 0.8, h, 0.2), h);
        eprintln!("{found:?}");
        if let Some(f) = found {
            assert!(f.uncertainty > 0.2, "{f:?}");
        }
    }

    #[test]
    fn too_few_frames_tell_nothing() {
        let h = 720;
        let u = |t: f64| 100.0 * (t / 3.0).sin();
        assert!(readout_from_motion(&bands(u, 2, 0.8, h, 0.2), h).is_none());
        assert!(readout_from_motion(&[], h).is_none());
    }
}

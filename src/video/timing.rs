//! The readout fraction from the motion alone, when the camera's speed changes.
//!
//! Under a rolling shutter a band of rows at row `y` measures, between frames `p` and `p + 1`,
//! the content's mean velocity over the frame interval starting when frame `p` reads that band,
//! at `p + rho * y / H`. So the bands of one frame pair sample the velocity at times spread over
//! `rho` of a frame interval: when the speed changes (a hand's shake, a pan easing to a stop),
//! the displacements change from band to band as much as `rho` stretches the time between them,
//! and only the true `rho` puts the bands of neighbouring frame pairs on one smooth velocity
//! curve. [`readout_from_motion`] finds the `rho` that does: no face needed. A steady pan says
//! nothing (every band measures the same velocity whatever `rho`), and says so through a wide
//! uncertainty.

use super::readout::{VelocityCurve, VelocitySample};

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
    /// 1-sigma, from the misfit's curvature scaled by its residual spread.
    pub uncertainty: f64,
    /// Frame pairs that took part (with both neighbours measured), counted as 8 bands each.
    pub pairs: usize,
}

/// Displacements this many sigmas off count less (Huber), so a band that a passing subject
/// pulled does not decide.
const HUBER: f64 = 3.0;
/// The smallest uncertainty given to one band: below it the smooth curve's own misfit dominates.
const MIN_SIGMA: f64 = 0.3;
/// The readout fractions searched.
const RHO_RANGE: (f64, f64) = (0.05, 1.2);

/// The misfit of the bands of `pairs` (sorted by pair, each pair's bands together) to one smooth
/// velocity curve per pair through it and its `half` neighbours on each side, at readout `rho`;
/// with the number of displacements scored.
fn misfit(pairs: &[(u64, &[BandReading])], rho: f64, height: u32, half: usize) -> (f64, usize) {
    let mut cost = 0.0;
    let mut scored = 0;
    let mut samples = Vec::with_capacity(64);
    for w in pairs.windows(2 * half + 1) {
        let first = w[0].0;
        if w.iter()
            .enumerate()
            .any(|(i, (p, _))| *p != first + i as u64)
        {
            continue;
        }
        let (b, mid) = w[half];
        samples.clear();
        for (_, bands) in w {
            samples.extend(bands.iter().map(|r| {
                VelocitySample::from_band(r.pair as f64, r.row, r.dx, r.dy, r.sigma, rho, height)
            }));
        }
        let t0 = b as f64 + 0.5 + rho / 2.0;
        let Some(curve) = VelocityCurve::fit_all(&samples, t0) else {
            continue;
        };
        for r in mid.iter() {
            let s =
                VelocitySample::from_band(r.pair as f64, r.row, r.dx, r.dy, r.sigma, rho, height);
            let e = (s.dx - curve.mean_velocity(s.time).0).abs() / s.sigma.max(MIN_SIGMA);
            cost += if e <= HUBER {
                e * e
            } else {
                2.0 * HUBER * e - HUBER * HUBER
            };
            scored += 1;
        }
    }
    (cost, scored)
}

/// The readout fraction that puts the measured band displacements on smooth velocity curves
/// (see the module's comment), with its uncertainty; `None` without three consecutive measured
/// frame pairs. `bands` need not be sorted.
///
/// The curves are cubics in time over three frame pairs: a shake faster than they can follow
/// (a few frames per period), seen through the gaps a short readout leaves between frames,
/// biases `rho`. The same search over five frame pairs errs differently, so the two answers'
/// difference is added to the uncertainty.
pub(crate) fn readout_from_motion(bands: &[BandReading], height: u32) -> Option<MotionTiming> {
    let mut sorted: Vec<BandReading> = bands
        .iter()
        .copied()
        .filter(|b| b.dx.is_finite() && b.dy.is_finite() && b.sigma.is_finite())
        .collect();
    sorted.sort_by(|a, b| a.pair.cmp(&b.pair).then(a.row.total_cmp(&b.row)));
    let pairs: Vec<(u64, &[BandReading])> = sorted
        .chunk_by(|a, b| a.pair == b.pair)
        .map(|c| (c[0].pair, c))
        .collect();
    let (rho, uncertainty, n) = best_fit(&pairs, height, 1)?;
    let wide = best_fit(&pairs, height, 2).map_or(0.0, |(r, _, _)| (r - rho).abs());
    Some(MotionTiming {
        readout_fraction: rho,
        uncertainty: uncertainty.hypot(wide),
        pairs: n / 8,
    })
}

/// The readout fraction of least [`misfit`] (a grid, then golden-section search about its best
/// point), its uncertainty from the misfit's curvature, and the displacements scored.
fn best_fit(
    pairs: &[(u64, &[BandReading])],
    height: u32,
    half: usize,
) -> Option<(f64, f64, usize)> {
    let cost = |rho: f64| misfit(pairs, rho, height, half).0;
    let (_, n) = misfit(pairs, 0.8, height, half);
    if n < 16 {
        return None;
    }
    let step = 0.05;
    let (best, _) = (0..)
        .map(|i| RHO_RANGE.0 + step * f64::from(i))
        .take_while(|&r| r <= RHO_RANGE.1 + 1e-9)
        .map(|r| (r, cost(r)))
        .min_by(|a, b| a.1.total_cmp(&b.1))?;
    let (mut lo, mut hi) = (
        (best - step).max(RHO_RANGE.0),
        (best + step).min(RHO_RANGE.1),
    );
    let g = (5f64.sqrt() - 1.0) / 2.0;
    for _ in 0..20 {
        let (a, b) = (hi - g * (hi - lo), lo + g * (hi - lo));
        if cost(a) < cost(b) {
            hi = b;
        } else {
            lo = a;
        }
    }
    let rho = (lo + hi) / 2.0;
    // The curvature of the misfit (a chi-square in the bands' sigmas) about its minimum, scaled
    // by the residual spread actually seen (the bands' sigmas are rough). Each curve takes 4 of
    // the 24 or so displacements it is fitted to.
    let h = 0.01;
    let c0 = cost(rho);
    let curvature = (cost(rho + h) - 2.0 * c0 + cost(rho - h)) / (h * h);
    let spread = (c0 / (n as f64 * 5.0 / 6.0)).max(1.0);
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
    /// within 2% at 0.8 and 1; at 0.5 (half of each frame interval unread) the curves are
    /// less sure, and the stated uncertainty covers the error.
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
            if rho >= 0.8 {
                assert!(error <= 0.02 * rho, "{rho}: {found:?}");
                assert!(found.uncertainty < 0.05, "{found:?}");
            }
        }
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

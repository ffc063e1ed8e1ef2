//! The scene's verticals as a second ruler: when the camera moved during the readout, everything
//! static in the frame is sheared by the same `k`, so near-vertical structures (door frames,
//! poles, building edges, window columns) lean together, `dx/dy = k`, while horizontals stay
//! level.
//!
//! Two other things tilt verticals and must not be read as shear:
//!
//! * **A roll** of the camera by `a` turns verticals to `dx/dy = -tan a` but also horizontals to
//!   `dy/dx = tan a`, which a shear leaves level. Rolled, then sheared by the readout, verticals
//!   have `dx/dy = k - t` and horizontals `dy/dx = t / (1 + k t)` (`t = tan a`): the horizontals
//!   give `t`, and `k` follows. Without horizontals that agree, the roll is taken as 0 and its
//!   typical size ([`ROLL_PRIOR`]) is added to the uncertainty.
//! * **A pitched camera** makes verticals converge on a vanishing point instead of leaning
//!   together. A shear keeps lines through that point through one point (it is linear), so each
//!   vertical's tilt is linear in where it crosses the middle row: `s = k + w u`, with `u` that
//!   crossing's offset from the middle column (in long sides of the picture) and `w` the
//!   convergence (0 for a level camera). `k` is then the tilt of the vertical through the centre,
//!   and a Gaussian prior on `w` ([`CONVERGENCE_PRIOR`]) makes the uncertainty grow when the
//!   verticals sit on one side of the picture, where pitch and shear cannot be told apart.
//!
//! The segments come from the `lsdetect` crate (the LSD line segment detector of Grompone von
//! Gioi et al., pure Rust, only `rayon` beside it) on a picture box-averaged down to about
//! [`WORKING_SIDE`] pixels on its long side. The consensus is hand-written (a few dozen lines): a
//! search over the tilts each segment or pair of long segments proposes, scored by the length of
//! the segments that agree (MSAC); refused when a second group of tilts, disjoint from the
//! first, is nearly as strong (a leaning stair beside true verticals) or when the agreeing
//! segments lie on fewer than [`MIN_LINES`] distinct lines (a single tilted pole), then a
//! weighted least-squares fit on the distinct lines gives `k` and its uncertainty.

use image::GrayImage;
use serde::{Deserialize, Serialize};

use crate::geometry::Point;

/// Long side (pixels) the picture is box-averaged down to before segments are looked for: the
/// detector's time grows with the pixels, and a building edge 100 px long in a 1080p frame is
/// still 40 px long there.
pub const WORKING_SIDE: u32 = 800;

/// Largest |dx/dy| of a segment that may vote as a vertical: beyond it a segment is a diagonal
/// (a roof, a stair), not a sheared vertical (the development shears reach 0.40).
pub const MAX_TILT: f64 = 0.5;

/// Largest |dy/dx| of a segment taken as a horizontal for the roll (about 8.5 degrees).
const MAX_LEVEL_TILT: f64 = 0.15;

/// Fewest distinct lines (segments of one line, or of the two edges of one pole, count once)
/// whose tilts must agree: one or two leaning structures alone are not a shear.
pub const MIN_LINES: usize = 3;

/// Largest uncertainty (one standard deviation of `k`) at which the scene's reading is given.
pub const DEFAULT_MAX_UNCERTAINTY: f64 = 0.03;

/// Typical size of an unseen roll, as `tan` (about 1.1 degrees): the uncertainty's roll term
/// when no horizontals say what the roll is. Hand-held photos are levelled by eye to a degree
/// or two.
pub const ROLL_PRIOR: f64 = 0.02;

/// Standard deviation of the prior on the convergence `w` (per long side): a camera pitched by
/// 10 degrees with a focal length of one long side makes `w = tan 10° = 0.18`.
pub const CONVERGENCE_PRIOR: f64 = 0.18;

/// How far (one standard deviation of `dx/dy`) real verticals stray from true, at least: walls
/// and poles are not plumb to better than about half a degree, and lenses bend lines.
const STRUCTURE_SCATTER: f64 = 0.01;

/// A segment's end points' error, in the detector's pixels (LSD's are sub-pixel).
const ENDPOINT_ERROR: f64 = 0.7;

/// Tilt tolerance of the consensus, added to twice a segment's own tilt error.
const TILT_TOLERANCE: f64 = 0.015;

/// Shortest segment that votes, as a share of the picture's height: shorter ones' tilts are
/// too noisy and mostly texture.
const MIN_LENGTH: f64 = 0.04;

/// Segments whose crossings of the middle row (or, for horizontals, of the middle column) are
/// closer than this share of the long side are one line (or one pole's two edges).
const SAME_LINE: f64 = 0.02;

/// A second, disjoint group of tilts with at least this share of the best group's weight makes
/// the reading ambiguous.
const RIVAL_SHARE: f64 = 0.5;

/// How the scene's shear is estimated.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct SceneParams {
    /// Largest uncertainty at which a reading is given.
    pub(crate) max_uncertainty: f64,
}

impl Default for SceneParams {
    fn default() -> Self {
        Self {
            max_uncertainty: DEFAULT_MAX_UNCERTAINTY,
        }
    }
}

/// A line segment in input-image pixels.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SceneSegment {
    /// One end.
    pub from: Point,
    /// The other end.
    pub to: Point,
}

/// The shear the scene's verticals give: a second ruler beside the faces ([`ImageReport::scene`](crate::ImageReport::scene); how it is read: docs/how-it-works.md).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[non_exhaustive]
pub struct SceneShear {
    /// The shear: the tilt `dx/dy` of the vertical through the picture's centre, the roll taken
    /// out.
    pub k: f64,
    /// One standard deviation of `k`: the lines' scatter, the roll's and the convergence's.
    pub uncertainty: f64,
    /// How many segments voted.
    pub segments: usize,
    /// On how many distinct lines they lie.
    pub lines: usize,
    /// Their total length, in picture heights.
    pub length: f64,
    /// The camera's roll the horizontals give, degrees (positive: the picture's right side
    /// lower), `None` when they do not agree on one (then taken as 0).
    pub roll_degrees: Option<f64>,
    /// How fast the verticals' tilt changes across the picture (per long side; 0 when they are
    /// parallel, as from a level camera).
    pub convergence: f64,
    /// The segments that voted for `k` (verticals) and for the roll (horizontals).
    pub voters: Vec<SceneSegment>,
}

/// One detected segment as the consensus sees it.
#[derive(Debug, Clone, Copy)]
struct Candidate {
    segment: SceneSegment,
    /// `dx/dy` for a vertical, `dy/dx` for a horizontal.
    tilt: f64,
    /// Where its line crosses the middle row (a vertical) or column (a horizontal), from the
    /// middle, in long sides.
    offset: f64,
    /// Length, input pixels.
    length: f64,
    /// Its tilt's own error (one standard deviation).
    error: f64,
}

impl Candidate {
    fn tolerance(&self) -> f64 {
        TILT_TOLERANCE + 2.0 * self.error
    }

    /// MSAC weight of this segment under a model predicting `tilt`: its length, less as it
    /// strays, 0 beyond the tolerance.
    fn vote(&self, predicted: f64) -> f64 {
        let r = (self.tilt - predicted) / self.tolerance();
        self.length * (1.0 - r * r).max(0.0)
    }
}

/// A model of the tilts: `tilt = level + slope * offset`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Model {
    level: f64,
    slope: f64,
}

impl Model {
    fn at(&self, offset: f64) -> f64 {
        self.level + self.slope * offset
    }
}

/// The shear the scene's verticals give, `None` when they give none that can be trusted (too
/// few agreeing lines, two groups that disagree, or an uncertainty above
/// `params.max_uncertainty`).
pub(crate) fn estimate_scene_shear(gray: &GrayImage, params: &SceneParams) -> Option<SceneShear> {
    let (width, height) = gray.dimensions();
    let long = width.max(height);
    if width < 16 || height < 16 {
        return None;
    }
    let factor = long.div_ceil(WORKING_SIDE).max(1);
    let (small, sw, sh) = box_average(gray, factor);
    let found = lsdetect::detect(&small, sw, sh, lsdetect::SCALE).ok()?;
    let (w, h, l) = (f64::from(width), f64::from(height), f64::from(long));
    let f = f64::from(factor);
    let to_input = |x: f64, y: f64| Point::new(x * f + (f - 1.0) / 2.0, y * f + (f - 1.0) / 2.0);
    let (centre, middle) = (w / 2.0, h / 2.0);
    let mut verticals = Vec::new();
    let mut horizontals = Vec::new();
    for s in &found {
        let (a, b) = (to_input(s.x1, s.y1), to_input(s.x2, s.y2));
        let (dx, dy) = (b.x - a.x, b.y - a.y);
        let length = dx.hypot(dy);
        if length.is_nan() || length < MIN_LENGTH * h {
            continue;
        }
        let error = std::f64::consts::SQRT_2 * ENDPOINT_ERROR * f / length;
        let mid = a.midpoint(b);
        let segment = SceneSegment { from: a, to: b };
        if dy.abs() > 0.0 && (dx / dy).abs() <= MAX_TILT {
            let tilt = dx / dy;
            let offset = (mid.x - centre + tilt * (middle - mid.y)) / l;
            verticals.push(Candidate {
                segment,
                tilt,
                offset,
                length,
                error,
            });
        } else if dx.abs() > 0.0 && (dy / dx).abs() <= MAX_LEVEL_TILT {
            let tilt = dy / dx;
            let offset = (mid.y - middle + tilt * (centre - mid.x)) / l;
            horizontals.push(Candidate {
                segment,
                tilt,
                offset,
                length,
                error,
            });
        }
    }
    let vertical = consensus(&verticals, true)?;
    let level = consensus(&horizontals, false);
    let (mut k, mut variance) = (vertical.fit.level, vertical.variance);
    let roll = match &level {
        Some(level) => {
            // dy/dx of the horizontals is t / (1 + k t): t = h / (1 - h k), and k = v + t.
            let hz = level.fit.level;
            for _ in 0..3 {
                k = vertical.fit.level + hz / (1.0 - hz * k);
            }
            variance += level.variance;
            Some((hz / (1.0 - hz * k)).atan().to_degrees())
        }
        None => {
            variance += ROLL_PRIOR * ROLL_PRIOR;
            None
        }
    };
    let uncertainty = variance.sqrt();
    if !(k.is_finite() && uncertainty <= params.max_uncertainty) {
        return None;
    }
    let voters = vertical
        .inliers
        .iter()
        .map(|&i| verticals[i].segment)
        .chain(
            level
                .iter()
                .flat_map(|g| g.inliers.iter().map(|&i| horizontals[i].segment)),
        )
        .collect();
    Some(SceneShear {
        k,
        uncertainty,
        segments: vertical.inliers.len(),
        lines: vertical.lines,
        length: vertical
            .inliers
            .iter()
            .map(|&i| verticals[i].length)
            .sum::<f64>()
            / h,
        roll_degrees: roll,
        convergence: vertical.fit.slope,
        voters,
    })
}

/// The picture averaged over `factor` x `factor` blocks (the remainder rows and columns
/// dropped), as the detector's samples, with its width and height.
fn box_average(gray: &GrayImage, factor: u32) -> (Vec<f32>, usize, usize) {
    let (w, h) = gray.dimensions();
    let (sw, sh) = ((w / factor) as usize, (h / factor) as usize);
    let n = factor as usize;
    let raw = gray.as_raw();
    let width = w as usize;
    let mut out = vec![0.0f32; sw * sh];
    let scale = 1.0 / (n * n) as f32;
    let mut sums = vec![0u32; sw];
    for (y, row) in out.chunks_mut(sw.max(1)).enumerate().take(sh) {
        sums.iter_mut().for_each(|s| *s = 0);
        for r in 0..n {
            let line = &raw[(y * n + r) * width..(y * n + r) * width + sw * n];
            for (s, block) in sums.iter_mut().zip(line.chunks_exact(n)) {
                *s += block.iter().map(|&v| u32::from(v)).sum::<u32>();
            }
        }
        for (o, &s) in row.iter_mut().zip(&sums) {
            *o = s as f32 * scale;
        }
    }
    (out, sw, sh)
}

/// A group of segments whose tilts agree, and the fit through them.
#[derive(Debug, Clone)]
struct Group {
    fit: Model,
    /// Variance of `fit.level`.
    variance: f64,
    /// The segments (indices) that agree.
    inliers: Vec<usize>,
    /// On how many distinct lines they lie.
    lines: usize,
}

/// The group of `candidates` whose tilts agree, with the fit through its distinct lines:
/// `converging` lets the tilt change linearly across the picture (verticals under pitch,
/// with the prior [`CONVERGENCE_PRIOR`]); otherwise the tilt is one value. `None` when the
/// group's lines are fewer than [`MIN_LINES`] or a disjoint group rivals it.
fn consensus(candidates: &[Candidate], converging: bool) -> Option<Group> {
    if candidates.len() < MIN_LINES {
        return None;
    }
    let mut models: Vec<Model> = candidates
        .iter()
        .map(|c| Model {
            level: c.tilt,
            slope: 0.0,
        })
        .collect();
    if converging {
        // Pairs of the longest segments, far enough apart to say how the tilt changes.
        let mut longest: Vec<&Candidate> = candidates.iter().collect();
        longest.sort_by(|a, b| b.length.total_cmp(&a.length));
        longest.truncate(40);
        for (i, a) in longest.iter().enumerate() {
            for b in &longest[i + 1..] {
                let du = b.offset - a.offset;
                if du.abs() < 0.05 {
                    continue;
                }
                let slope = (b.tilt - a.tilt) / du;
                if slope.abs() <= 3.0 * CONVERGENCE_PRIOR {
                    models.push(Model {
                        level: a.tilt - slope * a.offset,
                        slope,
                    });
                }
            }
        }
    }
    let score = |m: &Model, skip: &[bool]| -> f64 {
        candidates
            .iter()
            .zip(skip)
            .filter(|(_, &s)| !s)
            .map(|(c, _)| c.vote(m.at(c.offset)))
            .sum()
    };
    let none = vec![false; candidates.len()];
    let best = models
        .iter()
        .map(|m| (*m, score(m, &none)))
        .max_by(|a, b| a.1.total_cmp(&b.1))?;
    if best.1 <= 0.0 {
        return None;
    }
    let agrees = |m: &Model| -> Vec<bool> {
        candidates
            .iter()
            .map(|c| (c.tilt - m.at(c.offset)).abs() <= c.tolerance())
            .collect()
    };
    let taken = agrees(&best.0);
    let rival = models.iter().map(|m| score(m, &taken)).fold(0.0, f64::max);
    if rival >= RIVAL_SHARE * best.1 {
        return None;
    }
    // Fit, then take the segments that agree with the fit and fit again.
    let mut fit = best.0;
    let mut group = None;
    for _ in 0..2 {
        let inliers: Vec<usize> = agrees(&fit)
            .iter()
            .enumerate()
            .filter_map(|(i, &a)| a.then_some(i))
            .collect();
        let lines = distinct_lines(candidates, &inliers);
        if lines.len() < MIN_LINES {
            return None;
        }
        let (model, variance) = fit_lines(&lines, converging)?;
        fit = model;
        group = Some(Group {
            fit,
            variance,
            lines: lines.len(),
            inliers,
        });
    }
    group
}

/// One distinct line: its segments' length-weighted tilt and offset, their total length and
/// the tilt's own error.
#[derive(Debug, Clone, Copy)]
struct Line {
    tilt: f64,
    offset: f64,
    length: f64,
    error: f64,
}

/// The segments `inliers` of `candidates` merged into distinct lines: sorted by offset, a
/// segment within [`SAME_LINE`] of the line before joins it.
fn distinct_lines(candidates: &[Candidate], inliers: &[usize]) -> Vec<Line> {
    let mut sorted: Vec<&Candidate> = inliers.iter().map(|&i| &candidates[i]).collect();
    sorted.sort_by(|a, b| a.offset.total_cmp(&b.offset));
    let mut lines: Vec<(Line, f64)> = Vec::new();
    for c in sorted {
        match lines.last_mut() {
            Some((line, last)) if c.offset - *last <= SAME_LINE => {
                let total = line.length + c.length;
                line.tilt = (line.tilt * line.length + c.tilt * c.length) / total;
                line.offset = (line.offset * line.length + c.offset * c.length) / total;
                // Segments of one line share its error; the longest sets it.
                line.error = line.error.min(c.error);
                line.length = total;
                *last = c.offset;
            }
            _ => lines.push((
                Line {
                    tilt: c.tilt,
                    offset: c.offset,
                    length: c.length,
                    error: c.error,
                },
                c.offset,
            )),
        }
    }
    lines.into_iter().map(|(l, _)| l).collect()
}

/// Weighted least squares of `tilt = level + slope * offset` over `lines` (each weighted by
/// its tilt error and [`STRUCTURE_SCATTER`], or the lines' own scatter when larger), with a
/// Gaussian prior of [`CONVERGENCE_PRIOR`] on `slope` when `converging` (otherwise the slope is
/// 0): the fit and the variance of its level.
fn fit_lines(lines: &[Line], converging: bool) -> Option<(Model, f64)> {
    let mut scatter = STRUCTURE_SCATTER;
    let mut result = None;
    for _ in 0..2 {
        let (mut a00, mut a01, mut a11, mut b0, mut b1) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for l in lines {
            let w = 1.0 / (scatter * scatter + l.error * l.error);
            a00 += w;
            a01 += w * l.offset;
            a11 += w * l.offset * l.offset;
            b0 += w * l.tilt;
            b1 += w * l.tilt * l.offset;
        }
        let (model, variance) = if converging {
            a11 += 1.0 / (CONVERGENCE_PRIOR * CONVERGENCE_PRIOR);
            let det = a00 * a11 - a01 * a01;
            if det.is_nan() || det <= 0.0 {
                return None;
            }
            let level = (a11 * b0 - a01 * b1) / det;
            let slope = (a00 * b1 - a01 * b0) / det;
            (Model { level, slope }, a11 / det)
        } else {
            (
                Model {
                    level: b0 / a00,
                    slope: 0.0,
                },
                1.0 / a00,
            )
        };
        // The lines' own scatter about the fit, when it is larger than assumed (a few lines
        // say little about it: the assumed floor stays).
        let n = lines.len() as f64;
        let dof = (n - if converging { 2.0 } else { 1.0 }).max(1.0);
        let spread = lines
            .iter()
            .map(|l| (l.tilt - model.at(l.offset)).powi(2))
            .sum::<f64>()
            / dof;
        result = Some((model, variance));
        if spread.sqrt() <= scatter {
            break;
        }
        scatter = spread.sqrt();
    }
    result
}

#[cfg(test)]
mod tests;

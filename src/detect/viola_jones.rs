//! The multi-scale sliding-window search, a re-implementation of OpenCV 4's
//! `CascadeClassifier::detectMultiScale` for Haar cascades (cascadedetect.cpp).
//!
//! OpenCV's choices are copied because they decide which windows are looked at and how each is
//! scored, and thus which boxes come out:
//!
//! * Scales are `1, s, s², …` (accumulated in `f64`, then stored as `f32`) while the scaled
//!   window `round(win · factor)` fits in the image; `min_size`/`max_size` filter that list.
//!   (Our one addition, off by default: `scale_offset` starts the ladder at `s^offset`.)
//! * For each scale the *image* is shrunk to `round(size / factor)` with the bit-exact bilinear
//!   resize and the 20×20 window slides over it: step 2 in x and y below factor 2, step 1 from
//!   2 on; a window rejected by the very first stage makes the next x position be skipped too.
//! * Each window is normalised by the standard deviation over its interior `(1, 1, w−2, h−2)`;
//!   windows that are (nearly) flat — `area / σ·area ≥ 0.1` — are rejected before any stage runs.
//! * Feature values are computed in `f32` exactly as OpenCV does (`Σ weight · rectsum`, times the
//!   `f32` inverse norm), stage sums in `f64`, thresholds lowered by 1e-5.
//! * A hit at `(x, y)` maps back to `(round(x · factor), round(y · factor))` with size
//!   `round(win · factor)`; the candidates are then merged by [`super::grouping`].

use image::GrayImage;
use rayon::prelude::*;

use super::cascade::{Cascade, CascadeData, HaarRect, Tree, TreeShape};
use super::grouping::{group_rectangles, IRect, GROUP_EPS};
use super::integral::Integrals;
use super::resize::resize_linear_exact;
use crate::Rect;

/// Search settings, named and defaulted like OpenCV's `detectMultiScale` arguments.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DetectorParams {
    /// Ratio between consecutive scales (OpenCV's `scaleFactor`); must be > 1. Default 1.1.
    pub scale_factor: f64,
    /// A merged box must gather more than this many raw hits (OpenCV's `minNeighbors`).
    /// 0 returns the raw, ungrouped hits. Default 3.
    pub min_neighbors: u32,
    /// Smallest box `(width, height)` to report; `(0, 0)` means the cascade window.
    pub min_size: (u32, u32),
    /// Largest box to report; `None` (or a zero dimension, as in OpenCV) means the whole image.
    pub max_size: Option<(u32, u32)>,
    /// How many of the cascade's last stages a window may fail and still count towards a near
    /// miss (`FaceDetector::detect_with_near_misses`; as OpenCV's `outputRejectLevels` keeps
    /// windows that reach the last stages). 0, the default, gives none. The boxes of
    /// [`FaceDetector::detect`] and `FaceDetector::detect_with_neighbors` never depend on it.
    pub stage_slack: u32,
    /// Where the scale ladder starts, in steps of `scale_factor`: the first scale is
    /// `scale_factor^scale_offset` times the cascade window (0, the default, is OpenCV's ladder;
    /// 0.5 puts every scale halfway between two of its rungs). Must be finite and >= 0.
    pub scale_offset: f64,
}

impl Default for DetectorParams {
    fn default() -> Self {
        Self {
            scale_factor: 1.1,
            min_neighbors: 3,
            min_size: (0, 0),
            max_size: None,
            stage_slack: 0,
            scale_offset: 0.0,
        }
    }
}

/// A Viola-Jones face (or object) detector: a [`Cascade`] plus [`DetectorParams`].
#[derive(Debug, Clone)]
pub struct FaceDetector {
    cascade: Cascade,
    params: DetectorParams,
}

impl FaceDetector {
    /// A detector running `cascade` with `params`.
    pub fn new(cascade: Cascade, params: DetectorParams) -> Self {
        Self { cascade, params }
    }

    /// The embedded OpenCV `haarcascade_frontalface_alt2` with default parameters.
    pub fn frontal_face() -> Self {
        Self::new(Cascade::frontal_face_alt2(), DetectorParams::default())
    }

    /// The cascade in use.
    pub(crate) fn cascade(&self) -> &Cascade {
        &self.cascade
    }

    /// The search parameters in use.
    pub(crate) fn params(&self) -> &DetectorParams {
        &self.params
    }

    /// Detected boxes in input pixels (integer-valued, as OpenCV reports them).
    ///
    /// Returns nothing for images smaller than the cascade window or when `scale_factor` is not
    /// a finite number greater than 1.
    pub fn detect(&self, gray: &GrayImage) -> Vec<Rect> {
        self.detect_with_neighbors(gray)
            .into_iter()
            .map(|(r, _)| r)
            .collect()
    }

    /// Detected boxes with the number of raw hits merged into each (a confidence: more is
    /// surer). With `min_neighbors == 0` every raw hit is returned with count 1.
    pub(crate) fn detect_with_neighbors(&self, gray: &GrayImage) -> Vec<(Rect, u32)> {
        let (accepted, _) = self.scan(gray, 0);
        grouped(&accepted, self.params.min_neighbors)
    }

    /// [`Self::detect_with_neighbors`]'s boxes, and from the same scan the near misses: boxes
    /// grouped (with the same neighbour count) from the accepted windows together with those
    /// rejected only by one of the last [`DetectorParams::stage_slack`] stages, that overlap
    /// none of the detected boxes (intersection over union under [`NEAR_MISS_MAX_IOU`]).
    ///
    /// A face the cascade barely sees, one slightly sheared, rolled, blurred or resampled,
    /// gathers windows that fail only its last stages; false alarms do too, so near misses are
    /// candidates for a stricter judge, not detections.
    pub(crate) fn detect_with_near_misses(&self, gray: &GrayImage) -> NearMisses {
        let (accepted, near) = self.scan(gray, self.params.stage_slack);
        let detected = grouped(&accepted, self.params.min_neighbors);
        let near_misses = if near.is_empty() {
            Vec::new()
        } else {
            let all = [accepted, near].concat();
            grouped(&all, self.params.min_neighbors)
                .into_iter()
                .filter(|(b, _)| detected.iter().all(|(d, _)| d.iou(b) < NEAR_MISS_MAX_IOU))
                .collect()
        };
        NearMisses {
            detected,
            near_misses,
        }
    }

    /// The accepted windows and those rejected only by one of the last `stage_slack` stages,
    /// each in a deterministic order (scale, row, column).
    fn scan(&self, gray: &GrayImage, stage_slack: u32) -> (Vec<IRect>, Vec<IRect>) {
        let data = &*self.cascade.data;
        let (w, h) = gray.dimensions();
        let factors = plan_scales((w, h), data.window, &self.params);
        let per_scale: Vec<(Vec<IRect>, Vec<IRect>)> = factors
            .par_iter()
            .map(|&f| scan_scale(data, gray, f, stage_slack, BAND_BYTES))
            .collect();
        let (accepted, near): (Vec<_>, Vec<_>) = per_scale.into_iter().unzip();
        (accepted.concat(), near.concat())
    }
}

/// The boxes of [`FaceDetector::detect_with_near_misses`].
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct NearMisses {
    /// The detector's boxes with their neighbour counts, as
    /// [`FaceDetector::detect_with_neighbors`] gives them.
    pub(crate) detected: Vec<(Rect, u32)>,
    /// Boxes that the windows the last stages rejected complete, with their neighbour counts
    /// (accepted and near-miss windows together).
    pub(crate) near_misses: Vec<(Rect, u32)>,
}

/// The largest overlap (intersection over union) of a near miss with a detected box: a group
/// that overlaps a detection more is that detection, enlarged by its near-miss windows.
pub(crate) const NEAR_MISS_MAX_IOU: f64 = 0.3;

/// OpenCV's grouping of `raw` windows, as boxes in input pixels with their neighbour counts.
fn grouped(raw: &[IRect], min_neighbors: u32) -> Vec<(Rect, u32)> {
    group_rectangles(raw, min_neighbors, GROUP_EPS)
        .into_iter()
        .map(|(r, n)| {
            (
                Rect::new(
                    f64::from(r.x),
                    f64::from(r.y),
                    f64::from(r.w),
                    f64::from(r.h),
                ),
                n,
            )
        })
        .collect()
}

/// OpenCV's scale list (see the module docs).
pub(crate) fn plan_scales(img: (u32, u32), win: (u32, u32), p: &DetectorParams) -> Vec<f32> {
    if !(p.scale_factor.is_finite() && p.scale_factor > 1.0) {
        return Vec::new();
    }
    if !(p.scale_offset.is_finite() && p.scale_offset >= 0.0) {
        return Vec::new();
    }
    if img.0 < win.0 || img.1 < win.1 {
        return Vec::new();
    }
    let max = match p.max_size {
        Some((mw, mh)) if mw > 0 && mh > 0 => (mw, mh),
        _ => img,
    };
    let round = |v: f64| v.round_ties_even() as i64;
    let mut all = Vec::new();
    let mut factor = p.scale_factor.powf(p.scale_offset);
    loop {
        let ws = (
            round(f64::from(win.0) * factor),
            round(f64::from(win.1) * factor),
        );
        if ws.0 > i64::from(img.0) || ws.1 > i64::from(img.1) {
            break;
        }
        all.push(factor as f32);
        factor *= p.scale_factor;
    }
    let mut out = Vec::new();
    for f in all {
        // int * float in C++: the product is a float.
        let ws = (round_f32(win.0 as f32 * f), round_f32(win.1 as f32 * f));
        if ws.0 > i64::from(max.0) || ws.1 > i64::from(max.1) {
            break;
        }
        if ws.0 < i64::from(p.min_size.0) || ws.1 < i64::from(p.min_size.1) {
            continue;
        }
        out.push(f);
    }
    out
}

/// `cvRound` of a float: round half to even.
fn round_f32(v: f32) -> i64 {
    v.round_ties_even() as i64
}

/// One Haar feature with its rectangle corners turned into offsets from a window's top-left
/// entry in the integral buffer of one scale (OpenCV's `HaarEvaluator::OptFeature`).
#[derive(Debug, Clone, Copy)]
struct OptFeature {
    ofs: [[u32; 4]; 3],
    weight: [f32; 3],
}

impl OptFeature {
    fn new(rects: &[HaarRect; 3], tilted: bool, stride: usize, plane: usize) -> Self {
        let mut ofs = [[0u32; 4]; 3];
        let mut weight = [0f32; 3];
        for (k, r) in rects.iter().enumerate() {
            weight[k] = r.weight;
            if r.weight == 0.0 {
                // Unused slot: all four corners at the same place sum to zero.
                continue;
            }
            // Rectangles were validated to lie inside the window, so none of these underflow;
            // offsets fit in u32 because the integral buffer itself is indexed by them and
            // images are far below 4 G pixels (checked in `scan_scale`).
            let at = |x: i32, y: i32| (plane + y as usize * stride + x as usize) as u32;
            ofs[k] = if tilted {
                [
                    at(r.x, r.y),
                    at(r.x - r.h, r.y + r.h),
                    at(r.x + r.w, r.y + r.w),
                    at(r.x + r.w - r.h, r.y + r.w + r.h),
                ]
            } else {
                [
                    at(r.x, r.y),
                    at(r.x + r.w, r.y),
                    at(r.x, r.y + r.h),
                    at(r.x + r.w, r.y + r.h),
                ]
            };
        }
        OptFeature { ofs, weight }
    }

    /// `Σ weight · rectsum` in `f32`, in OpenCV's order of operations.
    #[inline(always)]
    fn value(&self, win: &[i32]) -> f32 {
        let s = |o: &[u32; 4]| rect_sum(win, o) as f32;
        let mut v = self.weight[0] * s(&self.ofs[0]) + self.weight[1] * s(&self.ofs[1]);
        if self.weight[2] != 0.0 {
            v += self.weight[2] * s(&self.ofs[2]);
        }
        v
    }
}

/// Four-corner sum relative to the window start `win` (wrapping, see `integral`).
#[inline(always)]
fn rect_sum(win: &[i32], o: &[u32; 4]) -> i32 {
    win[o[0] as usize]
        .wrapping_sub(win[o[1] as usize])
        .wrapping_sub(win[o[2] as usize])
        .wrapping_add(win[o[3] as usize])
}

/// A tree node with its feature inlined, so scoring a node touches one cache line or two.
#[derive(Debug, Clone, Copy)]
struct FastNode {
    feature: OptFeature,
    threshold: f32,
    left: i32,
    right: i32,
}

/// A tree of [`TreeShape::RootAndOneChild`] with its two nodes' features and its three leaf
/// values in one place, so that scoring it reads one stretch of memory.
#[derive(Debug, Clone, Copy)]
struct TwoNodeTree {
    root: OptFeature,
    root_threshold: f32,
    child: OptFeature,
    child_threshold: f32,
    /// Whether the root sends windows below its threshold (left) to the child node.
    child_on_left: bool,
    /// The root's own leaf, and the child's left and right leaves, widened once (exact) for
    /// the `f64` stage sums.
    root_leaf: f64,
    child_leaves: [f64; 2],
}

impl TwoNodeTree {
    /// The leaf value a window reaches. Both nodes are scored and the leaf picked without a
    /// branch: whether a window goes on to the second node is a coin toss the processor
    /// mispredicts, which costs more than scoring the second node. The windows found are the
    /// same either way.
    #[inline(always)]
    fn leaf(&self, win: &[i32], inv: f32) -> f64 {
        let v0 = self.root.value(win) * inv;
        let v1 = self.child.value(win) * inv;
        let from_child = if v1 < self.child_threshold {
            self.child_leaves[0]
        } else {
            self.child_leaves[1]
        };
        if (v0 < self.root_threshold) == self.child_on_left {
            from_child
        } else {
            self.root_leaf
        }
    }
}

/// Everything needed to score windows of one scale, given integral planes laid out for
/// `stride` and `rows` (see [`Integrals::with_capacity`]).
struct Evaluator<'a> {
    data: &'a CascadeData,
    /// `data.nodes` with offsets for this scale's integral buffer layout.
    nodes: Vec<FastNode>,
    /// Leaf values widened once (exact) for the `f64` stage sums.
    leaves: Vec<f64>,
    /// Corners of the variance rectangle `(1, 1, w−2, h−2)` in the sum plane.
    norm: [u32; 4],
    /// The same in the squared-sum plane.
    norm_sq: [u32; 4],
    norm_area: f64,
    /// Below this `nf` a window is certainly too flat (see `run_at`).
    flat_limit: f64,
    /// Every tree as a [`TwoNodeTree`], in the cascade's order, when all have that shape
    /// ([`TreeShape::RootAndOneChild`]); empty otherwise (the trees are then walked node by node).
    two_node_trees: Vec<TwoNodeTree>,
}

impl<'a> Evaluator<'a> {
    /// The evaluator for integral planes of `stride` and `rows` (as in [`Integrals`]).
    fn new(data: &'a CascadeData, stride: usize, rows: usize) -> Self {
        let offset = |p| Integrals::plane_offset_in(stride, rows, p);
        let features: Vec<OptFeature> = data
            .features
            .iter()
            .map(|f| {
                let plane = if f.tilted {
                    offset(Integrals::TILTED)
                } else {
                    offset(Integrals::SUM)
                };
                OptFeature::new(&f.rects, f.tilted, stride, plane)
            })
            .collect();
        let nodes: Vec<FastNode> = data
            .nodes
            .iter()
            .map(|n| FastNode {
                // Feature indices were validated when the cascade was parsed.
                feature: features[n.feature as usize],
                threshold: n.threshold,
                left: n.left,
                right: n.right,
            })
            .collect();
        let (ww, wh) = (data.window.0 as usize, data.window.1 as usize);
        let norm_at = |plane: usize| {
            [
                stride + 1,
                stride + ww - 1,
                (wh - 1) * stride + 1,
                (wh - 1) * stride + ww - 1,
            ]
            .map(|o| (plane + o) as u32)
        };
        let leaf = |t: &Tree, child: i32| {
            f64::from(data.leaves[t.first_leaf as usize + child.unsigned_abs() as usize])
        };
        let two_node_trees = if data.shape == TreeShape::RootAndOneChild {
            data.trees
                .iter()
                .map(|t| {
                    let (root, child) = (
                        &nodes[t.first_node as usize],
                        &nodes[t.first_node as usize + 1],
                    );
                    let child_on_left = root.left > 0;
                    TwoNodeTree {
                        root: root.feature,
                        root_threshold: root.threshold,
                        child: child.feature,
                        child_threshold: child.threshold,
                        child_on_left,
                        root_leaf: leaf(t, if child_on_left { root.right } else { root.left }),
                        child_leaves: [leaf(t, child.left), leaf(t, child.right)],
                    }
                })
                .collect()
        } else {
            Vec::new()
        };
        Evaluator {
            two_node_trees,
            data,
            nodes,
            leaves: data.leaves.iter().map(|&v| f64::from(v)).collect(),
            norm: norm_at(offset(Integrals::SUM)),
            norm_sq: norm_at(offset(Integrals::SQSUM)),
            norm_area: ((ww - 2) * (wh - 2)) as f64,
            flat_limit: (10.0 * ((ww - 2) * (wh - 2)) as f64).powi(2) * (1.0 - 1e-6),
        }
    }

    /// OpenCV's `runAt` for the window whose top-left entry in the integral buffer `ii` is
    /// `p`: 1 = accepted, 0 = rejected by the first stage, −k = rejected by stage k, −1 also for
    /// windows too flat to normalise.
    #[inline]
    fn run_at(&self, ii: &[i32], p: usize) -> i32 {
        let win = &ii[p..];
        let valsum = rect_sum(win, &self.norm);
        let valsqsum = rect_sum(win, &self.norm_sq) as u32;
        let nf = self.norm_area * f64::from(valsqsum) - f64::from(valsum) * f64::from(valsum);
        // OpenCV rejects windows with `area · (1/√nf as f32) ≥ 0.1`, i.e. nf ≲ (10·area)². Most
        // rejected windows are far below that, so settle them without the square root; the
        // exact test below still decides the borderline ones (the margin dwarfs f32 rounding).
        // (`nf` is never NaN: it comes from finite integers.)
        if nf < self.flat_limit {
            return -1;
        }
        let inv = (1.0 / nf.sqrt()) as f32;
        if self.norm_area * f64::from(inv) >= 1e-1 {
            return -1;
        }
        let d = self.data;
        for (si, stage) in d.stages.iter().enumerate() {
            let first = stage.first_tree as usize;
            let count = stage.tree_count as usize;
            let mut sum = 0f64;
            if self.two_node_trees.is_empty() {
                for t in &d.trees[first..first + count] {
                    let base = t.first_node as usize;
                    let mut idx = 0usize;
                    let leaf = loop {
                        let n = &self.nodes[base + idx];
                        let v = n.feature.value(win) * inv;
                        let next = if v < n.threshold { n.left } else { n.right };
                        if next <= 0 {
                            break next.unsigned_abs() as usize;
                        }
                        idx = next as usize;
                    };
                    sum += self.leaves[t.first_leaf as usize + leaf];
                }
            } else {
                for t in &self.two_node_trees[first..first + count] {
                    sum += t.leaf(win, inv);
                }
            }
            if sum < f64::from(stage.threshold) {
                return -(si as i32);
            }
        }
        1
    }
}

/// All hits at one scale, in original-image coordinates.
fn scan_scale(
    data: &CascadeData,
    gray: &GrayImage,
    factor: f32,
    stage_slack: u32,
    band_bytes: usize,
) -> (Vec<IRect>, Vec<IRect>) {
    let (iw, ih) = gray.dimensions();
    let sw = round_f32(iw as f32 / factor).max(0) as usize;
    let sh = round_f32(ih as f32 / factor).max(0) as usize;
    let (ww, wh) = (data.window.0 as usize, data.window.1 as usize);
    // Window rows are scanned in bands, each with integrals of only the image rows it needs
    // (see `Integrals`): the same sums as whole-image integrals, in memory bounded by
    // BAND_BYTES per scale (96 MB of integrals saved on a 12 MP photo). Bands are taken in
    // turn, so one buffer serves them all; the rows of a band are scanned in parallel. Small
    // images fit in one band, computed exactly once (smaller bands would slow video down).
    let step = if factor >= 2.0 { 1 } else { 2 };
    let bytes_per_row = (sw + 1) * if data.has_tilted { 12 } else { 8 };
    let min_height = (MIN_BAND_WINDOW_ROWS - 1) * step + wh;
    let band_height = (band_bytes / bytes_per_row.max(1)).max(min_height).min(sh);
    // Integral offsets are u32: skip scales whose three band planes would not be addressable
    // (rows over ~20 M pixels wide; the image reader's size limit stops such inputs long before).
    if sw < ww || sh < wh || 3 * (sw + 1) * (band_height + 1) > u32::MAX as usize {
        return (Vec::new(), Vec::new());
    }
    // At factor 1 the "resize" is a copy (as in OpenCV): read the image itself instead, which
    // saves a full-size copy at the scale that needs the most memory.
    let pixels: std::borrow::Cow<'_, [u8]> = if (sw, sh) == (iw as usize, ih as usize) {
        std::borrow::Cow::Borrowed(gray.as_raw())
    } else {
        std::borrow::Cow::Owned(resize_linear_exact(
            gray.as_raw(),
            iw as usize,
            ih as usize,
            sw,
            sh,
        ))
    };
    let ev = Evaluator::new(data, sw + 1, band_height + 1);
    let mut ii = Integrals::with_capacity(sw, band_height, data.has_tilted);
    // Window positions x in 0..=sw−ww (OpenCV's "working size" is (sw+1) − ww).
    let (nx, ny) = (sw + 1 - ww, sh + 1 - wh);
    let win = (
        round_f32(data.window.0 as f32 * factor) as i32,
        round_f32(data.window.1 as f32 * factor) as i32,
    );
    let rows: Vec<usize> = (0..ny).step_by(step).collect();
    // `run_at` returns -s for a window rejected by stage s >= 1 (and -1 for a flat window): the
    // windows rejected by stages from `first_slack` on are near misses. Never below stage 2, so
    // that neither flat windows nor first-stage rejections (0) are.
    let first_slack = data
        .stages
        .len()
        .saturating_sub(stage_slack as usize)
        .max(2) as i32;
    // Window rows whose windows fit in one band.
    let rows_per_band = (band_height - wh) / step + 1;
    let (mut accepted, mut near) = (Vec::new(), Vec::new());
    for band in rows.chunks(rows_per_band) {
        let top = band[0];
        let height = band[band.len() - 1] + wh - top;
        ii.compute(&pixels[top * sw..], height);
        let ii = &ii;
        // Chunks of 8 rows keep rayon's task overhead small while still splitting big bands.
        let found: Vec<(IRect, bool)> = band
            .par_chunks(8)
            .flat_map_iter(|chunk| {
                let mut hits = Vec::new();
                for &y in chunk {
                    let row = (y - top) * ii.stride;
                    let mut x = 0;
                    while x < nx {
                        let r = ev.run_at(&ii.buf, row + x);
                        if r > 0 || -r >= first_slack {
                            let hit = IRect {
                                x: round_f32(x as f32 * factor) as i32,
                                y: round_f32(y as f32 * factor) as i32,
                                w: win.0,
                                h: win.1,
                            };
                            hits.push((hit, r > 0));
                        }
                        // OpenCV skips the next position after a first-stage rejection.
                        x += if r == 0 { 2 * step } else { step };
                    }
                }
                hits
            })
            .collect();
        for (hit, is_accepted) in found {
            if is_accepted {
                accepted.push(hit);
            } else {
                near.push(hit);
            }
        }
    }
    (accepted, near)
}

/// Memory for one scale's band of integral images (see `scan_scale`): about a megapixel fits in
/// one band; a 1920x1080 frame's first scale takes two, a 4000x3000 photo's about a dozen.
const BAND_BYTES: usize = 8 << 20;

/// Fewest window rows per band, so that very wide images still share few rows between bands.
const MIN_BAND_WINDOW_ROWS: usize = 32;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::detect::cascade::tests::TINY;

    #[test]
    fn scale_plan_matches_opencv_rules() {
        let p = DetectorParams::default();
        let s = plan_scales((40, 30), (20, 20), &p);
        // 20·1.1^k ≤ 30 → k ≤ 4 (1.1^4 = 1.4641 → 29.28 → 29).
        assert_eq!(s.len(), 5);
        assert_eq!(s[0], 1.0);
        assert!((s[4] - 1.4641).abs() < 1e-6);
        assert!(plan_scales((19, 100), (20, 20), &p).is_empty());
        let min = DetectorParams {
            min_size: (24, 24),
            max_size: Some((27, 27)),
            ..p
        };
        // windows 20, 22, 24, 27, 29 → keep 24 and 27 (26.62 rounds to 27).
        assert_eq!(plan_scales((40, 30), (20, 20), &min).len(), 2);
        let bad = DetectorParams {
            scale_factor: 1.0,
            ..p
        };
        assert!(plan_scales((400, 300), (20, 20), &bad).is_empty());
    }

    /// A half-step offset puts every scale between two of the default ladder's, geometrically.
    #[test]
    fn scale_offset_shifts_the_ladder_between_the_default_rungs() {
        let p = DetectorParams::default();
        let half = DetectorParams {
            scale_offset: 0.5,
            ..p
        };
        let rungs = plan_scales((400, 300), (20, 20), &p);
        let between = plan_scales((400, 300), (20, 20), &half);
        assert!((between[0] - 1.1f32.sqrt()).abs() < 1e-6);
        for (i, b) in between.iter().enumerate() {
            let mid = (rungs[i] * rungs[i + 1]).sqrt();
            assert!((b / mid - 1.0).abs() < 1e-5, "scale {i}: {b} against {mid}");
        }
        // The windows still stop at the image: 20 * 1.1^(n + 0.5) <= 300.
        assert_eq!(between.len(), rungs.len() - 1);
        for bad in [-0.5, f64::NAN, f64::INFINITY] {
            let p = DetectorParams {
                scale_offset: bad,
                ..p
            };
            assert!(plan_scales((400, 300), (20, 20), &p).is_empty(), "{bad}");
        }
    }

    /// The tiny cascade fires where the left half of a 4x4 window is much brighter than the
    /// right half: a single bright-to-dark vertical edge is found at the right place.
    #[test]
    fn synthetic_cascade_finds_edge() {
        let cascade = Cascade::from_xml(TINY).unwrap();
        let params = DetectorParams {
            scale_factor: 10.0, // one scale only
            min_neighbors: 0,
            ..Default::default()
        };
        let det = FaceDetector::new(cascade, params);
        // 12x12 image: columns 0..6 bright (200), 6..12 dark (20), plus mild texture so no
        // window is flat.
        let img = GrayImage::from_fn(12, 12, |x, y| {
            let base = if x < 6 { 200 } else { 20 };
            image::Luma([base + ((x * 7 + y * 3) % 5) as u8])
        });
        let hits = det.detect(&img);
        assert!(!hits.is_empty());
        for r in &hits {
            // Left half of the window (x..x+2) must be bright, right half (x+2..x+4) dark:
            // only the window straddling column 6 at x = 4 passes (x steps by 2).
            assert_eq!(r.x, 4.0, "{r:?}");
            assert_eq!((r.width, r.height), (4.0, 4.0));
        }
        // Rows step by 2 over y = 0..=8.
        assert_eq!(hits.len(), 5);
        // Nothing on a flat image: the variance check rejects every window.
        let flat = GrayImage::from_pixel(12, 12, image::Luma([90]));
        assert!(det.detect(&flat).is_empty());
    }

    /// [`TINY`]'s edge stage twice, then a stage no window passes (its leaves sum to at most 1,
    /// its threshold is 2).
    fn edge_cascade_with_impossible_last_stage() -> Cascade {
        let stage = |threshold: f64| {
            format!(
                "<_><maxWeakCount>1</maxWeakCount><stageThreshold>{threshold}</stageThreshold>\
                 <weakClassifiers><_><internalNodes>0 -1 0 0.25</internalNodes>\
                 <leafValues>0 1</leafValues></_></weakClassifiers></_>"
            )
        };
        let stages = [stage(0.5), stage(0.5), stage(2.0)].concat();
        let start = TINY.find("<stageNum>").expect("TINY has stages");
        let end = TINY.find("</stages>").expect("TINY has stages");
        let xml = format!(
            "{}<stageNum>3</stageNum><stages>{stages}{}",
            &TINY[..start],
            &TINY[end..]
        );
        Cascade::from_xml(&xml).expect("a valid three-stage cascade")
    }

    #[test]
    fn near_misses_are_windows_only_the_last_stages_reject() {
        let img = GrayImage::from_fn(12, 12, |x, y| {
            let base = if x < 6 { 200 } else { 20 };
            image::Luma([base + ((x * 7 + y * 3) % 5) as u8])
        });
        let params = |stage_slack| DetectorParams {
            scale_factor: 10.0,
            min_neighbors: 0,
            stage_slack,
            ..Default::default()
        };
        let detector =
            |slack| FaceDetector::new(edge_cascade_with_impossible_last_stage(), params(slack));
        // No window passes the last stage: no detection, whatever the slack.
        for slack in [0, 1, 5] {
            assert!(detector(slack).detect(&img).is_empty());
            assert!(detector(slack)
                .detect_with_near_misses(&img)
                .detected
                .is_empty());
        }
        assert!(detector(0)
            .detect_with_near_misses(&img)
            .near_misses
            .is_empty());
        // With one stage of slack the edge windows (x = 4, five rows) are near misses.
        let found = detector(1).detect_with_near_misses(&img);
        assert_eq!(found.near_misses.len(), 5, "{found:?}");
        assert!(found.near_misses.iter().all(|(b, n)| b.x == 4.0 && *n == 1));
        // A slack reaching the first stages changes nothing more: stage 1's and the first
        // stage's rejections never count.
        assert_eq!(detector(5).detect_with_near_misses(&img), found);
        // With the last stage passable the same windows are detections, and a near miss
        // overlapping a detection is not reported.
        let passable = FaceDetector::new(Cascade::from_xml(TINY).expect("TINY"), params(1));
        let found = passable.detect_with_near_misses(&img);
        assert_eq!(found.detected.len(), 5);
        assert!(found.near_misses.is_empty());
    }

    /// A known detection on a real photo (Yale face database), compared with what OpenCV 4.14's
    /// `detectMultiScale(gray, 1.1, 3)` reports for the same file: `[108, 54, 145, 145]`.
    #[test]
    fn detects_yale_face() {
        let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../shared/data/yale-faces/images/subject01.normal.jpeg");
        if !p.exists() {
            // Past the test harness's output capture, so the skip shows.
            let _ = std::io::Write::write_all(
                &mut std::io::stderr(),
                b"skipped: ../shared not found\n",
            );
            return;
        }
        let img = image::open(&p).expect("decodable fixture");
        let faces = FaceDetector::frontal_face()
            .detect_with_neighbors(&crate::detect::to_gray_opencv(&img));
        assert_eq!(faces.len(), 1, "{faces:?}");
        let (r, n) = faces[0];
        let opencv = Rect::new(108.0, 54.0, 145.0, 145.0);
        // JPEG decoders differ by a level here and there, so allow a pixel or two.
        assert!(r.iou(&opencv) > 0.9, "{r:?} vs OpenCV {opencv:?}");
        assert!(n > 3);
    }

    /// The committed Yale fixture, grey as OpenCV converts it.
    fn fixture_gray() -> GrayImage {
        let img = image::open(
            std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("tests/fixtures/faces/subject01.normal.jpeg"),
        )
        .expect("fixture");
        crate::detect::to_gray_opencv(&img)
    }

    /// Scanning in many thin bands finds exactly the windows that one band over the whole image
    /// finds, at every scale (the band edges fall in different places at each scale).
    #[test]
    fn bands_do_not_change_the_hits() {
        let gray = fixture_gray();
        let det = FaceDetector::frontal_face();
        let data = &*det.cascade.data;
        let factors = plan_scales(gray.dimensions(), data.window, &det.params);
        let mut total = 0;
        for &f in &factors {
            let whole = scan_scale(data, &gray, f, 0, usize::MAX).0;
            // The smallest budget: bands of MIN_BAND_WINDOW_ROWS rows.
            let thin = scan_scale(data, &gray, f, 0, 1).0;
            assert_eq!(whole, thin, "scale {f}");
            total += whole.len();
        }
        assert!(total > 20, "the face gives many raw hits: {total}");
    }

    /// The branch-free walk of two-node trees gives every window exactly the verdict (accepted,
    /// or the stage that rejected it) of the node-by-node walk.
    #[test]
    fn two_node_trees_walked_without_branches_give_the_same_verdicts() {
        let gray = fixture_gray();
        let det = FaceDetector::frontal_face();
        let fast = &*det.cascade.data;
        assert_eq!(fast.shape, TreeShape::RootAndOneChild);
        let mut slow = fast.clone();
        slow.shape = TreeShape::Mixed;
        let mut verdicts = std::collections::HashMap::new();
        for &f in &plan_scales(gray.dimensions(), fast.window, &det.params) {
            let w = round_f32(gray.width() as f32 / f) as usize;
            let h = round_f32(gray.height() as f32 / f) as usize;
            let (iw, ih) = (gray.width() as usize, gray.height() as usize);
            let pixels = resize_linear_exact(gray.as_raw(), iw, ih, w, h);
            let ii = Integrals::new(&pixels, w, h, false);
            let (ev_fast, ev_slow) = (
                Evaluator::new(fast, ii.stride, ii.rows),
                Evaluator::new(&slow, ii.stride, ii.rows),
            );
            for y in 0..=h - 20 {
                for x in 0..=w - 20 {
                    let p = y * ii.stride + x;
                    let v = ev_fast.run_at(&ii.buf, p);
                    assert_eq!(v, ev_slow.run_at(&ii.buf, p), "scale {f}, window {x}, {y}");
                    *verdicts.entry(v).or_insert(0) += 1;
                }
            }
        }
        // The comparison covers accepted windows and rejections at many stages.
        assert!(verdicts.get(&1).copied().unwrap_or(0) > 0, "{verdicts:?}");
        assert!(verdicts.len() > 10, "{verdicts:?}");
    }

    #[test]
    fn tiny_and_odd_images_do_not_panic() {
        let det = FaceDetector::frontal_face();
        for (w, h) in [(0, 0), (1, 1), (19, 19), (20, 20), (21, 300), (300, 21)] {
            let img = GrayImage::new(w, h);
            assert!(det.detect(&img).is_empty());
        }
    }
}

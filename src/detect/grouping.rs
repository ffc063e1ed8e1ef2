//! Merging raw window hits into detections: OpenCV's `groupRectangles` (objdetect.cpp),
//! including its integer/float rounding, so the merged boxes match OpenCV's to the pixel.
//!
//! 1. `cv::partition` with the `SimilarRects(eps)` predicate: two boxes are neighbours when all
//!    four edges differ by at most `eps · (min widths + min heights) / 2`; classes are the
//!    connected components (union-find).
//! 2. Each class is averaged (integer sums times the `f32` reciprocal of the count, rounded half
//!    to even like `saturate_cast<int>`).
//! 3. Classes with `<= min_neighbors` members are dropped.
//! 4. A surviving box lying inside another surviving box (with an `eps` margin) is dropped when
//!    the other has more members than `max(3, own)` — or when it has fewer than 3 itself.

/// OpenCV's `GROUP_EPS` used by `detectMultiScale`.
pub(crate) const GROUP_EPS: f64 = 0.2;

/// An integer box like OpenCV's `cv::Rect`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub(crate) struct IRect {
    pub(crate) x: i32,
    pub(crate) y: i32,
    pub(crate) w: i32,
    pub(crate) h: i32,
}

/// OpenCV's `SimilarRects`.
fn similar(a: &IRect, b: &IRect, eps: f64) -> bool {
    let delta = eps * f64::from(a.w.min(b.w) + a.h.min(b.h)) * 0.5;
    f64::from((a.x - b.x).abs()) <= delta
        && f64::from((a.y - b.y).abs()) <= delta
        && f64::from((a.x + a.w - b.x - b.w).abs()) <= delta
        && f64::from((a.y + a.h - b.y - b.h).abs()) <= delta
}

/// `cv::partition`: class label per item, classes numbered in order of first appearance.
fn partition(rects: &[IRect], eps: f64) -> (Vec<usize>, usize) {
    let n = rects.len();
    let mut parent: Vec<usize> = (0..n).collect();
    let mut rank = vec![0u8; n];
    fn find(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            // Path halving keeps the trees flat.
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    for i in 0..n {
        for j in (i + 1)..n {
            // The predicate is symmetric, so testing each pair once gives OpenCV's components.
            if !similar(&rects[i], &rects[j], eps) {
                continue;
            }
            let (ri, rj) = (find(&mut parent, i), find(&mut parent, j));
            if ri == rj {
                continue;
            }
            match rank[ri].cmp(&rank[rj]) {
                std::cmp::Ordering::Greater => parent[rj] = ri,
                std::cmp::Ordering::Less => parent[ri] = rj,
                std::cmp::Ordering::Equal => {
                    parent[ri] = rj;
                    rank[rj] = rank[rj].saturating_add(1);
                }
            }
        }
    }
    let mut label_of_root = vec![usize::MAX; n];
    let mut labels = Vec::with_capacity(n);
    let mut classes = 0;
    for i in 0..n {
        let r = find(&mut parent, i);
        if label_of_root[r] == usize::MAX {
            label_of_root[r] = classes;
            classes += 1;
        }
        labels.push(label_of_root[r]);
    }
    (labels, classes)
}

/// `saturate_cast<int>(float)`: round half to even, clamp.
fn sat_round(v: f32) -> i32 {
    let r = v.round_ties_even();
    if r.is_nan() {
        0
    } else {
        r.clamp(i32::MIN as f32, i32::MAX as f32) as i32
    }
}

/// OpenCV's `groupRectangles(rects, weights, group_threshold, eps)`: merged boxes with their
/// member counts. `group_threshold == 0` returns the input unchanged with count 1 each.
pub(crate) fn group_rectangles(
    rects: &[IRect],
    group_threshold: u32,
    eps: f64,
) -> Vec<(IRect, u32)> {
    if group_threshold == 0 || rects.is_empty() {
        return rects.iter().map(|&r| (r, 1)).collect();
    }
    let (labels, nclasses) = partition(rects, eps);
    let mut sums = vec![[0i64; 4]; nclasses];
    let mut counts = vec![0u32; nclasses];
    for (r, &c) in rects.iter().zip(&labels) {
        let s = &mut sums[c];
        s[0] += i64::from(r.x);
        s[1] += i64::from(r.y);
        s[2] += i64::from(r.w);
        s[3] += i64::from(r.h);
        counts[c] += 1;
    }
    // OpenCV sums into int fields and multiplies by a float reciprocal.
    let avg: Vec<IRect> = sums
        .iter()
        .zip(&counts)
        .map(|(s, &n)| {
            let inv = 1.0f32 / n as f32;
            IRect {
                x: sat_round(s[0] as i32 as f32 * inv),
                y: sat_round(s[1] as i32 as f32 * inv),
                w: sat_round(s[2] as i32 as f32 * inv),
                h: sat_round(s[3] as i32 as f32 * inv),
            }
        })
        .collect();

    let mut out = Vec::new();
    for i in 0..nclasses {
        let (r1, n1) = (avg[i], counts[i]);
        if n1 <= group_threshold {
            continue;
        }
        let swallowed = (0..nclasses).any(|j| {
            let n2 = counts[j];
            if j == i || n2 <= group_threshold {
                return false;
            }
            let r2 = avg[j];
            let dx = (f64::from(r2.w) * eps).round_ties_even() as i32;
            let dy = (f64::from(r2.h) * eps).round_ties_even() as i32;
            r1.x >= r2.x - dx
                && r1.y >= r2.y - dy
                && r1.x + r1.w <= r2.x + r2.w + dx
                && r1.y + r1.h <= r2.y + r2.h + dy
                && (n2 > n1.max(3) || n1 < 3)
        });
        if !swallowed {
            out.push((r1, n1));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn r(x: i32, y: i32, w: i32, h: i32) -> IRect {
        IRect { x, y, w, h }
    }

    #[test]
    fn four_overlapping_and_one_isolated() {
        let rects = [
            r(100, 100, 50, 50),
            r(102, 101, 50, 50),
            r(98, 99, 52, 52),
            r(101, 103, 48, 48),
            r(400, 400, 50, 50),
        ];
        let g = group_rectangles(&rects, 3, GROUP_EPS);
        // Sums: x 401, y 403, w 200, h 200 over 4 → 100.25, 100.75, 50, 50.
        assert_eq!(g, vec![(r(100, 101, 50, 50), 4)]);
        // With min_neighbors 4 the group of four is not enough.
        assert!(group_rectangles(&rects, 4, GROUP_EPS).is_empty());
        // min_neighbors 0 passes raw boxes through.
        assert_eq!(group_rectangles(&rects, 0, GROUP_EPS).len(), 5);
    }

    #[test]
    fn averaging_rounds_half_to_even() {
        // x: (10 + 11) / 2 = 10.5 → 10; y: (13 + 14) / 2 = 13.5 → 14 (OpenCV's cvRound).
        let rects = [r(10, 13, 40, 40), r(11, 14, 40, 40)];
        assert_eq!(
            group_rectangles(&rects, 1, GROUP_EPS),
            vec![(r(10, 14, 40, 40), 2)]
        );
    }

    #[test]
    fn chains_join_transitively() {
        // a~b and b~c but not a~c: partition still puts all three together.
        let rects = [r(0, 0, 20, 20), r(4, 0, 20, 20), r(8, 0, 20, 20)];
        assert!(!similar(&rects[0], &rects[2], GROUP_EPS));
        assert_eq!(
            group_rectangles(&rects, 2, GROUP_EPS),
            vec![(r(4, 0, 20, 20), 3)]
        );
    }

    #[test]
    fn small_box_inside_stronger_big_box_is_dropped() {
        let mut rects = Vec::new();
        // Big face: 6 hits. Small box inside it: 4 hits.
        for k in 0..6 {
            rects.push(r(100 + k % 2, 100, 100, 100));
        }
        for _ in 0..4 {
            rects.push(r(130, 130, 30, 30));
        }
        let g = group_rectangles(&rects, 3, GROUP_EPS);
        assert_eq!(g, vec![(r(100, 100, 100, 100), 6)]);
        // If the big box has no more hits than max(3, small) both stay.
        let mut rects2: Vec<IRect> = rects[..4].to_vec();
        rects2.extend_from_slice(&rects[6..]);
        assert_eq!(group_rectangles(&rects2, 3, GROUP_EPS).len(), 2);
    }
}

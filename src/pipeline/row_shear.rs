//! The shear changing down the rows of a still: a pan that speeds up or slows down during the
//! readout shears each row by its own amount (the rows' offsets bend), so faces at different
//! heights read different shears. When they disagree beyond their uncertainty, a line through
//! their shears against their rows gives every row its own.

use serde::{Deserialize, Serialize};

use super::combine::FACE_UNCERTAINTY;
use super::report::FaceReport;

/// The least share of the image's height between the highest and the lowest face for their
/// shears to tell how the shear changes down the rows: closer together, a face's own error of a
/// few hundredths would become a large change of shear over the frame.
pub(crate) const MIN_ROW_SPAN: f64 = 0.25;

/// One standard deviation of the difference between a face's error and the mean error of the
/// faces beside it in one photo: on the camera-like development frames (`eval shear --camera`,
/// 410 pairs of accepted faces in one frame) their errors differ by 0.040 times the square root
/// of 2 (smaller faces in group photos, each with its own bias).
pub(crate) const FACE_ROW_SIGMA: f64 = 0.04;

/// How many standard deviations of its own uncertainty (the faces' errors, [`FACE_ROW_SIGMA`]
/// each) the fitted change of shear must reach to be believed: two faces must differ by more
/// than 0.17, which 1.5% of pairs of faces in one development frame do by their own errors.
pub(crate) const MIN_CHANGE_SIGMAS: f64 = 3.0;

/// An image's shear changing down its rows: linear between the rows of the highest and the
/// lowest face that gave it, held beyond them (nothing there says how it goes on).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[non_exhaustive]
pub struct RowShear {
    /// The highest face's row (the middle of its eyes and nostrils) and the shear there.
    pub top: (f64, f64),
    /// The lowest face's row and the shear there.
    pub bottom: (f64, f64),
}

impl RowShear {
    /// A shear `top.1` at row `top.0` changing linearly to `bottom.1` at row `bottom.0`
    /// (`top.0 < bottom.0`), held beyond; `None` unless both rows and shears are finite and the
    /// rows in order.
    pub fn new(top: (f64, f64), bottom: (f64, f64)) -> Option<Self> {
        let finite = [top.0, top.1, bottom.0, bottom.1]
            .iter()
            .all(|v| v.is_finite());
        (finite && top.0 < bottom.0).then_some(Self { top, bottom })
    }

    /// The shear at row `y`.
    pub fn k_at(&self, y: f64) -> f64 {
        let (t0, k0) = self.top;
        let (t1, k1) = self.bottom;
        let s = ((y - t0) / (t1 - t0)).clamp(0.0, 1.0);
        k0 + (k1 - k0) * s
    }

    /// `int_{top} ^ y k(t) dt`, in closed form.
    fn integral(&self, y: f64) -> f64 {
        let (t0, k0) = self.top;
        let (t1, k1) = self.bottom;
        if y <= t0 {
            k0 * (y - t0)
        } else if y <= t1 {
            let d = y - t0;
            k0 * d + (k1 - k0) * d * d / (2.0 * (t1 - t0))
        } else {
            (k0 + k1) / 2.0 * (t1 - t0) + k1 * (y - t1)
        }
    }

    /// Each row's horizontal offset relative to row `pivot` (the integral of the shear from
    /// `pivot` to the row), for rows `0..height`: `out(x, y) = in(x + offsets[y], y)` undoes
    /// it. With the same shear on every row, exactly `k (y - pivot)`.
    pub fn offsets(&self, height: u32, pivot: f64) -> Vec<f64> {
        let base = self.integral(pivot);
        (0..height)
            .map(|y| self.integral(f64::from(y)) - base)
            .collect()
    }
}

/// The row a face's shear belongs to: halfway between its eyes and its nostrils, the middle of
/// the features it is measured from.
pub(crate) fn face_row(f: &FaceReport) -> f64 {
    let eyes = f.right_eye.midpoint(f.left_eye).y;
    let nostrils = f.right_nostril.midpoint(f.left_nostril).y;
    (eyes + nostrils) / 2.0
}

/// The largest change of shear between the highest and the lowest face that a bend may
/// explain: a camera's speed changes by a limited share of its peak within one readout (a whip
/// pan reaches full speed over several frame intervals), and faces further apart in shear than
/// this are more likely one misread than a pan changing speed.
pub(crate) const MAX_ROW_CHANGE: f64 = 0.3;

/// How the shear changes down the rows of an image `height` rows tall, from its faces' accepted
/// estimates: a least-squares line of shear against row, when the faces span at least
/// [`MIN_ROW_SPAN`] of the height, the line's slope is at least [`MIN_CHANGE_SIGMAS`] of its
/// uncertainty (the faces disagree beyond what their own errors explain), it changes by at most
/// [`MAX_ROW_CHANGE`] between them, and it passes within [`FACE_UNCERTAINTY`] of every face.
/// Tried on every accepted face first (a bend explains faces the consensus outvoted), then on
/// those the consensus kept. `None`: one shear for every row.
pub(crate) fn fit_row_shear(faces: &[FaceReport], height: u32) -> Option<RowShear> {
    let accepted = |keep_outvoted: bool| -> Vec<(f64, f64)> {
        faces
            .iter()
            .filter(|f| keep_outvoted || !f.outvoted)
            .filter_map(|f| Some((face_row(f), f.k?)))
            .filter(|(y, k)| y.is_finite() && k.is_finite())
            .collect()
    };
    let all = accepted(true);
    line_through(&all, height).or_else(|| {
        let kept = accepted(false);
        (kept.len() < all.len())
            .then(|| line_through(&kept, height))
            .flatten()
    })
}

/// [`fit_row_shear`]'s line through `(row, k)` points, with its tests.
fn line_through(points: &[(f64, f64)], height: u32) -> Option<RowShear> {
    if points.len() < 2 {
        return None;
    }
    let (lo, hi) = points
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
            (a.min(p.0), b.max(p.0))
        });
    if hi - lo < MIN_ROW_SPAN * f64::from(height) {
        return None;
    }
    let n = points.len() as f64;
    let (my, mk) = points
        .iter()
        .fold((0.0, 0.0), |(a, b), p| (a + p.0 / n, b + p.1 / n));
    let syy: f64 = points.iter().map(|p| (p.0 - my).powi(2)).sum();
    let syk: f64 = points.iter().map(|p| (p.0 - my) * (p.1 - mk)).sum();
    let slope = syk / syy;
    let slope_sigma = FACE_ROW_SIGMA / syy.sqrt();
    let at = |y: f64| mk + slope * (y - my);
    let significant = slope.abs() >= MIN_CHANGE_SIGMAS * slope_sigma;
    let plausible = (slope * (hi - lo)).abs() <= MAX_ROW_CHANGE;
    let explains = points
        .iter()
        .all(|&(y, k)| (k - at(y)).abs() <= FACE_UNCERTAINTY);
    if !(significant && plausible && explains) {
        return None;
    }
    RowShear::new((lo, at(lo)), (hi, at(hi)))
}

/// Whether `face`'s accepted estimate lies within [`FACE_UNCERTAINTY`] of `rows` at its row:
/// the bend explains it (a face the consensus outvoted is then part of it).
pub(crate) fn explained(rows: &RowShear, face: &FaceReport) -> bool {
    face.k
        .is_some_and(|k| (k - rows.k_at(face_row(face))).abs() <= FACE_UNCERTAINTY + 1e-9)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{Point, Rect};

    fn face(row: f64, k: Option<f64>) -> FaceReport {
        FaceReport {
            face_box: Rect::new(0.0, row - 40.0, 80.0, 80.0),
            right_eye: Point::new(20.0, row - 10.0),
            left_eye: Point::new(60.0, row - 10.0),
            right_nostril: Point::new(35.0, row + 10.0),
            left_nostril: Point::new(45.0, row + 10.0),
            k,
            ..FaceReport::default()
        }
    }

    #[test]
    fn the_offsets_integrate_the_shear_and_reduce_to_a_line() {
        let same = RowShear::new((100.0, 0.3), (300.0, 0.3)).expect("a curve");
        for (y, o) in same.offsets(400, 200.0).iter().enumerate() {
            assert!((o - 0.3 * (y as f64 - 200.0)).abs() < 1e-9);
        }
        let bent = RowShear::new((100.0, 0.2), (300.0, 0.4)).expect("a curve");
        let o = bent.offsets(401, 200.0);
        // Each row's step is the shear between it and the next (trapezoid exact for a line).
        for y in 0..400 {
            let step = o[y + 1] - o[y];
            let mid = (bent.k_at(y as f64) + bent.k_at(y as f64 + 1.0)) / 2.0;
            assert!((step - mid).abs() < 1e-9, "row {y}: {step} vs {mid}");
        }
        assert_eq!(o[200], 0.0);
        assert_eq!(bent.k_at(0.0), 0.2);
        assert_eq!(bent.k_at(400.0), 0.4);
        assert!((bent.k_at(200.0) - 0.3).abs() < 1e-12);
        assert!(RowShear::new((3.0, 0.1), (3.0, 0.2)).is_none());
        assert!(RowShear::new((0.0, f64::NAN), (3.0, 0.2)).is_none());
    }

    #[test]
    fn faces_disagreeing_beyond_their_error_bend_the_rows() {
        // Two faces half the height apart, 0.20 apart in shear (3.5 sigmas of the slope).
        let fit = fit_row_shear(&[face(200.0, Some(0.20)), face(600.0, Some(0.40))], 800)
            .expect("a change of shear");
        assert!((fit.top.0 - 200.0).abs() < 1e-9 && (fit.top.1 - 0.20).abs() < 1e-9);
        assert!((fit.bottom.0 - 600.0).abs() < 1e-9 && (fit.bottom.1 - 0.40).abs() < 1e-9);
        // Three faces on one line: the line through them.
        let fit = fit_row_shear(
            &[
                face(100.0, Some(0.10)),
                face(400.0, Some(0.25)),
                face(700.0, Some(0.40)),
            ],
            800,
        )
        .expect("a change of shear");
        assert!((fit.k_at(400.0) - 0.25).abs() < 1e-9);
    }

    #[test]
    fn faces_within_their_error_or_too_close_keep_one_shear() {
        // 0.15 apart: within what two faces' errors explain.
        assert!(fit_row_shear(&[face(200.0, Some(0.30)), face(600.0, Some(0.45))], 800).is_none());
        // Further apart than a pan's change of speed explains.
        assert!(fit_row_shear(&[face(200.0, Some(0.0)), face(600.0, Some(0.35))], 800).is_none());
        // Three faces, one off the line through the others by more than a face's window.
        assert!(fit_row_shear(
            &[
                face(100.0, Some(0.10)),
                face(400.0, Some(0.40)),
                face(700.0, Some(0.30)),
            ],
            800
        )
        .is_none());
        // Far apart in shear but only 100 of 800 rows apart.
        assert!(fit_row_shear(&[face(350.0, Some(0.20)), face(450.0, Some(0.40))], 800).is_none());
        // One face, a refused face, an outvoted face.
        assert!(fit_row_shear(&[face(200.0, Some(0.30))], 800).is_none());
        assert!(fit_row_shear(&[face(200.0, Some(0.30)), face(600.0, None)], 800).is_none());
        let mut outvoted = face(600.0, Some(0.45));
        outvoted.outvoted = true;
        assert!(fit_row_shear(&[face(200.0, Some(0.30)), outvoted], 800).is_none());
    }

    #[test]
    fn a_bend_explains_a_face_the_consensus_outvoted() {
        // 0.25 apart: beyond the consensus window (0.20), within a pan's change of speed.
        let mut low = face(600.0, Some(0.45));
        low.outvoted = true;
        let fit = fit_row_shear(&[face(200.0, Some(0.20)), low], 800).expect("a bend");
        assert!((fit.k_at(600.0) - 0.45).abs() < 1e-9);
        assert!(explained(&fit, &low));
        // A wild face beside two that bend is left out of the bend, as the consensus left it.
        let mut wild = face(400.0, Some(-0.30));
        wild.outvoted = true;
        let fit = fit_row_shear(
            &[face(200.0, Some(0.20)), face(600.0, Some(0.40)), wild],
            800,
        )
        .expect("a bend through the two");
        assert!((fit.k_at(200.0) - 0.20).abs() < 1e-9);
        assert!(!explained(&fit, &wild));
    }
}

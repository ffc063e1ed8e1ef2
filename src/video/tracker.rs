//! Faces followed from frame to frame, so that full-frame detection is not paid on every frame.
//!
//! * **Full detection** runs on the first frame, every [`TrackerParams::redetect_interval`]
//!   frames, and while nothing is tracked every [`TrackerParams::lost_interval`] frames. It
//!   looks at the frame shrunk to at most [`TrackerParams::detect_width`] columns (area
//!   averaging): detection cost grows with the pixel count, and the cascade's 20-pixel window
//!   still finds faces of `20 * width / detect_width` pixels and more (60 px on a 1920-wide
//!   frame with the default 640).
//! * **Between full detections** each tracked face is searched for at full resolution in a
//!   window around its last box (the box grown by [`TrackerParams::search_margin`] of its size
//!   on every side) and only at scales within [`TrackerParams::size_tolerance`] of its last size.
//!   A window of about twice the face at a handful of scales costs a small fraction of a
//!   full-frame search. The new box is the detection that overlaps the old one most; with none
//!   the track is dropped (lost).
//! * **Shear hint.** Viola-Jones loses faces under strong shear. When the caller passes the
//!   current filtered `k`, the searched pixels are de-sheared by it first (about their middle
//!   row) and the boxes found are moved back onto the sheared face.

use image::imageops;
use image::{DynamicImage, GrayImage};

use crate::detect::{shrunk_to_width, DetectorParams, FaceDetector};
use crate::warp::{self, Canvas, Interpolation};
use crate::{Rect, Shear};

/// Tracking settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackerParams {
    /// Full detection every this many frames even while faces are tracked (>= 1).
    pub redetect_interval: u64,
    /// While no face is tracked, full detection every this many frames (>= 1; 1: every frame).
    pub lost_interval: u64,
    /// Full detection on the frame shrunk to at most this many columns (0: full size).
    pub detect_width: u32,
    /// The search window is the last box grown by this fraction of its size on every side.
    pub search_margin: f64,
    /// The local search looks for boxes from `size / t` to `size * t`.
    pub size_tolerance: f64,
    /// At most this many faces are tracked (the largest).
    pub max_faces: usize,
    /// Shears smaller than this are not undone before searching.
    pub min_hint: f64,
}

/// [`TrackerParams::redetect_interval`] with the network detector: it is cheap enough to find a
/// face entering the frame within a few frames (the cascade's default is 30).
pub const NETWORK_REDETECT_INTERVAL: u64 = 5;

impl TrackerParams {
    /// The defaults for a corrector whose faces the network detector finds (`network`, see
    /// [`crate::Unshear::uses_network_detector`]): full detection every
    /// `NETWORK_REDETECT_INTERVAL` frames; otherwise as [`TrackerParams::default`] (every 30,
    /// the cascade being slower).
    pub fn for_detector(network: bool) -> Self {
        let mut params = Self::default();
        if network {
            params.redetect_interval = NETWORK_REDETECT_INTERVAL;
        }
        params
    }
}

impl Default for TrackerParams {
    fn default() -> Self {
        Self {
            redetect_interval: 30,
            lost_interval: 5,
            detect_width: 640,
            search_margin: 0.5,
            size_tolerance: 1.25,
            max_faces: 4,
            min_hint: 0.05,
        }
    }
}

/// Counts of the work done, for reports and tests.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct TrackerStats {
    /// Frames seen.
    pub frames: u64,
    /// Full-frame detections run.
    pub full_detections: u64,
    /// Local (windowed) searches run.
    pub local_searches: u64,
    /// Tracks dropped because the local search found nothing.
    pub lost: u64,
}

/// The tracker (see the module docs).
#[derive(Debug, Clone)]
pub struct FaceTracker {
    detector: FaceDetector,
    params: TrackerParams,
    tracks: Vec<Rect>,
    last_full: Option<u64>,
    stats: TrackerStats,
}

impl FaceTracker {
    /// A tracker detecting with `detector` (its scale factor and neighbour count are kept for
    /// every search; its size limits apply to full detections).
    pub fn new(detector: FaceDetector, params: TrackerParams) -> Self {
        Self {
            detector,
            params,
            tracks: Vec::new(),
            last_full: None,
            stats: TrackerStats::default(),
        }
    }

    /// Work counts so far.
    pub fn stats(&self) -> TrackerStats {
        self.stats
    }

    /// The face boxes of the next frame (luma), largest first. `k_hint` is the shear the
    /// frame is believed to have (see the module docs).
    pub fn track(&mut self, gray: &GrayImage, k_hint: f64) -> Vec<Rect> {
        let frame = self.stats.frames;
        self.stats.frames += 1;
        let hint = if k_hint.is_finite() && k_hint.abs() >= self.params.min_hint {
            k_hint
        } else {
            0.0
        };
        let since_full = self.last_full.map(|f| frame - f);
        let interval = if self.tracks.is_empty() {
            self.params.lost_interval
        } else {
            self.params.redetect_interval
        };
        let full_due = since_full.is_none_or(|s| s >= interval.max(1));
        // Follow the current tracks first (also on full-detection frames: a face the shrunk
        // frame misses keeps its track).
        let mut tracked = Vec::with_capacity(self.tracks.len());
        for b in std::mem::take(&mut self.tracks) {
            self.stats.local_searches += 1;
            match self.search_near(gray, b, hint) {
                Some(n) => tracked.push(n),
                None => self.stats.lost += 1,
            }
        }
        if full_due {
            self.stats.full_detections += 1;
            self.last_full = Some(frame);
            for b in self.detect_full(gray, hint) {
                if tracked.iter().all(|t| t.iou(&b) < 0.3) {
                    tracked.push(b);
                }
            }
        }
        tracked.sort_by(|a, b| b.area().total_cmp(&a.area()));
        tracked.truncate(self.params.max_faces);
        self.tracks = tracked.clone();
        tracked
    }

    /// Detection on the whole frame, shrunk to `detect_width`.
    fn detect_full(&self, gray: &GrayImage, hint: f64) -> Vec<Rect> {
        let (img, scale) = shrunk_to_width(gray, self.params.detect_width);
        detect_desheared(&self.detector, &img, hint)
            .into_iter()
            .map(|r| Rect::new(r.x * scale, r.y * scale, r.width * scale, r.height * scale))
            .collect()
    }

    /// The face near `last` in this frame, searched in a window around it.
    fn search_near(&self, gray: &GrayImage, last: Rect, hint: f64) -> Option<Rect> {
        let (w, h) = gray.dimensions();
        let m = self.params.search_margin.max(0.0);
        let x0 = (last.x - m * last.width).floor().clamp(0.0, f64::from(w)) as u32;
        let y0 = (last.y - m * last.height).floor().clamp(0.0, f64::from(h)) as u32;
        let x1 = (last.x + last.width * (1.0 + m))
            .ceil()
            .clamp(0.0, f64::from(w)) as u32;
        let y1 = (last.y + last.height * (1.0 + m))
            .ceil()
            .clamp(0.0, f64::from(h)) as u32;
        if x1 <= x0 || y1 <= y0 {
            return None;
        }
        let window = imageops::crop_imm(gray, x0, y0, x1 - x0, y1 - y0).to_image();
        let t = self.params.size_tolerance.max(1.0);
        let base = *self.detector.params();
        let size = |v: f64| v.round().clamp(1.0, f64::from(u32::MAX)) as u32;
        let params = DetectorParams {
            min_size: (size(last.width / t), size(last.height / t)),
            max_size: Some((size(last.width * t), size(last.height * t))),
            ..base
        };
        let detector = FaceDetector::new(self.detector.cascade().clone(), params);
        detect_desheared(&detector, &window, hint)
            .into_iter()
            .map(|r| Rect::new(r.x + f64::from(x0), r.y + f64::from(y0), r.width, r.height))
            .map(|r| (last.iou(&r), r))
            .filter(|(iou, _)| *iou > 0.0)
            .max_by(|a, b| a.0.total_cmp(&b.0))
            .map(|(_, r)| r)
    }
}

/// Detects in `img` de-sheared by `k` about its middle row (none for `k = 0`), with the boxes
/// moved back so that their centres sit on the sheared face.
fn detect_desheared(detector: &FaceDetector, img: &GrayImage, k: f64) -> Vec<Rect> {
    if k == 0.0 {
        return detector.detect(img);
    }
    let shear = Shear::about_middle(k, img.height());
    let straight = match warp::try_remove_shear(
        &DynamicImage::ImageLuma8(img.clone()),
        shear,
        Interpolation::Linear,
        Canvas::Same,
    ) {
        Ok((DynamicImage::ImageLuma8(g), _)) => g,
        _ => return detector.detect(img),
    };
    detector
        .detect(&straight)
        .into_iter()
        .map(|r| {
            let c = r.center();
            Rect::new(r.x + shear.row_shift(c.y), r.y, r.width, r.height)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn face_frame(w: u32, h: u32, at: (i64, i64), k: f64) -> GrayImage {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/fixtures/faces/subject01.normal.jpeg"
        );
        let face = crate::imageio::read_image(path.as_ref(), 1 << 24)
            .expect("fixture")
            .to_luma8();
        let mut canvas = GrayImage::from_pixel(w, h, image::Luma([120]));
        imageops::overlay(&mut canvas, &face, at.0, at.1);
        let (sheared, _) = warp::apply_shear(
            &DynamicImage::ImageLuma8(canvas),
            Shear::about_middle(k, h),
            Interpolation::Linear,
            Canvas::Same,
        );
        sheared.to_luma8()
    }

    #[test]
    fn follows_a_moving_face_with_few_full_detections() {
        let mut tracker = FaceTracker::new(
            FaceDetector::frontal_face(),
            TrackerParams {
                redetect_interval: 10,
                detect_width: 320,
                ..Default::default()
            },
        );
        let mut centres = Vec::new();
        for t in 0..12i64 {
            let boxes = tracker.track(&face_frame(480, 300, (40 + 6 * t, 30), 0.0), 0.0);
            assert_eq!(boxes.len(), 1, "frame {t}: {boxes:?}");
            centres.push(boxes[0].center().x);
        }
        let s = tracker.stats();
        assert_eq!(s.frames, 12);
        assert_eq!(s.full_detections, 2, "frames 0 and 10");
        assert_eq!(s.local_searches, 11);
        assert_eq!(s.lost, 0);
        // The box moves with the face: 6 px per frame, 66 px in all (boxes jitter by a few).
        let moved = centres[11] - centres[0];
        assert!((moved - 66.0).abs() < 8.0, "moved {moved}");
    }

    #[test]
    fn lost_face_is_dropped_and_searched_for_again() {
        let mut tracker = FaceTracker::new(
            FaceDetector::frontal_face(),
            TrackerParams {
                lost_interval: 3,
                ..Default::default()
            },
        );
        let blank = GrayImage::from_pixel(400, 300, image::Luma([120]));
        assert_eq!(
            tracker
                .track(&face_frame(400, 300, (40, 30), 0.0), 0.0)
                .len(),
            1
        );
        assert!(tracker.track(&blank, 0.0).is_empty());
        assert_eq!(tracker.stats().lost, 1);
        // Frames 2 and 3: no full detection yet (every 3 frames while lost); frame 3 finds it.
        assert!(tracker
            .track(&face_frame(400, 300, (40, 30), 0.0), 0.0)
            .is_empty());
        assert_eq!(
            tracker
                .track(&face_frame(400, 300, (40, 30), 0.0), 0.0)
                .len(),
            1
        );
        assert_eq!(tracker.stats().full_detections, 2);
    }

    #[test]
    fn shear_hint_boxes_sit_on_the_sheared_face() {
        let k = 0.45;
        let frame = face_frame(480, 320, (80, 40), k);
        let plain = FaceTracker::new(FaceDetector::frontal_face(), TrackerParams::default())
            .track(&frame, 0.0);
        let hinted = FaceTracker::new(FaceDetector::frontal_face(), TrackerParams::default())
            .track(&frame, k);
        assert_eq!((plain.len(), hinted.len()), (1, 1));
        // Found in the de-sheared frame and moved back: the same face as without the hint
        // (boxes of one face differ by a few pixels between two detections).
        let (a, b) = (plain[0].center(), hinted[0].center());
        assert!(a.distance(b) < 10.0, "{a:?} vs {b:?}");
    }
}

//! Faces of a still scene recognised when they come back into view, through the camera's
//! measured motion.
//!
//! A camera panning over a still scene sees each face only for a few frames at a time (at the
//! speeds whose shear matters, a face crosses the frame in a handful of frames), so a face track
//! sees few speeds and its own bias (asymmetry, pose) can hardly be told from the readout. But
//! the content's displacement between consecutive frames, summed, says where each frame's view
//! lies in the scene: a face of the scene keeps its place there, so it is the same face
//! whenever it comes back into view (the pan stops, turns, shakes), and its bias is shared by
//! every sighting. [`SceneAnchors`] gives each such face one identity over the clip.

/// A face's place in the scene: its eyes' midpoint minus the view's accumulated displacement.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct ScenePlace {
    /// The stretch of frames whose displacements were all measured (a frame pair without a
    /// measurement starts a new one: places of different stretches are not comparable).
    pub stretch: u64,
    pub x: f64,
    pub y: f64,
}

#[derive(Debug, Clone, Copy)]
struct Anchor {
    id: u64,
    place: ScenePlace,
    eye_distance: f64,
    sightings: f64,
}

/// The first identity given to a face of the scene: far above any track number, so the two
/// never collide in the calibration.
pub(crate) const FIRST_ANCHOR: u64 = 1 << 48;

/// Where the view is in the scene, frame after frame, and the faces of the scene seen so far.
#[derive(Debug, Clone, Default)]
pub(crate) struct SceneAnchors {
    stretch: u64,
    /// The view's accumulated displacement: where the scene's origin appears in the frame.
    offset: (f64, f64),
    started: bool,
    anchors: Vec<Anchor>,
    by_track: std::collections::HashMap<u64, u64>,
}

impl SceneAnchors {
    /// Moves the view to the next frame: `shift` is the content's displacement into it (`None`
    /// when it was not measured: a new stretch starts).
    pub fn advance(&mut self, shift: Option<(f64, f64)>) {
        match shift {
            Some((dx, dy)) if self.started && dx.is_finite() && dy.is_finite() => {
                self.offset.0 += dx;
                self.offset.1 += dy;
            }
            _ => {
                if self.started {
                    self.stretch += 1;
                }
                self.started = true;
                self.offset = (0.0, 0.0);
            }
        }
    }

    /// The scene place of a face whose eyes' midpoint is at `(x, y)` in the current frame,
    /// sheared by about `k` (rows away from the middle row `c` are displaced by `k (y - c)`
    /// against the displacement measured there).
    pub fn place(&self, x: f64, y: f64, k: f64, c: f64) -> ScenePlace {
        ScenePlace {
            stretch: self.stretch,
            x: x - self.offset.0 - k * (y - c),
            y: y - self.offset.1,
        }
    }

    /// The identity of the scene face that `track` (a face moving with the scene, at `place`,
    /// eyes `eye_distance` apart) is: the one it was given before, else the face of the scene
    /// within half an eye distance of its place and of a similar size, else a new one.
    pub fn identify(&mut self, track: u64, place: ScenePlace, eye_distance: f64) -> u64 {
        if let Some(&id) = self.by_track.get(&track) {
            return id;
        }
        let near = |a: &&mut Anchor| {
            let tol = 0.5 * a.eye_distance.min(eye_distance).max(8.0);
            let ratio = eye_distance / a.eye_distance.max(1e-9);
            a.place.stretch == place.stretch
                && (a.place.x - place.x).abs() <= tol
                && (a.place.y - place.y).abs() <= tol
                && (0.75..=1.0 / 0.75).contains(&ratio)
        };
        let id = match self.anchors.iter_mut().find(near) {
            Some(a) => {
                // The place and size as the mean of the sightings.
                let w = 1.0 / (a.sightings + 1.0);
                a.place.x += w * (place.x - a.place.x);
                a.place.y += w * (place.y - a.place.y);
                a.eye_distance += w * (eye_distance - a.eye_distance);
                a.sightings += 1.0;
                a.id
            }
            None => {
                let id = FIRST_ANCHOR + self.anchors.len() as u64;
                self.anchors.push(Anchor {
                    id,
                    place,
                    eye_distance,
                    sightings: 1.0,
                });
                id
            }
        };
        self.by_track.insert(track, id);
        id
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A face at scene place 500 seen by a view panning 100 px/frame: at frame n it appears at
    /// 500 + 100 n. Two tracks seeing it ten frames apart are the same face.
    #[test]
    fn a_face_coming_back_into_view_is_recognised() {
        let mut s = SceneAnchors::default();
        let mut ids = Vec::new();
        for n in 0..30 {
            // Pans right for 10 frames, stops for 5, pans back.
            let v = match n {
                0 => 0.0,
                1..=10 => 100.0,
                11..=15 => 0.0,
                _ => -100.0,
            };
            s.advance(Some((v, 0.0)));
            let x = 500.0 + s.offset.0 + 0.3; // measurement noise
            if (0.0..1920.0).contains(&x) && matches!(n, 2 | 13 | 25) {
                let track = n as u64; // a new track each time
                ids.push(s.identify(track, s.place(x, 300.0, 0.0, 360.0), 40.0));
            }
        }
        assert_eq!(ids.len(), 3, "{ids:?}");
        assert!(ids.iter().all(|&i| i == ids[0] && i >= FIRST_ANCHOR));
    }

    #[test]
    fn faces_apart_in_the_scene_or_in_size_are_different() {
        let mut s = SceneAnchors::default();
        s.advance(None);
        let a = s.identify(0, s.place(100.0, 300.0, 0.0, 360.0), 40.0);
        // 30 px away: more than half an eye distance.
        let b = s.identify(1, s.place(130.0, 300.0, 0.0, 360.0), 40.0);
        // Same place, twice the size.
        let c = s.identify(2, s.place(100.0, 300.0, 0.0, 360.0), 80.0);
        // Same place and size: the first face.
        let d = s.identify(3, s.place(110.0, 305.0, 0.0, 360.0), 42.0);
        assert!(a != b && a != c && b != c);
        assert_eq!(d, a);
        // A track keeps the identity it was given.
        assert_eq!(s.identify(1, s.place(100.0, 300.0, 0.0, 360.0), 40.0), b);
    }

    #[test]
    fn an_unmeasured_displacement_starts_a_new_stretch() {
        let mut s = SceneAnchors::default();
        s.advance(None);
        let a = s.identify(0, s.place(100.0, 300.0, 0.0, 360.0), 40.0);
        s.advance(None);
        let b = s.identify(1, s.place(100.0, 300.0, 0.0, 360.0), 40.0);
        assert_ne!(a, b);
    }

    #[test]
    fn rows_away_from_the_middle_are_placed_through_the_shear() {
        let mut s = SceneAnchors::default();
        s.advance(None);
        // A face 200 rows below the middle of a frame sheared by 0.25 appears 50 px right.
        let p = s.place(150.0, 560.0, 0.25, 360.0);
        assert!((p.x - 100.0).abs() < 1e-9 && (p.y - 560.0).abs() < 1e-9);
    }
}

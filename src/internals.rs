//! Pieces of the library's inside that the development examples (`examples/`) use: the
//! correlation-filter feature search and a median. Feature `dev`; like `dev`, no stability
//! promise (they change with the pipeline).

pub use crate::filters::correlate::Peak;
pub use crate::locate::filters::{
    expected_eyes, EyePair, EyeSearch, FacePoints, FeatureLocator, Located, NormalizedFace,
    EYE_CANDIDATES, EYE_PAIR_FEATURES,
};
pub use crate::stats::median;
pub use crate::video::motion::{region_shift, BandShift, FrameShift, MotionEstimator};
pub use crate::video::temporal::{ShearFilter, ShearSmoother};

/// The scene ruler alone on `gray`, with its default settings (what
/// [`Unshear::estimate`](crate::Unshear::estimate) reports as `scene`).
pub fn scene_shear(gray: &image::GrayImage) -> Option<crate::SceneShear> {
    crate::scene::estimate_scene_shear(gray, &Default::default())
}

/// The image's shear from the faces' `faces_k` (of `faces` agreeing faces) and the scene's
/// reading as `ruler` combines them, with which rulers made it and whether the two disagree
/// (what [`Unshear::estimate`](crate::Unshear::estimate) reports as `k`, `k_source` and
/// `scene_disagrees`).
pub fn fuse(
    faces_k: Option<f64>,
    faces: usize,
    scene: Option<&crate::SceneShear>,
    ruler: crate::Ruler,
) -> (Option<f64>, Option<crate::ShearSource>, bool) {
    crate::pipeline::fuse(faces_k, faces, scene, ruler)
}

/// How many times the landmark network has run in this process so far, on every thread (each
/// crop read as it is, and each mirrored reading, counts once): the difference across one
/// [`Unshear::estimate`](crate::Unshear::estimate) is that frame's network runs, the measure
/// of the windows' judging cost (`cargo bench --features dev --bench pipeline -- realistic`
/// prints it per frame).
pub fn landmark_network_runs() -> u64 {
    crate::locate::network::RUNS.load(std::sync::atomic::Ordering::Relaxed)
}

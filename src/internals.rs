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

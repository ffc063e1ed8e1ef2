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

//! Face detection: OpenCV-compatible Viola-Jones on Haar cascades, and face proposals.
//!
//! The detector reproduces OpenCV 4's `CascadeClassifier::detectMultiScale` for Haar cascades
//! closely enough that its boxes coincide with OpenCV's on ordinary photos: same scale list,
//! the same bit-exact bilinear image pyramid, the same window grid and early skip, the same
//! `f32`/`f64` arithmetic in feature evaluation and the same `groupRectangles` merge. The
//! embedded default is OpenCV's `haarcascade_frontalface_alt2.xml`; any OpenCV Haar cascade file
//! (new or old XML layout, upright and 45° features, trees of any depth) can be loaded instead.
//!
//! ```no_run
//! use unshear::detect::{FaceDetector, to_gray_opencv};
//! let img = image::open("face.jpg").unwrap();
//! let faces = FaceDetector::frontal_face().detect(&to_gray_opencv(&img));
//! ```
//!
//! Files by job:
//! * [`cascade`](Cascade): XML loading and validation;
//! * `integral`: sum, squared-sum and tilted integral images;
//! * `resize`: the bit-exact pyramid resize and OpenCV's grey conversion;
//! * `viola_jones`: the multi-scale sliding window and variance normalisation;
//! * `grouping`: OpenCV's `groupRectangles`;
//! * `proposals` ([`ProposalNet`]): a small convolutional window classifier, trained by this
//!   project on sheared and rolled faces, whose windows the thorough face search
//!   (`pipeline::FaceSearch::Thorough`) adds to the cascade's boxes as candidates for faces
//!   the cascade misses.

pub mod boxes;
mod cascade;
mod grouping;
mod integral;
mod proposals;
mod resize;
mod viola_jones;

pub use cascade::Cascade;
pub use proposals::{Proposal, ProposalNet, ProposalParams};
pub(crate) use resize::shrunk_to_width;
pub use resize::to_gray_opencv;
pub use viola_jones::{DetectorParams, FaceDetector};

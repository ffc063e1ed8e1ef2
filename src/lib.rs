//! # unshear
//!
//! Remove rolling-shutter skew from photos and video frames of people, using the face itself as
//! the ruler: Viola-Jones face detection searched in de-sheared and turned views, the face's
//! features located by a small landmark network (the default) or by correlation filters for
//! the eyes, nostrils, nose and mouth (MOSSE by default, the paper's UMACE on request), the
//! shear estimate of equation 5 or the shear-roll-yaw model that extends it, and the row-shift
//! correction of equation 6 of the paper in `../shared/paper/`.
//!
//! Data flows one way through the modules:
//!
//! ```text
//! imageio ─▶ detect ─▶ landmarks, or features (filters) ─▶ estimate ─▶ warp ─▶ imageio
//! ```
//!
//! * [`imageio`]: read (EXIF orientation applied, size-limited) and write (atomic, never over an input).
//! * [`detect`]: OpenCV-compatible Viola-Jones face detection on Haar cascades.
//! * [`landmarks`]: the landmark network (eyes, nose, mouth and the shear read off one crop of
//!   the face), the default locator.
//! * [`filters`]: correlation filters (UMACE, ASEF, MOSSE): synthesis, file format, frequency-domain
//!   correlation.
//! * [`features`]: eyes, nostrils, nose and mouth located in the 150-px face with the filters.
//! * [`estimate`]: the shear `k` from the feature points (equation 5, or shear with roll and
//!   yaw).
//! * [`warp`]: sub-pixel row shifts that apply or undo a shear (equation 6), and the turned views
//!   the detector searches.
//! * [`pipeline`]: all of the above behind one [`Unshear`] value.
//! * [`train`]: building the eye filters from an annotated data set.
//! * [`eval`]: the measurements the README reports (synthetic shear, nostrils, recognition).
//! * [`video`]: y4m streams and frame folders, faces tracked between detections, `k` filtered
//!   over time.

// Every public item is documented (`.ci/run` denies warnings).
#![warn(missing_docs)]

pub mod annotate;
pub mod dataset;
pub mod detect;
pub mod error;
pub mod estimate;
pub mod eval;
pub mod features;
pub mod filters;
pub mod geometry;
pub mod imageio;
pub mod landmarks;
mod modelfile;
pub mod pipeline;
pub mod resample;
#[cfg(test)]
mod testing;
pub mod train;
pub mod video;
pub mod warp;

pub use error::{Error, Result};
pub use geometry::{Point, Rect, Shear};
pub use pipeline::{FaceReport, ImageReport, Unshear};

/// The README's Rust example, compiled as a doctest so it cannot go stale.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
pub struct ReadmeDoctests;

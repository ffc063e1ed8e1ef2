//! # unshear
//!
//! Remove rolling-shutter skew from photos and video frames of people, using the face itself as
//! the ruler: faces found by Viola-Jones (searched in de-sheared and turned views) and a small
//! proposal classifier, their eyes, nose and mouth located by a small landmark network (or by
//! the paper's correlation filters), the shear estimated from those points (equation 5 of the
//! paper in `../shared/paper/`, or the shear-and-roll model that extends it), and undone row by
//! row (equation 6).
//!
//! ```no_run
//! use unshear::{Config, CorrectOptions, Error, FileOptions, Unshear};
//!
//! # fn main() -> unshear::Result<()> {
//! let unshear = Unshear::new(Config::default())?;
//! // Read with its EXIF orientation applied; written with its colour profile and EXIF.
//! let (options, file) = (CorrectOptions::default(), FileOptions::default());
//! match unshear.correct_file("photo.jpg", "fixed.jpg", &options, &file) {
//!     Ok(report) => println!("k = {:+.3}", report.k.unwrap_or_default()),
//!     Err(Error::InvalidArgument(why)) => eprintln!("not corrected: {why}"),
//!     Err(e) => return Err(e),
//! }
//! # Ok(())
//! # }
//! ```
//!
//! Data flows one way through the modules; none imports a module after it in this list:
//!
//! ```text
//! geometry, stats ─▶ imageio ─▶ warp ─▶ scene ─▶ detect ─▶ filters ─▶ estimate ─▶ locate ─▶ config
//!     ─▶ pipeline ─▶ video ─▶ dev (feature "dev") ─▶ the `unshear` binary (crate `unshear-cli`)
//! ```
//!
//! * [`imageio`]: read (EXIF orientation applied, size-limited) and write (atomic, never over an
//!   input).
//! * [`warp`]: sub-pixel row shifts that apply or undo a shear (equation 6), and turned views.
//! * `scene`: the shear the scene's verticals give ([`SceneShear`]), a second ruler beside the
//!   faces.
//! * [`detect`]: Viola-Jones on OpenCV's Haar cascades, the face proposal classifier, and the
//!   geometry tying a detector box to the eyes it holds.
//! * [`filters`]: correlation filters (UMACE, ASEF, MOSSE): synthesis, file format, correlation.
//! * [`estimate`]: the shear `k` from located points (equation 5, shear and roll, yaw).
//! * [`locate`]: where the features are in one face: the landmark network (which reads the
//!   shear from its points as it walks), or the filters.
//! * [`config`]: every setting, as one plain value.
//! * [`pipeline`]: all of the above behind one [`Unshear`] value, with how far each face's
//!   estimate can be trusted.
//! * [`video`]: y4m streams and frame folders, faces tracked between detections, `k` filtered
//!   over time.
//! * `dev` (feature `dev`): the data sets, filter training, the rolling-shutter simulator and the
//!   measurements of `docs/accuracy.md`.
//!
//! The default features are empty. The command-line tool is another crate of the workspace
//! (`unshear-cli`, in `cli/`): argument parsing, progress, Ctrl-C, the `ffmpeg` driver for video
//! containers, and the `eval`, `train` and `simulate` commands on the `dev` feature.

// Every public item is documented (`.ci/run` denies warnings).
#![warn(missing_docs)]

pub mod annotate;
pub mod config;
pub mod deblur;
pub mod detect;
#[cfg(feature = "dev")]
pub mod dev;
mod error;
pub mod estimate;
pub mod filters;
pub(crate) mod fitted;
mod geometry;
pub mod imageio;
#[cfg(feature = "dev")]
pub mod internals;
pub mod locate;
mod modelfile;
pub(crate) mod nn;
pub mod pipeline;
pub(crate) mod resample;
#[cfg(any(test, feature = "dev"))]
mod rng;
mod scene;
pub(crate) mod stats;
#[cfg(test)]
mod testing;
pub mod video;
pub mod warp;

pub use config::{Config, Detector, FaceSearch, Locator, Ruler};
pub use error::{Error, Result};
pub use geometry::{Point, Rect, Shear};
pub use pipeline::{
    CorrectOptions, FaceReport, FaceStart, FileOptions, ImageReport, Models, Readout, Refusal,
    Region, RowShear, ShearSource, Unshear,
};
pub use scene::{SceneSegment, SceneShear};

/// The README's Rust example, compiled as a doctest so it cannot go stale.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
pub struct ReadmeDoctests;

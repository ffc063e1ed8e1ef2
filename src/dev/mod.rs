//! Developer tools behind the `dev` feature: reading the annotated data sets, training the
//! correlation filters, and the measurements in `docs/accuracy.md`.

pub mod dataset;
pub mod eval;
pub mod landmark_crops;
pub mod simulate;
pub mod train;

/// The trainers' seeded generator, for the example programs that cut training data.
pub use crate::rng::SplitMix64;

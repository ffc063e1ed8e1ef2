//! Where a face's features are, in one face: the landmark network ([`network`], the default)
//! or the paper's correlation filters in the 150-pixel normalised face (`filters`).

pub(crate) mod filters;
pub mod network;

//! What the fit is judged on, kept apart from the fit itself.
//!
//! * [`ground_truth`]: random supertoroids with known parameters, their clouds (full or a
//!   single view, noise, outliers) and the success rule up to the shape's symmetries.
//! * [`chamfer`]: how far apart two surfaces are, for shapes whose parameters are ambiguous.
//! * [`attainable`]: the share of a suite's cases that an efficient estimator (one at the
//!   Cramér-Rao bound of each cloud) would get right.

pub mod attainable;
pub mod chamfer;
pub mod ground_truth;

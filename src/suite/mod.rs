//! What the fit is judged on, kept apart from the fit itself.
//!
//! * [`ground_truth`]: random supertoroids with known parameters, their clouds (full or a
//!   single view, noise, outliers) and the success rule up to the shape's symmetries.
//! * [`broad`]: shapes beyond the suite's ranges seen through a depth sensor's noise,
//!   the clouds in the camera's frame.
//! * [`chamfer`]: how far apart two surfaces are, for shapes whose parameters are ambiguous.
//! * [`attainable`]: the share of a suite's cases that an efficient estimator (one at the
//!   Cramér-Rao bound of each cloud) would get right.

pub mod attainable;
pub mod broad;
pub mod chamfer;
pub mod ground_truth;

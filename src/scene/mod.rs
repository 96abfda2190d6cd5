//! Scenes: the table found and taken away, so that a detector's box is enough to fit
//! what is in it, and a whole frame split into the objects on its table and fitted.
//!
//! * [`plane`]: a robust plane fit (seeded RANSAC, refined by least squares).
//! * [`table`]: the table in a depth frame's box removed and the object kept as the
//!   largest connected region of pixels above it; a box that holds nothing but the table
//!   is refused.
//! * [`objects`]: a whole frame's table and the objects standing on it, split apart by
//!   Euclidean clustering on a grid of cells.
//! * [`fit`]: every object of a frame fitted in one batch ([`fit::fit_scene`]).
//! * [`pieces`]: pieces of one object the clustering split apart, joined after the fits.

pub mod fit;
pub mod objects;
pub mod pieces;
pub mod plane;
pub mod table;

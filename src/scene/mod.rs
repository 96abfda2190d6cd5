//! Scenes: the table an object stands on, found and taken away, so that a detector's box
//! is enough to fit what is in it.
//!
//! * [`plane`]: a robust plane fit (seeded RANSAC, refined by least squares).
//! * [`table`]: the table in a depth frame's box removed and the object kept as the
//!   largest connected region of pixels above it; a box that holds nothing but the table
//!   is refused.

pub mod plane;
pub mod table;

//! Free space: what a depth sensor's lines of sight say about where the object is not.
//!
//! Given the sensor's position (the fit's `viewpoint`), points on each point's line of
//! sight a little in front of it are known to lie outside the object (the sensor saw
//! through that space to reach the point), and the evaluators charge a candidate for each
//! one it puts inside itself (residual min(r, 0), see `eval::PointSet`).
//!
//! A support the object rests on (a table) says the same of the space under it: points
//! just below the table under the sample points ([`below_support`]) join them.
//!
//! Tried and left out: points on the lines of sight that pass just beside the cloud's
//! outline or through its gaps (the sensor saw past the object there), at the cloud's
//! depths. They were all outside the true shapes, but a body grown into the unseen side
//! hides behind the visible surface and seldom crosses them: 356 -> 357 of 540 suite
//! cases, for twice the free-space points and the assumption that nothing in front hid the
//! outline.

use glam::DVec3;

/// Offsets of the in-front points in normalised units (the cloud's RMS radius is 1):
/// clear of the noise (the suite's 2% of the size is about 0.03), near enough to the
/// surface to catch a body grown towards the sensor. Measured on the ground-truth suite
/// (540 single- and full-view cases): (0.1, 0.25, 0.5) 352 successes, (0.05, 0.15, 0.3)
/// 356, (0.03, 0.08, 0.2) 349.
pub const IN_FRONT_OFFSETS: [f64; 3] = [0.05, 0.15, 0.3];

/// One point per sample point on its line of sight towards `viewpoint`, at
/// IN_FRONT_OFFSETS[i mod 3] in front of it (all normalised).
pub fn in_front(sample: &[DVec3], viewpoint: DVec3) -> Vec<DVec3> {
    sample
        .iter()
        .enumerate()
        .filter_map(|(i, p)| {
            let to_sensor = viewpoint - *p;
            let distance = to_sensor.length();
            let offset = IN_FRONT_OFFSETS[i % IN_FRONT_OFFSETS.len()];
            // a point closer to the sensor than the offset has no free space to spare
            (distance > 2.0 * offset).then(|| *p + to_sensor * (offset / distance))
        })
        .collect()
}

/// Depths below the support plane of its points (normalised units): inside the table,
/// where the object is not, near enough to its surface to catch a body grown down
/// through it.
pub const BELOW_SUPPORT_OFFSETS: [f64; 2] = [0.05, 0.15];

/// One point per sample point under it, inside the support (a table): the sample point
/// projected onto the plane and moved BELOW_SUPPORT_OFFSETS[i mod 2] below it (all
/// normalised; the plane's normal towards the object). Points already below the plane
/// (noise, outliers) give none.
pub fn below_support(sample: &[DVec3], normal: DVec3, offset: f64) -> Vec<DVec3> {
    sample
        .iter()
        .enumerate()
        .filter_map(|(i, p)| {
            let height = normal.dot(*p) + offset;
            let depth = BELOW_SUPPORT_OFFSETS[i % BELOW_SUPPORT_OFFSETS.len()];
            (height > 0.0).then(|| *p - normal * (height + depth))
        })
        .collect()
}

/// A free-space point counts as violated when it lies this deep inside a candidate
/// (normalised units: clear of the suite's noise).
const VIOLATION_DEPTH: f64 = 0.02;

/// Above this fraction of violated free-space points the viewpoint is taken to be wrong.
/// Measured on the suite's 90 single views (0-2% noise, 0-10% outliers in the bounding
/// box, whose own free-space points can lie inside the object): with the camera's
/// position at most 0.16 (median 0.03); from the point opposite the camera 0.20 at the
/// 10th percentile (median 0.34); from beside it median 0.19.
pub const MAX_VIOLATED_FRACTION: f64 = 0.25;

/// The fraction of free-space points inside `candidate` by more than VIOLATION_DEPTH.
pub fn violated_fraction(candidate: &crate::eval::Candidate, free: &[DVec3]) -> f64 {
    if free.is_empty() {
        return 0.0;
    }
    let inverse = candidate.pose.rotation.inverse();
    let violated = free
        .iter()
        .filter(|p| {
            let q = inverse * (**p - candidate.pose.translation);
            crate::model::meridian_distance(&candidate.shape, q).signed < -VIOLATION_DEPTH
        })
        .count();
    violated as f64 / free.len() as f64
}

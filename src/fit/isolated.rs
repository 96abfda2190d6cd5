//! Points far from every other point: stray returns spread over the scene rather than on
//! the object (a depth sensor's specks, a segmentation that let bits of the background
//! through). Each point's distance to its [`NEIGHBOURS`]-th nearest neighbour against the
//! median of those distances: a point on a sampled surface has its neighbours at the
//! sampling's spacing, a point strewn over a volume many times the object's has them
//! many spacings away. Such points are set aside before the fit (the statistical outlier
//! removal of PCL and Open3D, by the median rather than the mean).

use glam::DVec3;
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rayon::prelude::*;
use rustc_hash::FxHashMap;
use std::num::NonZeroUsize;

/// The neighbour whose distance measures how isolated a point is.
pub const NEIGHBOURS: usize = 8;

/// A point is isolated when its [`NEIGHBOURS`]-th neighbour is farther than this many
/// times the median of that distance over the cloud.
pub const ISOLATION_FACTOR: f64 = 5.0;

/// The most points whose distances give the median: a larger cloud's median is taken
/// on an even stride of it (the clouds of a single view, up to a few thousand points,
/// are measured whole).
pub const MEDIAN_SAMPLE: usize = 8000;

/// The cloud without its isolated points; None where none is isolated (or the cloud is
/// too small to tell, or holds a non-finite point).
///
/// Only the points that cannot be told kept from their grid cell are queried: a point
/// whose cell (a cube whose diagonal is the isolation distance) holds [`NEIGHBOURS`]
/// others has them within that distance. On a sampled surface that is most points, so a
/// depth frame's mask of tens of thousands of points costs a few thousand queries.
pub fn without_isolated(points: &[DVec3]) -> Option<Vec<DVec3>> {
    // (a non-finite point is the cloud check's to refuse, which comes next)
    if points.len() <= 4 * NEIGHBOURS || !points.iter().all(|p| p.is_finite()) {
        return None;
    }
    let entries: Vec<[f64; 3]> = points.iter().map(|p| p.to_array()).collect();
    let tree = ImmutableKdTree::<f64, 3>::new_from_slice(&entries).ok()?;
    let k = NonZeroUsize::new(NEIGHBOURS + 1).expect("non-zero");
    // (the point itself is its own nearest: the (k+1)-th is its k-th neighbour)
    let kth_distance = |p: &[f64; 3]| {
        tree.query(p)
            .nearest_n::<SquaredEuclidean<f64>>(k)
            .execute()
            .iter()
            .map(|n| n.distance)
            .fold(0.0, f64::max)
            .sqrt()
    };
    let stride = points.len().div_ceil(MEDIAN_SAMPLE);
    let mut sampled: Vec<f64> = entries
        .par_iter()
        .step_by(stride)
        .map(kth_distance)
        .collect();
    let median = crate::fit::report::median(&mut sampled);
    if !(median > 0.0) {
        return None;
    }
    let limit = ISOLATION_FACTOR * median;
    let side = limit / 3f64.sqrt();
    let cell = |p: &DVec3| (*p / side).floor().as_i64vec3().to_array();
    let mut occupancy: FxHashMap<[i64; 3], usize> = FxHashMap::default();
    for p in points {
        *occupancy.entry(cell(p)).or_default() += 1;
    }
    let kept: Vec<bool> = points
        .par_iter()
        .zip(&entries)
        .map(|(p, e)| occupancy[&cell(p)] > NEIGHBOURS || kth_distance(e) <= limit)
        .collect();
    let count = kept.iter().filter(|k| **k).count();
    (count < points.len()).then(|| {
        points
            .iter()
            .zip(&kept)
            .filter(|(_, k)| **k)
            .map(|(p, _)| *p)
            .collect()
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{Pose, Shape};
    use crate::synth;
    use glam::DQuat;
    use rand::Rng;

    /// A noisy surface of `count` points and 5% of that strewn over a box four times the
    /// object's extent: every surface point stays, at most a tenth of the strays do.
    fn strays_go_and_the_surface_stays(count: usize) {
        let shape = Shape::new(0.06, 0.05, 0.02, 2.0, 0.8, 1.0);
        let pose = Pose::new(DQuat::IDENTITY, DVec3::new(0.0, 0.0, 0.6));
        let mut rng = synth::rng(7);
        let mut points = synth::sample_surface(&shape, &pose, count, &mut rng);
        synth::add_noise(&mut points, 0.002, &mut rng);
        assert!(
            without_isolated(&points).is_none(),
            "a clean surface keeps every point"
        );
        let surface = points.len();
        let strays = count / 20;
        for _ in 0..strays {
            let offset = DVec3::new(
                rng.random_range(-0.5..0.5),
                rng.random_range(-0.5..0.5),
                rng.random_range(-0.5..0.5),
            );
            points.push(pose.translation + offset);
        }
        let kept = without_isolated(&points).expect("strays set aside");
        // (the kept points keep their order: the surface's come first)
        assert!(
            kept.len() >= surface && kept[..surface] == points[..surface],
            "every surface point stays"
        );
        assert!(
            kept.len() - surface <= strays / 10,
            "{} of {strays} strays kept",
            kept.len() - surface
        );
    }

    #[test]
    fn strays_over_the_scene_go_and_the_surface_stays() {
        strays_go_and_the_surface_stays(2000);
    }

    #[test]
    fn a_depth_mask_sized_cloud_is_screened_on_its_median_stride() {
        // (over MEDIAN_SAMPLE points: the median from a stride, most points kept by
        // their cell)
        strays_go_and_the_surface_stays(3 * MEDIAN_SAMPLE);
    }
}

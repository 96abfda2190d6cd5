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
use std::num::NonZeroUsize;

/// The neighbour whose distance measures how isolated a point is.
pub const NEIGHBOURS: usize = 8;

/// A point is isolated when its [`NEIGHBOURS`]-th neighbour is farther than this many
/// times the median of that distance over the cloud.
pub const ISOLATION_FACTOR: f64 = 5.0;

/// The cloud without its isolated points; None where none is isolated (or the cloud is
/// too small to tell, or holds a non-finite point).
pub fn without_isolated(points: &[DVec3]) -> Option<Vec<DVec3>> {
    // (a non-finite point is the cloud check's to refuse, which comes next)
    if points.len() <= 4 * NEIGHBOURS || !points.iter().all(|p| p.is_finite()) {
        return None;
    }
    let entries: Vec<[f64; 3]> = points.iter().map(|p| p.to_array()).collect();
    let tree = ImmutableKdTree::<f64, 3>::new_from_slice(&entries).ok()?;
    let k = NonZeroUsize::new(NEIGHBOURS + 1).expect("non-zero");
    let distances: Vec<f64> = entries
        .par_iter()
        .map(|p| {
            tree.query(p)
                .nearest_n::<SquaredEuclidean<f64>>(k)
                .execute()
                .iter()
                .map(|n| n.distance)
                .fold(0.0, f64::max)
                .sqrt()
        })
        .collect();
    let mut sorted = distances.clone();
    let median = crate::fit::report::median(&mut sorted);
    if !(median > 0.0) {
        return None;
    }
    let limit = ISOLATION_FACTOR * median;
    let kept: Vec<DVec3> = points
        .iter()
        .zip(&distances)
        .filter(|(_, d)| **d <= limit)
        .map(|(p, _)| *p)
        .collect();
    (kept.len() < points.len()).then_some(kept)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{Pose, Shape};
    use crate::synth;
    use glam::DQuat;
    use rand::Rng;

    #[test]
    fn strays_over_the_scene_go_and_the_surface_stays() {
        let shape = Shape::new(0.06, 0.05, 0.02, 2.0, 0.8, 1.0);
        let pose = Pose::new(DQuat::IDENTITY, DVec3::new(0.0, 0.0, 0.6));
        let mut rng = synth::rng(7);
        let mut points = synth::sample_surface(&shape, &pose, 2000, &mut rng);
        synth::add_noise(&mut points, 0.002, &mut rng);
        assert!(
            without_isolated(&points).is_none(),
            "a clean surface keeps every point"
        );
        // 5% strewn over a box four times the object's extent
        let surface = points.len();
        for _ in 0..100 {
            let offset = DVec3::new(
                rng.random_range(-0.5..0.5),
                rng.random_range(-0.5..0.5),
                rng.random_range(-0.5..0.5),
            );
            points.push(pose.translation + offset);
        }
        let kept = without_isolated(&points).expect("strays set aside");
        let surface_kept = kept
            .iter()
            .filter(|p| points[..surface].contains(p))
            .count();
        assert_eq!(surface_kept, surface, "every surface point stays");
        assert!(
            kept.len() - surface <= 10,
            "{} of 100 strays kept",
            kept.len() - surface
        );
    }
}

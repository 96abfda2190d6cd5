//! The surface chamfer distance between two shapes: how far apart their surfaces are,
//! whatever their parameters. A superellipsoid's parameters are ambiguous (a box is the
//! same box with its axes relabelled and its eps exchanged; a sphere has no axes), so
//! the model-choice suite judges a superellipsoid's fit by its surface: within
//! [`CHAMFER_BOUND`] of the true one.
//!
//! (Measured point to surface, not sample to sample: two samples of one surface lie
//! half their spacing apart, about 2% of a 15 cm box's size at 2000 points.)

use crate::model::{Pose, Shape};
use crate::synth;
use glam::DVec3;
use kiddo::{ImmutableKdTree, SquaredEuclidean};

/// A fit is right when its surface lies within this share of the true object's size
/// (bounding-box half-diagonal) of the true surface, on average both ways.
pub const CHAMFER_BOUND: f64 = 0.02;
/// Surface samples of each shape, and the parameter grid (per side) of the surface
/// they are measured to.
const SAMPLES: usize = 2000;
const GRID: usize = 200;

/// The mean of the two mean distances (each surface's area-uniform samples to the other
/// surface), over the first shape's size.
pub fn relative_chamfer(truth: (&Shape, &Pose), fitted: (&Shape, &Pose)) -> f64 {
    let mut rng = synth::rng(1);
    let a = synth::sample_surface(truth.0, truth.1, SAMPLES, &mut rng);
    let b = synth::sample_surface(fitted.0, fitted.1, SAMPLES, &mut rng);
    0.5 * (mean_distance(&a, fitted) + mean_distance(&b, truth)) / truth.0.size()
}

/// The mean distance from `points` to a surface: to the tangent plane of the nearest
/// point of a dense parameter grid (exact on flat faces, where the grid is sparse, and
/// within the grid's spacing squared over the curvature radius elsewhere).
fn mean_distance(points: &[DVec3], surface: (&Shape, &Pose)) -> f64 {
    let grid = crate::grasp::surface::grid(surface.0, surface.1, GRID, GRID);
    let entries: Vec<[f64; 3]> = grid.iter().map(|q| q.point).collect();
    let Ok(tree) = ImmutableKdTree::<f64, 3>::new_from_slice(&entries) else {
        return f64::INFINITY;
    };
    let total: f64 = points
        .iter()
        .map(|p| {
            let nearest = tree
                .query(&p.to_array())
                .nearest_one::<SquaredEuclidean<f64>>()
                .execute();
            let q = &grid[nearest.item as usize];
            (*p - DVec3::from(q.point)).dot(DVec3::from(q.normal)).abs()
        })
        .sum();
    total / points.len().max(1) as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DQuat;

    #[test]
    fn a_box_relabelled_is_the_same_surface_and_a_larger_one_is_not() {
        let pose = Pose::new(DQuat::IDENTITY, DVec3::new(0.0, 0.0, 0.5));
        let boxy = Shape::new(0.05, 0.03, 0.08, 0.0, 0.2, 0.2);
        // the same box, its x and z axes exchanged by a quarter turn about y
        let turned = Pose::new(
            DQuat::from_rotation_y(std::f64::consts::FRAC_PI_2),
            pose.translation,
        );
        let relabelled = Shape::new(0.08, 0.03, 0.05, 0.0, 0.2, 0.2);
        let same = relative_chamfer((&boxy, &pose), (&relabelled, &turned));
        assert!(same < 0.5 * CHAMFER_BOUND, "{same}");
        let larger = Shape::new(0.055, 0.033, 0.088, 0.0, 0.2, 0.2);
        let off = relative_chamfer((&boxy, &pose), (&larger, &pose));
        assert!(off > CHAMFER_BOUND, "{off}");
    }
}

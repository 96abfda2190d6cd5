use super::SeededRng;
use crate::model::{Pose, Shape};
use glam::DVec3;
use rand::Rng;
use rand_distr::{Distribution, Normal};

/// Grid resolution of the area table; fine enough that even eps = 0.1 (nearly square
/// corners, where the parametrisation bunches up) gets near-uniform samples.
const GRID: usize = 256;

/// `count` points spread uniformly by area over the surface, in world coordinates.
///
/// The (eta, omega) domain is cut into GRID x GRID cells; each cell's area is taken from
/// its four corner points (two triangles, robust at the seams where the tangents blow up
/// for eps < 1), a cell is drawn with probability proportional to its area and a point is
/// drawn uniformly in its parameter rectangle. Only the eta range on which the
/// parametrisation lies on the implicit surface is used (see [`Shape::eta_range`]).
pub fn sample_surface(shape: &Shape, pose: &Pose, count: usize, rng: &mut SeededRng) -> Vec<DVec3> {
    sample_surface_on_grid(shape, pose, count, GRID, rng)
}

/// [`sample_surface`] with a `grid` x `grid` area table: 64 is a sixteenth of the work,
/// near-uniform enough for checks that count samples per region rather than place them.
pub fn sample_surface_on_grid(
    shape: &Shape,
    pose: &Pose,
    count: usize,
    grid: usize,
    rng: &mut SeededRng,
) -> Vec<DVec3> {
    use std::f64::consts::PI;
    let grid = grid.max(2);
    let eta_max = shape.eta_range();
    let d_eta = 2.0 * eta_max / grid as f64;
    let d_omega = 2.0 * PI / grid as f64;
    // each corner once: (grid + 1)^2 surface points
    let corners: Vec<DVec3> = (0..=grid)
        .flat_map(|i| {
            (0..=grid).map(move |j| {
                shape.surface_point(-eta_max + i as f64 * d_eta, -PI + j as f64 * d_omega)
            })
        })
        .collect();
    let corner = |i: usize, j: usize| corners[i * (grid + 1) + j];
    let mut cumulative = Vec::with_capacity(grid * grid);
    let mut total = 0.0;
    for i in 0..grid {
        for j in 0..grid {
            let (p00, p10, p01, p11) = (
                corner(i, j),
                corner(i + 1, j),
                corner(i, j + 1),
                corner(i + 1, j + 1),
            );
            let area = 0.5 * (p11 - p00).cross(p01 - p10).length();
            total += area;
            cumulative.push(total);
        }
    }
    (0..count)
        .map(|_| {
            let target = rng.random::<f64>() * total;
            let cell = cumulative
                .partition_point(|&c| c < target)
                .min(grid * grid - 1);
            let (i, j) = (cell / grid, cell % grid);
            let eta = -eta_max + (i as f64 + rng.random::<f64>()) * d_eta;
            let omega = -PI + (j as f64 + rng.random::<f64>()) * d_omega;
            pose.to_world(shape.surface_point(eta, omega))
        })
        .collect()
}

/// Adds isotropic Gaussian noise with standard deviation `sigma` (world units).
pub fn add_noise(points: &mut [DVec3], sigma: f64, rng: &mut SeededRng) {
    if sigma <= 0.0 {
        return;
    }
    let normal = Normal::new(0.0, sigma).expect("sigma is finite and positive");
    for p in points {
        *p += DVec3::new(normal.sample(rng), normal.sample(rng), normal.sample(rng));
    }
}

/// Appends uniform outliers inside the object's oriented bounding box inflated by 10%,
/// so that they make up `fraction` of the returned cloud (fraction in [0, 1)).
pub fn add_outliers(
    points: &mut Vec<DVec3>,
    shape: &Shape,
    pose: &Pose,
    fraction: f64,
    rng: &mut SeededRng,
) {
    if fraction <= 0.0 || points.is_empty() {
        return;
    }
    let fraction = fraction.min(0.95);
    let extra = ((points.len() as f64) * fraction / (1.0 - fraction)).round() as usize;
    let half = shape.half_extents() * 1.1;
    for _ in 0..extra {
        let canonical = DVec3::new(
            rng.random_range(-half.x..=half.x),
            rng.random_range(-half.y..=half.y),
            rng.random_range(-half.z..=half.z),
        );
        points.push(pose.to_world(canonical));
    }
}

/// Random subset of `count` points (order kept), or all when there are fewer.
pub fn subsample<T: Copy>(points: &[T], count: usize, rng: &mut SeededRng) -> Vec<T> {
    if points.len() <= count {
        return points.to_vec();
    }
    let mut idx = rand::seq::index::sample(rng, points.len(), count).into_vec();
    idx.sort_unstable();
    idx.into_iter().map(|i| points[i]).collect()
}

//! The dominant plane of a point set: RANSAC on seeded three-point samples, its inliers
//! refined by a least-squares fit (the normal is the eigenvector of the inliers' scatter
//! with the least eigenvalue), then recounted. A few dozen lines against the crates that
//! offer RANSAC (`arrsac`, `sample-consensus`), which would still need this model and
//! estimator written for them.

use crate::model::Plane;
use glam::DVec3;
use rand::Rng;

/// RANSAC samples tried.
pub const ITERATIONS: usize = 200;
/// The most points each sample's plane is scored on (an even stride through the points;
/// the best is then refined and counted on all of them). The share of a plane's points
/// among 4000 is known to about 1%, which tells the dominant plane from the next, and a
/// depth frame's 300,000 points cost each sample 75 times as much.
pub const SCORED_POINTS: usize = 4000;

#[derive(Clone, Debug)]
pub struct PlaneFit {
    pub plane: Plane,
    /// per point: within the tolerance of the plane
    pub inliers: Vec<bool>,
    pub inlier_count: usize,
}

/// The plane with the most points within `tolerance`, or None for fewer than 3 points.
pub fn fit_plane(points: &[DVec3], tolerance: f64, seed: u64) -> Option<PlaneFit> {
    if points.len() < 3 {
        return None;
    }
    let mut rng = crate::synth::rng(seed);
    let mut best: Option<(usize, Plane)> = None;
    let stride = points.len().div_ceil(SCORED_POINTS);
    let scored: Vec<DVec3> = points.iter().step_by(stride).copied().collect();
    for _ in 0..ITERATIONS {
        let [a, b, c] = [0; 3].map(|_| points[rng.random_range(0..points.len())]);
        let normal = (b - a).cross(c - a);
        if normal.length_squared() < 1e-24 {
            continue;
        }
        let plane = Plane::through(a, normal);
        let count = count_within(&scored, &plane, tolerance);
        if best.as_ref().is_none_or(|(n, _)| count > *n) {
            best = Some((count, plane));
        }
    }
    let (_, plane) = best?;
    let refined = refine(points, &plane, tolerance).unwrap_or(plane);
    let inliers: Vec<bool> = points
        .iter()
        .map(|&p| refined.signed_distance(p).abs() <= tolerance)
        .collect();
    let inlier_count = inliers.iter().filter(|&&b| b).count();
    Some(PlaneFit {
        plane: refined,
        inliers,
        inlier_count,
    })
}

fn count_within(points: &[DVec3], plane: &Plane, tolerance: f64) -> usize {
    points
        .iter()
        .filter(|&&p| plane.signed_distance(p).abs() <= tolerance)
        .count()
}

/// The least-squares plane of the points within `tolerance` of `plane`.
fn refine(points: &[DVec3], plane: &Plane, tolerance: f64) -> Option<Plane> {
    let inliers: Vec<DVec3> = points
        .iter()
        .copied()
        .filter(|&p| plane.signed_distance(p).abs() <= tolerance)
        .collect();
    if inliers.len() < 3 {
        return None;
    }
    let centroid = inliers.iter().sum::<DVec3>() / inliers.len() as f64;
    let mut scatter = nalgebra::Matrix3::<f64>::zeros();
    for p in &inliers {
        let d = nalgebra::Vector3::new(p.x - centroid.x, p.y - centroid.y, p.z - centroid.z);
        scatter += d * d.transpose();
    }
    let eigen = nalgebra::SymmetricEigen::new(scatter);
    let (i, _) = eigen
        .eigenvalues
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))?;
    let n = eigen.eigenvectors.column(i);
    let mut normal = DVec3::new(n[0], n[1], n[2]);
    // keep the side the RANSAC plane's normal pointed to
    if normal.dot(plane.normal()) < 0.0 {
        normal = -normal;
    }
    Some(Plane::through(centroid, normal))
}

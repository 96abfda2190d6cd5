//! The cloud's own scatter about a smooth surface, measured without any model: a
//! reference that tells a fit left far from its points (a wrong basin) from a cloud
//! that is simply noisy. Not in the paper.
//!
//! Around each of a few hundred points spread over the cloud, a quadric height field
//! h = a·u² + b·uv + c·v² + d·u + e·v + f is fitted by least squares to its
//! [`NEIGHBOURS`] nearest neighbours, in the frame of their principal axes (h along the
//! least-variance one). The RMS of its residuals (over the neighbours less the six
//! parameters) estimates the noise sigma there, the surface's curvature taken out to
//! second order; the median over the points is the cloud's scatter, robust to
//! neighbourhoods that hold outliers or straddle an edge.
//!
//! On the suite's single views (four seed sets, 360 cases) it reads the true noise
//! sigma to within about 10% at 1% and 2% noise, and 1e-4 to 2e-3 of the size on the
//! noise-free clouds (the third-order terms of the surface over a neighbourhood).
//! Full clouds, 2000 points over a whole ring, read more: 20 neighbours span much of a
//! thin section, so its curvature counts as noise. On set 1190000 (camera frame; median
//! over each category, of the true sigma or of the size where noise-free): views 0.97 at
//! 1% noise, 0.85 at 2%, 2.4e-4 noise-free; full clouds 1.52, 1.08 and 5.4e-3. Fewer
//! neighbours trade one error for the other (12: full clouds 1.11, 0.90, 1.0e-3; views
//! 0.90, 0.71, 8e-5: the nearest neighbours in 3D lie on the same side of the noise); a
//! cubic height field, or neighbours taken by their distance along the surface, change
//! neither much.

use glam::DVec3;
use nalgebra::{Matrix3, Matrix6, Vector3, Vector6};
use rayon::prelude::*;

/// Neighbours per local quadric: enough above its six parameters for a stable RMS,
/// few enough that the neighbourhood stays nearly quadric.
pub const NEIGHBOURS: usize = 20;
/// The most points the neighbours are looked up among (an even stride over a larger
/// cloud), which bounds the brute-force search.
pub const MAX_POINTS: usize = 4000;
/// The most neighbourhoods whose scatter is taken.
pub const MAX_CENTRES: usize = 100;

/// The median local scatter of the cloud (in its units), or None for a cloud too small
/// to have neighbourhoods of [`NEIGHBOURS`] points.
pub fn local_scatter(cloud: &[DVec3]) -> Option<f64> {
    if cloud.len() <= NEIGHBOURS + 1 {
        return None;
    }
    let points: Vec<DVec3> = cloud
        .iter()
        .step_by(cloud.len().div_ceil(MAX_POINTS))
        .copied()
        .collect();
    let centres: Vec<DVec3> = points
        .iter()
        .step_by(points.len().div_ceil(MAX_CENTRES))
        .copied()
        .collect();
    let mut scatter: Vec<f64> = centres
        .par_iter()
        .map_init(Vec::new, |dist: &mut Vec<(f64, usize)>, p| {
            let neighbours: Vec<DVec3> = super::starts::nearest(&points, *p, NEIGHBOURS, dist)
                .iter()
                .map(|&(_, j)| points[j])
                .collect();
            quadric_residual_rms(&neighbours)
        })
        .flatten()
        .collect();
    if scatter.is_empty() {
        return None;
    }
    let middle = scatter.len() / 2;
    let (_, median, _) = scatter.select_nth_unstable_by(middle, f64::total_cmp);
    Some(*median)
}

/// The RMS residual of the quadric height field fitted to a neighbourhood, with the six
/// parameters' degrees of freedom taken out; None where the fit is degenerate.
fn quadric_residual_rms(neighbours: &[DVec3]) -> Option<f64> {
    let n = neighbours.len() as f64;
    let mean = neighbours.iter().copied().sum::<DVec3>() / n;
    let mut cov = Matrix3::<f64>::zeros();
    for q in neighbours {
        let d = *q - mean;
        let v = Vector3::new(d.x, d.y, d.z);
        cov += v * v.transpose();
    }
    let eig = cov.symmetric_eigen();
    let mut order = [0, 1, 2];
    order.sort_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]));
    let axis = |i: usize| {
        let c = eig.eigenvectors.column(order[i]);
        DVec3::new(c[0], c[1], c[2])
    };
    let (normal, u, v) = (axis(0), axis(2), axis(1));
    // in units of the neighbourhood's radius, so that the normal equations of the
    // 6-parameter least squares (solved by Cholesky) stay well conditioned
    let radius = neighbours
        .iter()
        .map(|q| (*q - mean).length())
        .fold(0.0, f64::max);
    if radius <= 0.0 {
        return None;
    }
    let (mut ata, mut atb) = (Matrix6::<f64>::zeros(), Vector6::<f64>::zeros());
    let rows: Vec<(Vector6<f64>, f64)> = neighbours
        .iter()
        .map(|q| {
            let d = (*q - mean) / radius;
            let (x, y) = (d.dot(u), d.dot(v));
            (Vector6::new(x * x, x * y, y * y, x, y, 1.0), d.dot(normal))
        })
        .collect();
    for (row, h) in &rows {
        ata += row * row.transpose();
        atb += row * *h;
    }
    let coefficients = ata.cholesky()?.solve(&atb);
    let squares: f64 = rows
        .iter()
        .map(|(row, h)| (row.dot(&coefficients) - h).powi(2))
        .sum();
    let dof = neighbours.len().checked_sub(6).filter(|&d| d > 0)? as f64;
    let rms = radius * (squares / dof).sqrt();
    rms.is_finite().then_some(rms)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{Pose, Shape};
    use crate::synth;

    #[test]
    fn the_scatter_reads_the_noise_of_a_curved_surface() {
        let shape = Shape::new(0.06, 0.05, 0.02, 1.6, 0.8, 1.2);
        let pose = Pose::default();
        let mut rng = synth::rng(7);
        let clean = synth::sample_surface(&shape, &pose, 2000, &mut rng);
        let size = shape.size();
        let floor = local_scatter(&clean).unwrap();
        assert!(
            floor < 2e-3 * size,
            "noise-free scatter {floor} of size {size}"
        );
        for fraction in [0.005, 0.01, 0.02] {
            let mut noisy = clean.clone();
            synth::add_noise(&mut noisy, fraction * size, &mut rng);
            let read = local_scatter(&noisy).unwrap() / (fraction * size);
            assert!(
                (0.8..1.25).contains(&read),
                "noise {fraction}: read {read} of it"
            );
        }
    }

    #[test]
    fn a_cloud_too_small_for_a_neighbourhood_has_no_scatter() {
        let points: Vec<DVec3> = (0..NEIGHBOURS).map(|i| DVec3::splat(i as f64)).collect();
        assert_eq!(local_scatter(&points), None);
    }
}

//! Is there an object in the cloud at all? A cloud whose points lie on one plane within
//! their own noise is a bare surface (a table in a detector's box) or a single face seen
//! head-on: no fit can tell its depth, and a fit would hand the robot a made-up ring.
//! Such a cloud is refused, unless its points enclose a hole: a flat washer or a ring
//! seen face-on is planar too, and its outline and hole are worth fitting.
//!
//! Planar means: the plane that holds the most points within [`TOLERANCE_SCATTERS`] of
//! the cloud's own scatter ([`scatter::local_scatter`], the noise measured about local
//! quadrics, so in the cloud's units and whatever its sensor) holds at least
//! [`PLANAR_SHARE`] of them. A curved or many-faced object leaves most of its points
//! many noise widths off any plane: a can seen from the side is off by a good part of
//! its radius.
//!
//! One plane within the scatter is not yet a bare surface: a whole thin washer (both
//! faces sampled, a full cloud) lies within three scatters of its middle plane too, since
//! the local quadrics straddle its thickness and read it as noise. One noisy layer puts
//! about two-thirds of its points within one scatter of the plane (a Gaussian's share
//! within a sigma); two layers, the faces either side of the middle, far fewer. Fewer
//! than [`ONE_LAYER_SHARE`] of them there is depth, and the cloud is fitted.
//!
//! The hole: the plane's points projected onto it and binned in square cells
//! [`CELL_SPACINGS`] times the points' typical spacing (so a cell of the surface holds
//! many points); empty cells that the empty border cannot reach, edge to edge, are
//! enclosed. At least [`MIN_HOLE_CELLS`] of them make a hole.

use super::{FitError, check_cloud, scatter, starts};
use crate::scene::plane::fit_plane;
use glam::{DVec2, DVec3};

/// Points within this many scatters of the plane are on it (three sigmas of Gaussian
/// noise: 99.7% of a noisy plane's points).
pub const TOLERANCE_SCATTERS: f64 = 3.0;
/// A cloud with at least this share of its points on one plane is planar: room for a
/// few percent of outliers and flying pixels, while a box seen almost head-on with a
/// sliver of a second face (more than this share) is still fitted.
pub const PLANAR_SHARE: f64 = 0.95;
/// The least share of the plane's points within one scatter of it that one layer
/// shows: a Gaussian puts 68% within a sigma, and the scatter reads 0.7-1 of the true
/// sigma (`scatter`'s docs), so 52-68%; two faces either side of a thin object's middle
/// plane put few there. Set from that before measuring; measured
/// (`docs/fit.md`, stage 0): noisy patches of table 0.66-0.68, the suite's single
/// views found planar 0.50-0.64, whole thin washers 0.11-0.55.
pub const ONE_LAYER_SHARE: f64 = 0.5;
/// A cell is this many typical point spacings across: about eight points to a cell of
/// randomly strewn points (whose median nearest-neighbour distance is half their mean
/// spacing), so that a cell of surface goes empty by chance about once in 3000; some
/// 36 to a cell of a depth sensor's grid of pixels.
pub const CELL_SPACINGS: f64 = 6.0;
/// Enclosed empty cells that make a hole (single cells go empty by chance).
pub const MIN_HOLE_CELLS: usize = 3;
/// The most points looked at (an even stride over a larger cloud).
const MAX_POINTS: usize = 4000;
/// Points whose nearest neighbour gives the typical spacing.
const SPACING_SAMPLES: usize = 200;

/// What the planarity screen found.
#[derive(Clone, Debug, PartialEq)]
pub enum Planarity {
    /// the points have depth off any plane: an object to fit
    Solid,
    /// on one plane, around an enclosed hole: a flat ring seen face-on
    FlatRing { share: f64 },
    /// on one plane, no hole: nothing to fit
    BarePlane { share: f64, tolerance: f64 },
}

/// The screen of one cloud (any units). `seed` makes the plane's RANSAC repeatable.
pub fn planarity(cloud: &[DVec3], seed: u64) -> Planarity {
    let points: Vec<DVec3> = cloud
        .iter()
        .step_by(cloud.len().div_ceil(MAX_POINTS).max(1))
        .copied()
        .collect();
    let Some(noise) = scatter::local_scatter(&points) else {
        return Planarity::Solid;
    };
    let tolerance = TOLERANCE_SCATTERS * noise;
    let Some(plane) = fit_plane(&points, tolerance, seed) else {
        return Planarity::Solid;
    };
    let share = plane.inlier_count as f64 / points.len() as f64;
    if share < PLANAR_SHARE {
        return Planarity::Solid;
    }
    let on_plane: Vec<DVec3> = points
        .iter()
        .zip(&plane.inliers)
        .filter(|(_, inlier)| **inlier)
        .map(|(p, _)| *p)
        .collect();
    let within_one_scatter = on_plane
        .iter()
        .filter(|p| plane.plane.signed_distance(**p).abs() <= noise)
        .count();
    if (within_one_scatter as f64) < ONE_LAYER_SHARE * on_plane.len() as f64 {
        return Planarity::Solid;
    }
    let normal = plane.plane.normal();
    let u = normal.any_orthonormal_vector();
    let v = normal.cross(u);
    let flat: Vec<DVec2> = on_plane
        .iter()
        .map(|p| DVec2::new(p.dot(u), p.dot(v)))
        .collect();
    if enclosed_empty_cells(&flat) >= MIN_HOLE_CELLS {
        Planarity::FlatRing { share }
    } else {
        Planarity::BarePlane { share, tolerance }
    }
}

/// The typical spacing of 2-D points: the median distance to the nearest neighbour of
/// an even sample of them.
fn typical_spacing(points: &[DVec2]) -> Option<f64> {
    let lifted: Vec<DVec3> = points.iter().map(|p| p.extend(0.0)).collect();
    let step = points.len().div_ceil(SPACING_SAMPLES).max(1);
    let mut buffer = Vec::new();
    let mut nearest: Vec<f64> = lifted
        .iter()
        .step_by(step)
        .filter(|_| lifted.len() > 1)
        // (the point itself is the nearest, at 0; its neighbour the next)
        .map(|p| starts::nearest(&lifted, *p, 1, &mut buffer)[1].0)
        .collect();
    if nearest.is_empty() {
        return None;
    }
    let middle = nearest.len() / 2;
    let (_, median, _) = nearest.select_nth_unstable_by(middle, f64::total_cmp);
    Some(median.sqrt())
}

/// The empty cells of the points' occupancy grid that the empty border cannot reach.
fn enclosed_empty_cells(points: &[DVec2]) -> usize {
    let Some(spacing) = typical_spacing(points).filter(|s| *s > 0.0) else {
        return 0;
    };
    let cell = CELL_SPACINGS * spacing;
    let (lo, hi) = points.iter().fold(
        (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    // a one-cell empty margin all round, so the border's empty cells are connected
    let dims = ((hi - lo) / cell).floor() + DVec2::splat(3.0);
    let (w, h) = (dims.x as usize, dims.y as usize);
    if w * h > 1_000_000 {
        return 0; // points too sparse for their extent to say anything
    }
    let mut occupied = vec![false; w * h];
    for p in points {
        let c = ((*p - lo) / cell).floor() + DVec2::ONE;
        occupied[c.y as usize * w + c.x as usize] = true;
    }
    // flood the empty cells from a corner, edge-connected
    let mut reached = vec![false; w * h];
    let mut stack = vec![0usize];
    reached[0] = true;
    while let Some(i) = stack.pop() {
        let (x, y) = (i % w, i / w);
        let neighbours = [
            (x > 0).then(|| i - 1),
            (x + 1 < w).then(|| i + 1),
            (y > 0).then(|| i - w),
            (y + 1 < h).then(|| i + w),
        ];
        for j in neighbours.into_iter().flatten() {
            if !occupied[j] && !reached[j] {
                reached[j] = true;
                stack.push(j);
            }
        }
    }
    (0..w * h).filter(|&i| !occupied[i] && !reached[i]).count()
}

/// [`FitError::NoObject`] for a bare plane. A flat ring seen face-on is fitted: where
/// its thickness is lost in the noise, its standard errors say so
/// ([`uncertainty`]).
pub(super) fn screen_for_an_object(points: &[DVec3], seed: u64) -> Result<(), FitError> {
    // `check_cloud`'s refusals come first, with their own errors
    check_cloud(points)?;
    match planarity(points, seed) {
        Planarity::Solid | Planarity::FlatRing { .. } => Ok(()),
        Planarity::BarePlane { share, tolerance } => Err(FitError::NoObject(format!(
            "{:.0}% of the points lie on one plane (within {tolerance:.1e} in the cloud's units, three times their \
             own scatter) and enclose no hole: a bare surface such as a table, or one face \
             seen head-on, whose depth no fit can tell",
            100.0 * share
        ))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{Pose, Shape};
    use crate::synth;
    use glam::DQuat;
    use rand::Rng;
    use rand_distr::{Distribution, Normal};

    /// A noisy disc or annulus of radius 0.1 on a tilted plane, noise along z.
    fn flat_patch(inner: f64, noise: f64, seed: u64) -> Vec<DVec3> {
        let mut rng = synth::rng(seed);
        let tilt = DQuat::from_rotation_x(0.4);
        let gauss = Normal::new(0.0, noise).unwrap();
        let mut points = Vec::new();
        while points.len() < 1500 {
            let p = DVec2::new(rng.random_range(-0.1..0.1), rng.random_range(-0.1..0.1));
            if p.length() > 0.1 || p.length() < inner {
                continue;
            }
            let z = 0.8 + gauss.sample(&mut rng);
            points.push(tilt * DVec3::new(p.x, p.y, 0.0) + DVec3::new(0.0, 0.0, z));
        }
        points
    }

    #[test]
    fn a_noisy_patch_of_table_is_a_bare_plane() {
        for seed in 0..3 {
            let verdict = planarity(&flat_patch(0.0, 0.002, seed), seed);
            assert!(
                matches!(verdict, Planarity::BarePlane { .. }),
                "seed {seed}: {verdict:?}"
            );
        }
    }

    #[test]
    fn a_washer_seen_face_on_keeps_its_hole() {
        for seed in 0..3 {
            let verdict = planarity(&flat_patch(0.04, 0.001, seed), seed);
            assert!(
                matches!(verdict, Planarity::FlatRing { .. }),
                "seed {seed}: {verdict:?}"
            );
        }
    }

    /// A whole thin washer (a full cloud: both faces, 1% noise and none) lies within
    /// three of its scatters of its middle plane, its hole too small for the occupancy
    /// grid's cells; its two faces are depth.
    #[test]
    fn a_whole_thin_washer_is_two_layers_not_a_plane() {
        let washer = Shape::new(0.07, 0.07, 0.01, 1.25, 1.0, 0.5);
        for (seed, noise) in [(0, 0.0), (1, 0.01)] {
            let mut rng = synth::rng(seed);
            let mut points = synth::sample_surface(&washer, &Pose::default(), 2000, &mut rng);
            synth::add_noise(&mut points, noise * washer.size(), &mut rng);
            let verdict = planarity(&points, seed);
            assert_eq!(verdict, Planarity::Solid, "noise {noise}");
        }
    }

    #[test]
    fn objects_seen_from_one_side_are_solid() {
        // a can's side and a ring seen obliquely, 1% noise: curved, not planar
        let can = Shape::new(0.033, 0.033, 0.06, 0.0, 0.1, 1.0);
        let ring = Shape::new(0.01, 0.01, 0.005, 3.0, 1.0, 1.0);
        for (k, shape) in [can, ring].iter().enumerate() {
            let mut rng = synth::rng(k as u64);
            // the half facing a sensor off to one side and above
            let towards = DVec3::new(0.8, 0.2, 0.5).normalize();
            let mut points: Vec<DVec3> =
                synth::sample_surface(shape, &Pose::default(), 3000, &mut rng)
                    .into_iter()
                    .filter(|p| p.dot(towards) > 0.0)
                    .collect();
            synth::add_noise(&mut points, 0.01 * shape.size(), &mut rng);
            assert_eq!(planarity(&points, 0), Planarity::Solid, "shape {k}");
        }
    }
}

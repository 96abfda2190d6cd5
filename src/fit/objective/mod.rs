//! The fit's objective: the likelihood of the cloud under a model of how a sensor makes
//! it. Points lie on the surface, blurred by isotropic Gaussian noise of an unknown sigma,
//! plus a share of outliers spread over the cloud's box:
//!
//!   p(x) = (1 - w) · W(x) / A · ∫_S N(x; s, sigma² I) dA(s) + w / V
//!
//! Without a viewpoint W = 1 and A is the surface's area. Seen from a viewpoint, the
//! sensor's points fall at cos(incidence) / range² per unit area over the surface it
//! sees: inside the integral each surface element counts with its own incidence and
//! visibility, W(x) = 1 / range(x)² (relative to a reference range), and A is the
//! integral of the same density over the surface, so a candidate that shows the sensor
//! surface without points pays for it in A.
//!
//! Why a likelihood: any least-squares distance fit is biased once the noise is a
//! sizeable part of the thinnest half-axis (noise rounds a square section, fills a pinched
//! one, and spreads points further outside a thin section than inside). The likelihood
//! models the blur instead of measuring through it, so its maximum sits at the true
//! surface whatever the noise.
//!
//! The integral is a tensor-product sum over the surface's own parameters (section nodes
//! times sweep samples, [`tables`]), and each point visits only the window of it within
//! [`CUTOFF`] sigmas: its sweep sample from its polar angle, its section nodes from their
//! heights and radii. No surface grid is built per evaluation but the normaliser's coarse
//! one ([`normaliser`]).
//!
//! The per-point sums run in the f64 loop of `Window::sums`, or with a device in the
//! data ([`Data::device`], the GPU evaluator's) in its WGSL kernel (`device.rs`), f32 term
//! for term; the tests hold the two together.
//!
//! Parameters: shape a1 a2 a3 a4 eps1 eps2, translation, a rotation vector applied on the
//! left of the reference rotation (world frame), ln sigma. The gradient is analytic (A's
//! too, [`normaliser`]); the Hessian is the BHHH outer product of the points' scores.

mod device;
pub mod normaliser;
mod refine;
pub mod tables;

pub use refine::{Limits, Refined, STOP_DECREASE, refine, refine_on, value, value_on};

use crate::eval::{Candidate, GpuObjective};
use crate::fit::sight::Sight;
use crate::model::{Pose, Shape};
use glam::{DQuat, DVec3};
use normaliser::Normaliser;
use rayon::prelude::*;
use std::f64::consts::TAU;
use tables::{Grid, SectionTable, SweepTable};

/// The model's parameters (see the module docs) as the likelihood's solver takes them.
pub use crate::solve::likelihood::{Matrix, PARAMETERS, Vector};

/// Points meet the surface within this many sigmas; the kernel is shifted down by its
/// value there so that it reaches zero continuously.
pub const CUTOFF: f64 = 4.0;
/// Points per work item of an evaluation.
const CHUNK: usize = 64;

/// The sensor seen from the model: where it was, and each point's range weight.
#[derive(Clone, Debug)]
pub struct Sensor {
    /// where it stood, and the edges of its frame where known (past them it saw nothing)
    pub sight: Sight,
    /// per point: reference / range²
    pub point_weights: Vec<f64>,
    /// the squared range the weights are relative to (a common factor: it cancels)
    pub reference: f64,
}

impl Sensor {
    /// The sensor at `sight` (normalised frame) for `points`.
    pub fn new(points: &[DVec3], sight: Sight) -> Self {
        let viewpoint = sight.viewpoint;
        let centre = points.iter().copied().sum::<DVec3>() / points.len().max(1) as f64;
        let reference = (centre - viewpoint).length_squared().max(1e-12);
        let point_weights = points
            .iter()
            .map(|p| reference / (*p - viewpoint).length_squared().max(1e-12))
            .collect();
        Self {
            sight,
            point_weights,
            reference,
        }
    }
}

/// The data of one objective: the points, the outlier model and the sensor.
pub struct Data<'a> {
    pub points: &'a [DVec3],
    pub outlier_weight: f64,
    /// w / V, the outliers' density
    pub outlier_density: f64,
    pub sensor: Option<&'a Sensor>,
    /// where the per-point sums run: the GPU's kernel, or (none) the f64 loop here
    pub device: Option<&'a GpuObjective>,
}

/// The parameter vector of a candidate and sigma (the turn zero: the candidate's rotation
/// is the reference).
pub fn parameters(candidate: &Candidate, sigma: f64) -> Vector {
    let s = candidate.shape;
    let t = candidate.pose.translation;
    Vector::from_column_slice(&[
        s.a1,
        s.a2,
        s.a3,
        s.a4,
        s.eps1,
        s.eps2,
        t.x,
        t.y,
        t.z,
        0.0,
        0.0,
        0.0,
        sigma.ln(),
    ])
}

/// The objective at one reference rotation and quadrature grid (both held for a run of
/// evaluations so the line search sees one function).
pub struct Objective<'a> {
    pub data: &'a Data<'a>,
    pub rotation0: DQuat,
    pub grid: Grid,
    /// the normaliser's grid ([`normaliser::FINE`] or [`normaliser::COARSE`])
    pub area_grid: (usize, usize),
    /// with a sensor: which of the normaliser's cells it sees, held ([`Objective::hold`])
    pub visible: Option<Vec<bool>>,
}

/// One point's sums over its window: the kernel sum and its partials.
#[derive(Default)]
struct PointSums {
    sum: f64,
    /// d sum / d shape via the surface positions, weights and sigma (ln sigma last)
    shape: [f64; 6],
    ln_sigma: f64,
    /// d sum / d q (canonical point) and d sum / d v (canonical sight line)
    by_point: DVec3,
    by_sight: DVec3,
}

impl<'a> Objective<'a> {
    pub fn new(data: &'a Data<'a>, candidate: &Candidate, sigma: f64) -> Self {
        Self {
            data,
            rotation0: candidate.pose.rotation,
            grid: Grid::for_shape(&candidate.shape, sigma),
            area_grid: normaliser::FINE,
            visible: None,
        }
    }

    /// Finds which cells the sensor sees at `x` and holds it for the evaluations after.
    pub fn hold(&mut self, x: &Vector) {
        self.visible = None;
        if let Some(sensor) = self.data.sensor {
            let n = normaliser::normaliser(
                &Self::shape(x),
                self.rotation(x),
                DVec3::new(x[6], x[7], x[8]),
                Some((sensor.sight, sensor.reference)),
                self.area_grid,
                None,
                false,
            );
            self.visible = n.visible;
        }
    }

    pub fn rotation(&self, x: &Vector) -> DQuat {
        DQuat::from_scaled_axis(DVec3::new(x[9], x[10], x[11])) * self.rotation0
    }

    pub fn shape(x: &Vector) -> Shape {
        Shape::new(x[0], x[1], x[2], x[3], x[4], x[5])
    }

    pub fn candidate(&self, x: &Vector) -> Candidate {
        Candidate {
            shape: Self::shape(x),
            pose: Pose::new(self.rotation(x).normalize(), DVec3::new(x[6], x[7], x[8])),
        }
    }

    /// The mean negative log-likelihood per point; with `with_gradient` also its
    /// gradient and the BHHH approximation of its Hessian.
    pub fn evaluate(&self, x: &Vector, with_gradient: bool) -> (f64, Vector, Matrix) {
        let shape = Self::shape(x);
        let sigma = x[12].exp();
        let rotation = self.rotation(x);
        let translation = DVec3::new(x[6], x[7], x[8]);
        let sensor = self.data.sensor;
        let normaliser = normaliser::normaliser(
            &shape,
            rotation,
            translation,
            sensor.map(|s| (s.sight, s.reference)),
            self.area_grid,
            self.visible.as_deref(),
            with_gradient,
        );
        let window = Window::new(&self.grid, &shape, sigma, &normaliser);
        let inverse = rotation.inverse();
        let kernel_scale = (std::f64::consts::TAU * sigma * sigma).powf(-1.5);
        let inlier = (1.0 - self.data.outlier_weight) * kernel_scale / normaliser.area;
        if let Some(device) = self.data.device {
            let pose = Pose::new(rotation, translation);
            // (a device that fails leaves the evaluation to the loop below)
            if let Some(sums) =
                device::sums(device, self.data, &window, &pose, inlier, with_gradient)
            {
                return sums;
            }
        }
        let point_term = |i: usize, x_world: DVec3| -> (f64, Vector) {
            let d = x_world - translation;
            let q = inverse * d;
            let sight = sensor.map(|s| inverse * (x_world - s.sight.viewpoint));
            let sums = window.sums(q, sight, with_gradient);
            let weight = sensor.map_or(1.0, |s| s.point_weights[i]);
            let density = inlier * weight * sums.sum + self.data.outlier_density;
            let mut grad = Vector::zeros();
            if with_gradient {
                let f = inlier * weight / density;
                grad.fixed_rows_mut::<6>(0).copy_from_slice(&sums.shape);
                let by_point = rotation * sums.by_point;
                grad[6] = -by_point.x;
                grad[7] = -by_point.y;
                grad[8] = -by_point.z;
                let mut turn = by_point.cross(d);
                if let Some(s) = sensor {
                    turn += (rotation * sums.by_sight).cross(x_world - s.sight.viewpoint);
                }
                grad[9] = turn.x;
                grad[10] = turn.y;
                grad[11] = turn.z;
                // (2 pi sigma²)^-3/2
                grad[12] = sums.ln_sigma - 3.0 * sums.sum;
                grad *= f;
                let share = f * sums.sum;
                for k in 0..12 {
                    grad[k] -= share * normaliser.d_log_area[k];
                }
            }
            (density.ln(), grad)
        };
        let n = self.data.points.len() as f64;
        let zero = || (0.0, Vector::zeros(), Matrix::zeros());
        // fixed chunks summed in order: the same sums whatever the threads' schedule, so a
        // seed always gives the same fit
        let partials: Vec<(f64, Vector, Matrix)> = self
            .data
            .points
            .par_chunks(CHUNK)
            .enumerate()
            .map(|(c, chunk)| {
                let mut acc = zero();
                for (j, p) in chunk.iter().enumerate() {
                    let (l, g) = point_term(c * CHUNK + j, *p);
                    acc.0 += l;
                    if with_gradient {
                        acc.1 += g;
                        acc.2 += g * g.transpose();
                    }
                }
                acc
            })
            .collect();
        let (log_likelihood, gradient, outer) = partials
            .into_iter()
            .fold(zero(), |a, b| (a.0 + b.0, a.1 + b.1, a.2 + b.2));
        (-log_likelihood / n, -gradient / n, outer / n)
    }
}

/// The quadrature at one parameter vector: both tables, the visibility of each node and
/// sample, and the kernel's constants.
struct Window<'a> {
    shape: Shape,
    section: SectionTable,
    /// per section node: its ring of the normaliser's grid
    rings: Vec<usize>,
    /// per sweep sample, what the per-point sums read of it, side by side
    samples: Vec<SweepSample>,
    /// per sweep sample: its polar angle in the canonical x-y plane (rising in [0, 2 pi))
    /// and its distance from the axis
    polar: Vec<f64>,
    radius: Vec<f64>,
    /// the section nodes by their height w (canonical z over a3), each with its index:
    /// a point meets only the nodes within the cutoff of its own height
    by_height: Vec<(f64, usize)>,
    normaliser: &'a Normaliser,
    /// 1 / a1 and 1 / a2, taken once for every surface element's partials
    inv_sizes: [f64; 2],
    var: f64,
    cut: f64,
    floor: f64,
}

/// A sweep sample as the per-point sums read it: its point C, tangent step D, C x D (its
/// point across its tangent step) and their eps2-derivatives, and its sector of the
/// normaliser's grid.
#[derive(Clone, Copy)]
struct SweepSample {
    point: [f64; 2],
    tangent: [f64; 2],
    cross: f64,
    d_point: [f64; 2],
    d_tangent: [f64; 2],
    d_cross: f64,
    sector: usize,
}

impl<'a> Window<'a> {
    fn new(grid: &Grid, shape: &Shape, sigma: f64, normaliser: &'a Normaliser) -> Self {
        let sweep = SweepTable::new(grid, shape.a1, shape.a2, shape.eps2);
        let samples: Vec<SweepSample> = (0..grid.sweep)
            .map(|m| {
                let [cx, cy] = sweep.point[m];
                let [dx, dy] = sweep.tangent[m];
                let [dcx, dcy] = sweep.d_point[m];
                let [ddx, ddy] = sweep.d_tangent[m];
                SweepSample {
                    point: [cx, cy],
                    tangent: [dx, dy],
                    cross: cx * dy - cy * dx,
                    d_point: [dcx, dcy],
                    d_tangent: [ddx, ddy],
                    d_cross: dcx * dy + cx * ddy - dcy * dx - cy * ddx,
                    sector: normaliser.sector_of(m as f64 * sweep.step),
                }
            })
            .collect();
        let polar = samples
            .iter()
            .map(|s| s.point[1].atan2(s.point[0]).rem_euclid(TAU))
            .collect();
        let radius = samples
            .iter()
            .map(|s| s.point[0].hypot(s.point[1]))
            .collect();
        let section = SectionTable::new(grid, shape.eps1);
        let mut by_height: Vec<(f64, usize)> = section
            .point
            .iter()
            .enumerate()
            .map(|(k, &[_, w])| (w, k))
            .collect();
        by_height.sort_by(|a, b| a.0.total_cmp(&b.0));
        Self {
            samples,
            by_height,
            shape: *shape,
            polar,
            radius,
            section,
            rings: grid
                .section
                .iter()
                .map(|&phi| normaliser.ring_of(phi))
                .collect(),
            normaliser,
            inv_sizes: [1.0 / shape.a1, 1.0 / shape.a2],
            var: sigma * sigma,
            cut: CUTOFF * sigma,
            floor: (-0.5 * CUTOFF * CUTOFF).exp(),
        }
    }

    /// The sweep samples whose polar angle (in the canonical x-y plane) lies in
    /// [from, to] (a span of at most a turn): the first and how many, wrapping round.
    fn sweep_range(&self, from: f64, to: f64) -> (usize, usize) {
        let count = self.polar.len();
        let first = |angle: f64| {
            let turns = angle.div_euclid(TAU);
            let index = self.polar.partition_point(|&p| p < angle - turns * TAU);
            index as isize + turns as isize * count as isize
        };
        let (lo, hi) = (first(from), first(to));
        let span = ((hi - lo).max(0) as usize).min(count);
        (lo.rem_euclid(count as isize) as usize, span)
    }

    /// n·v of each half of section node k's step against the sweep step (dx, dy), C x D
    /// = `cross`, seen along canonical `v` (negative where it faces the sensor), over
    /// lambda: n = (a3 tw dy, -a3 tw dx, -tc cross).
    fn half_facing(&self, k: usize, dx: f64, dy: f64, cross: f64, v: DVec3) -> [f64; 2] {
        let a3 = self.shape.a3;
        self.section.halves[k].map(|[tc, tw]| a3 * tw * (dy * v.x - dx * v.y) - tc * cross * v.z)
    }

    /// |n| of each half of section node k's step against the sweep step (dx, dy) with
    /// C x D = `cross` (the surface element's area over lambda).
    fn half_areas(&self, k: usize, dx: f64, dy: f64, cross: f64) -> [f64; 2] {
        let a3 = self.shape.a3;
        self.section.halves[k].map(|[tc, tw]| {
            (a3 * a3 * tw * tw * (dx * dx + dy * dy) + tc * tc * cross * cross).sqrt()
        })
    }

    /// Adds the partials of ln(element weight) in the shape (past ln lambda's) to
    /// `log_weight`, and the element's share of d sum / d sight (`term` its kernel term)
    /// to `by_sight`: section node k by sweep sample `s`, its area without a sight line,
    /// seen along `sight` its projected area (its halves' n·v, `facing`).
    fn add_log_weight_partials(
        &self,
        k: usize,
        s: &SweepSample,
        sight: Option<(DVec3, [f64; 2])>,
        term: f64,
        log_weight: &mut [f64; 6],
        by_sight: &mut DVec3,
    ) {
        let a3 = self.shape.a3;
        let [inv_a1, inv_a2] = self.inv_sizes;
        let [dx, dy] = s.tangent;
        let [ddx, ddy] = s.d_tangent;
        let (cross, d_cross) = (s.cross, s.d_cross);
        match sight {
            Some((v, facing)) => {
                // d ln sum_h (-facing_h) over the halves that face the sensor
                let total: f64 = facing.iter().map(|f| (-f).max(0.0)).sum();
                let per = 1.0 / -total;
                let turn = dy * v.x - dx * v.y;
                let (tc_v, by_tw) = (cross * v.z, DVec3::new(a3 * dy, -a3 * dx, 0.0));
                for h in 0..2 {
                    if facing[h] >= 0.0 {
                        continue;
                    }
                    let [tc, tw] = self.section.halves[k][h];
                    let [dtc, dtw] = self.section.d_halves[k][h];
                    // (D scales with a1 along x and a2 along y, the cross with a1·a2)
                    log_weight[0] += (a3 * tw * (-dx * v.y) - tc * tc_v) * inv_a1 * per;
                    log_weight[1] += (a3 * tw * (dy * v.x) - tc * tc_v) * inv_a2 * per;
                    log_weight[2] += tw * turn * per;
                    log_weight[4] += (a3 * dtw * turn - dtc * tc_v) * per;
                    log_weight[5] += (a3 * tw * (ddy * v.x - ddx * v.y) - tc * d_cross * v.z) * per;
                    *by_sight += (term * per) * DVec3::new(tw * by_tw.x, tw * by_tw.y, -tc * cross);
                }
            }
            None => {
                // d|n| = d|n|² / 2|n| for each half, over their sum
                let dd = dx * dx + dy * dy;
                let areas = self.half_areas(k, dx, dy, cross);
                let total = areas[0] + areas[1];
                for h in 0..2 {
                    if areas[h] == 0.0 {
                        continue;
                    }
                    let [tc, tw] = self.section.halves[k][h];
                    let [dtc, dtw] = self.section.d_halves[k][h];
                    let per = 1.0 / (areas[h] * total);
                    let (tw2, tc2x2) = (a3 * a3 * tw * tw, tc * tc * cross * cross);
                    log_weight[0] += (tw2 * dx * dx + tc2x2) * inv_a1 * per;
                    log_weight[1] += (tw2 * dy * dy + tc2x2) * inv_a2 * per;
                    log_weight[2] += a3 * tw * tw * dd * per;
                    log_weight[4] += (a3 * a3 * tw * dtw * dd + tc * dtc * cross * cross) * per;
                    log_weight[5] +=
                        (tw2 * (dx * ddx + dy * ddy) + tc * tc * cross * d_cross) * per;
                }
            }
        }
    }

    /// The kernel sum of canonical point `q` (seen along canonical `sight`, from the
    /// viewpoint to the point) over the surface within the cutoff, with its partials.
    fn sums(&self, q: DVec3, sight: Option<DVec3>, with_gradient: bool) -> PointSums {
        let Shape { a3, a4, .. } = self.shape;
        let [inv_a1, inv_a2] = self.inv_sizes;
        let mut out = PointSums::default();
        let count = self.samples.len();
        let rho = q.x.hypot(q.y);
        let cut2 = self.cut * self.cut;
        let inv_var = 1.0 / self.var;
        let exponent = -0.5 * inv_var;
        let inv_sight_length = sight.map_or(1.0, |v| 1.0 / v.length().max(1e-300));
        // every surface point within the cutoff lies, seen along the axis, in the disc of
        // that radius about the point: within asin(cut / rho) of its polar angle (all
        // round where the disc holds the axis), whatever its section node
        let (first, span) = if rho <= self.cut {
            (0, count)
        } else {
            let half = (self.cut / rho).asin();
            let polar = q.y.atan2(q.x).rem_euclid(TAU);
            self.sweep_range(polar - half, polar + half)
        };
        // the window's sweep samples, wrapped at the seam (two plain runs, no division
        // per step); their radii bound how near a node's sweep comes
        let window = [
            first..count.min(first + span),
            0..(first + span).saturating_sub(count),
        ];
        let (r_lo, r_hi) = window
            .clone()
            .into_iter()
            .flat_map(|run| &self.radius[run])
            .fold((f64::INFINITY, 0.0f64), |(lo, hi), &r| {
                (lo.min(r), hi.max(r))
            });
        let sectors = self.normaliser.grid.1;
        let height = |z: f64| self.by_height.partition_point(|&(w, _)| a3 * w < z);
        let nodes = height(q.z - self.cut)..height(q.z + self.cut);
        for &(_, k) in &self.by_height[nodes] {
            let [c, w] = self.section.point[k];
            let lambda = a4 + c;
            if lambda <= 0.0 {
                continue;
            }
            let dz = q.z - a3 * w;
            if dz * dz >= cut2 {
                continue;
            }
            let gap = (lambda * r_lo - rho).max(rho - lambda * r_hi).max(0.0);
            if gap * gap + dz * dz >= cut2 {
                continue;
            }
            // the node's ring of the normaliser's grid: which of its cells the sensor sees
            let seen = (self.normaliser.visible.as_deref())
                .map(|v| &v[self.rings[k] * sectors..][..sectors]);
            let inv_lambda = 1.0 / lambda;
            let [dc, dw] = self.section.d_point[k];
            for run in window.clone() {
                for s in &self.samples[run] {
                    let [cx, cy] = s.point;
                    let (ex, ey) = (q.x - lambda * cx, q.y - lambda * cy);
                    let d2 = ex * ex + ey * ey + dz * dz;
                    if d2 >= cut2 {
                        continue;
                    }
                    let [dx, dy] = s.tangent;
                    let cross = s.cross;
                    // the surface element's weight: its area, or seen by the sensor its
                    // projected area lambda·(-n·v)/|v|, n = (a3 tw dy, -a3 tw dx, -tc cross)
                    // (the two halves of the section's step one by one: at a sharp corner
                    // one may face the sensor and the other not, and their areas add up where
                    // the step's own would cut the corner)
                    let mut facing = [0.0; 2];
                    let weight = match sight {
                        Some(v) => {
                            if seen.is_some_and(|row| !row[s.sector]) {
                                continue;
                            }
                            facing = self.half_facing(k, dx, dy, cross, v);
                            let projected = facing.iter().map(|f| (-f).max(0.0)).sum::<f64>();
                            if projected <= 0.0 {
                                continue;
                            }
                            lambda * projected * inv_sight_length
                        }
                        None => lambda * self.half_areas(k, dx, dy, cross).iter().sum::<f64>(),
                    };
                    let gauss = (d2 * exponent).exp();
                    let term = weight * (gauss - self.floor);
                    out.sum += term;
                    if !with_gradient {
                        continue;
                    }
                    // d term = slope · d(-d²/2) + term · d ln weight
                    let slope = weight * gauss * inv_var;
                    let e = DVec3::new(ex, ey, dz);
                    out.by_point -= slope * e;
                    let [dcx, dcy] = s.d_point;
                    let radial = ex * cx + ey * cy;
                    // through the surface position S = (lambda C, a3 w)
                    let by_shape = [
                        ex * lambda * cx * inv_a1,
                        ey * lambda * cy * inv_a2,
                        dz * w,
                        radial,
                        radial * dc + dz * a3 * dw,
                        lambda * (ex * dcx + ey * dcy),
                    ];
                    out.ln_sigma += slope * d2;
                    // through the weight: ln lambda, then the area or the projected area
                    let mut log_weight = [0.0, 0.0, 0.0, inv_lambda, dc * inv_lambda, 0.0];
                    self.add_log_weight_partials(
                        k,
                        s,
                        sight.map(|v| (v, facing)),
                        term,
                        &mut log_weight,
                        &mut out.by_sight,
                    );
                    for p in 0..6 {
                        out.shape[p] += slope * by_shape[p] + term * log_weight[p];
                    }
                }
            }
        }
        out
    }
}

#[cfg(test)]
mod tests;

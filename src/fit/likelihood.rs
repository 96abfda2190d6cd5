//! Noise-aware refinement: the fit polished to the maximum-likelihood surface of a
//! generative model of the cloud, points spread evenly over the surface, blurred by
//! isotropic Gaussian noise of an unknown sigma, plus uniform outliers:
//!
//!   p(x) = (1 - w_out) · (1/A) ∫_S N(x; s, sigma² I) dA(s) + w_out / V
//!
//! Why: any least-squares distance fit, the paper's meridian distance or the exact
//! Euclidean one, is biased once the noise is a sizeable fraction of the shape's thinnest
//! half-axis. Noise rounds a square section and fills a pinched one, so eps drifts, and it
//! spreads points further outside a thin section than inside, so the sizes drift (a circle
//! of radius r fitted to points with noise sigma comes out about r + sigma²/2r). On the
//! ground-truth suite a least-squares fit started at the true parameters still failed the
//! tolerances on most clouds with sigma above 15% of the thinnest half-axis. The
//! likelihood above is consistent: its maximum sits at the true surface whatever the
//! noise, given enough points, because it models the blur instead of measuring through it.
//!
//! Seen from a viewpoint (a single view), the points cover only what the sensor saw, at a
//! density of cos(incidence) / range² per unit area: dA above becomes that density times
//! dA over the visible surface (a z-buffer of the grid's mesh, `visibility`, found once
//! per evaluation and held for its derivatives). Without it the model would shrink the
//! unseen side to raise the density on the seen one.
//!
//! The surface integral is a sum over a polar grid of the surface (cells at most
//! [`CELL_SIGMAS`] sigmas across, where a Gaussian kernel's sum equals its integral to a
//! fraction of a percent; [`refine_finely`] halves that along the section, whose
//! curvature the coarser rings bend the optimum with), each data point meeting only the cells within [`CUTOFF`] sigmas
//! of it (a uniform bucket grid). The parameters, sigma with them, are found by
//! Levenberg-Marquardt on the negative mean log-likelihood, the gradient in closed form
//! (for the shape through each grid corner's derivatives, `derivatives`).
//!
//! It runs on shapes with a hole (a4 > 1, where the grid covers the surface once), and
//! only when the noise is large enough to bias least squares
//! ([`super::LIKELIHOOD_NOISE_RATIO`], [`super::LIKELIHOOD_VIEW_NOISE_RATIO`]): below that
//! it would cost time for nothing. The search polishes its fits with it
//! ([`super::search::polish`]); what the polish earns, and what it costs, is measured in
//! `docs/fit.md` (`supertoroid bench ablation`).

mod derivatives;
mod grid;
pub(crate) mod visibility;

pub use grid::{CELL_SIGMAS, FINE_SECTION_CELL_SIGMAS, MAX_CELLS};
pub(crate) use grid::{Cells, Curves};
use grid::{grid_for, regrid, surface_cells};

pub(crate) use derivatives::{d_log_view_weight, d_log_view_weight_pose};

use super::sight::Sight;
use crate::eval::Candidate;
use crate::model::{Pose, Shape};
use crate::solve::Bounds;
use crate::solve::likelihood::{LikelihoodProblem, Matrix, Stopping, Vector, fold_turn, minimise};
use glam::{DQuat, DVec3};
use nalgebra::{SMatrix, SVector};
use rayon::prelude::*;
use visibility::View;

/// Data points meet surface cells within this many sigmas. The kernel is shifted down by
/// its value there (e^-8) so that it reaches zero continuously: a cell crossing the
/// cutoff would otherwise make the objective jump under the line search. The cut makes
/// the kernel lighter-tailed than the Gaussian noise it models, which biases the fit:
/// per point, sigma's score at the true sigma is +0.12 at 3.5 sigmas, +0.03 at 4, +0.005
/// at 4.5. On the suite (540 cases) 3.5 gave 498 successes, 4 gave 506, 4.5 gave 505.
pub const CUTOFF: f64 = 4.0;
/// Two steps in a row that raise the mean log-likelihood by less than this end the
/// refinement (a thousand points: 0.02 in all, far below what tells two fits apart
/// statistically). One such step alone can stop a fit in a flat valley (13% off in a3
/// seen on the suite); two in a row gave 519 against 518 of 540 (nothing lost), the fit
/// times the same within the machine's noise.
pub const STOP_DECREASE: f64 = 2e-5;
/// Levenberg-Marquardt iterations at most, by default.
pub const MAX_ITERATIONS: usize = 30;
/// The refinement stops where its undamped step predicts less than this decrease of the
/// log-likelihood of all the points (the quadratic model's g·H⁻¹g / 2 per point, times
/// their count): with H the points' information, the point is then within about one
/// standard error (a Mahalanobis distance of 1) of the model's optimum on these points,
/// closer than their noise places that optimum. On broadened views a refinement from the
/// search's fit had crept on for up to the 30-iteration cap at a few 1e-5 a point a
/// step. Measured interleaved: broadened views 4220000 (40) and 4230000 (80) 96 -> 97
/// right, mean 197 -> 181 and 210 -> 195 ms; suite 1720000 (180) no fit changed, mean
/// 97 -> 88 ms; at 2 nats, 97 right and 165, 183, 86 ms.
pub const WITHIN_NATS: f64 = 0.5;

/// The parameters of the refinement ([`crate::solve::likelihood`]'s): shape a1 a2 a3 a4
/// eps1 eps2, translation, a rotation vector applied on the left of the starting
/// rotation, ln sigma.
const N: usize = PARAMETERS;

pub use super::objective::{Limits, Refined};

/// The smallest and largest coordinates of `points`.
fn bounding_box(points: &[DVec3]) -> (DVec3, DVec3) {
    points.iter().fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    )
}

/// The volume the model spreads its outliers over: the box of `points` along their
/// principal axes (each side at least `sigma`). Not the box along the world's axes: its
/// volume depends on how the cloud happens to be turned in the world (on the suite's
/// clouds up to about five times the object's own box), and with it the outlier density
/// and the fit. Seen through the world's box, the model took half or less of the outliers
/// near the surface for outliers (at the true parameters, 10% outliers read as 4-7%), and
/// counted the rest as surface points blurring a thicker section: sizes 10-16% too large
/// on noisy single views.
pub fn outlier_volume(points: &[DVec3], sigma: f64) -> f64 {
    let (axes, _) = super::principal_axes(points);
    let along: Vec<DVec3> = points.iter().map(|p| axes.transpose() * *p).collect();
    let (lo, hi) = bounding_box(&along);
    (hi - lo).max(DVec3::splat(sigma)).element_product()
}

/// The problem: normalised points, the outlier model, the grid (fixed for a run of
/// iterations: the objective must not jump under the line search).
struct Problem<'a> {
    points: &'a [DVec3],
    outlier_weight: f64,
    /// outlier density w_out / V
    outlier_density: f64,
    rotation0: DQuat,
    grid: (usize, usize),
    /// the sensor's position (and frame): the points then cover only what it saw (see
    /// [`View`])
    sight: Option<Sight>,
    /// data points meet the cells within this many sigmas ([`CUTOFF`] for the fit)
    cutoff: f64,
    /// the rings' spacing along the section, in sigmas ([`grid_for`])
    section_cell_sigmas: f64,
}

/// Cells bucketed on a uniform grid of `cell`-sized boxes (a counting sort).
struct Buckets {
    origin: DVec3,
    cell: f64,
    dims: [i64; 3],
    start: Vec<usize>,
    items: Vec<u32>,
}

impl Buckets {
    /// Boxes at least `cut` wide, and no more than 64 along the longest side (a fine
    /// cutoff on a large shape would otherwise allocate millions of empty boxes).
    fn new(centres: &[DVec3], cut: f64) -> Self {
        Self::within(bounding_box(centres), centres, cut)
    }

    /// [`Buckets::new`] on the box `(lo, hi)`, which holds every centre.
    fn within((lo, hi): (DVec3, DVec3), centres: &[DVec3], cut: f64) -> Self {
        let cell = cut.max((hi - lo).max_element() / 64.0);
        let span = ((hi - lo) / cell).floor();
        let dims = [span.x as i64 + 1, span.y as i64 + 1, span.z as i64 + 1];
        let mut buckets = Self {
            origin: lo,
            cell,
            dims,
            start: vec![0; (dims[0] * dims[1] * dims[2]) as usize + 1],
            items: vec![0; centres.len()],
        };
        // (every centre lies in the box by construction)
        let keys: Vec<usize> = centres
            .par_iter()
            .map(|p| buckets.index(buckets.coords(*p)).unwrap_or(0))
            .collect();
        for &k in &keys {
            buckets.start[k + 1] += 1;
        }
        for k in 1..buckets.start.len() {
            buckets.start[k] += buckets.start[k - 1];
        }
        let mut fill = buckets.start.clone();
        for (j, &k) in keys.iter().enumerate() {
            buckets.items[fill[k]] = j as u32;
            fill[k] += 1;
        }
        buckets
    }

    fn coords(&self, p: DVec3) -> [i64; 3] {
        let q = ((p - self.origin) / self.cell).floor();
        [q.x as i64, q.y as i64, q.z as i64]
    }

    fn index(&self, c: [i64; 3]) -> Option<usize> {
        ((0..3).all(|k| (0..self.dims[k]).contains(&c[k])))
            .then(|| ((c[0] * self.dims[1] + c[1]) * self.dims[2] + c[2]) as usize)
    }

    /// Every cell in the 27 boxes around p.
    fn near(&self, p: DVec3, mut visit: impl FnMut(usize)) {
        let c = self.coords(p);
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    if let Some(k) = self.index([c[0] + dx, c[1] + dy, c[2] + dz]) {
                        for &j in &self.items[self.start[k]..self.start[k + 1]] {
                            visit(j as usize);
                        }
                    }
                }
            }
        }
    }
}

/// The surface grid at one parameter vector, in the normalised frame, with what the
/// gradient needs: each cell's centre and area, and their derivatives in the six shape
/// parameters (closed form, `derivatives`). Only the cells of positive weight are
/// kept (seen from a viewpoint, about half of them are hidden or face away, and add
/// nothing to a point's density or its gradient); `bounds` is the box of all of them.
struct Surface {
    bounds: (DVec3, DVec3),
    cells: Vec<DVec3>,
    areas: Vec<f64>,
    /// per cell: d centre / d shape_k (world frame), k = 0..6
    d_cells: Vec<[DVec3; 6]>,
    /// per cell: d ln area / d shape_k
    d_log_areas: Vec<[f64; 6]>,
    /// d ln A / d shape_k, A the total area
    d_log_area: [f64; 6],
    /// seen from a viewpoint, per cell: d ln weight / d pose_k (translation, turn), the
    /// view weight cos(incidence) / range² moving with the pose; empty without one
    d_log_weights_pose: Vec<[f64; 6]>,
    /// d ln A / d pose_k (zero without a viewpoint)
    d_log_area_pose: [f64; 6],
    area: f64,
}

impl<'a> Problem<'a> {
    /// The problem on `points` and the parameter vector of `candidate` with noise
    /// `sigma` (the turn zero: the candidate's rotation is the reference); None where
    /// the model does not apply (no hole: a4 <= 1; sigma not positive; under 20 points).
    fn at(
        points: &'a [DVec3],
        candidate: &Candidate,
        sigma: f64,
        outlier_weight: f64,
        sight: Option<Sight>,
        cutoff: f64,
        section_cell_sigmas: f64,
    ) -> Option<(Self, Vector)> {
        let s = candidate.shape;
        if s.a4 <= 1.0 || !(sigma > 0.0) || points.len() < 20 {
            return None;
        }
        let volume = outlier_volume(points, sigma);
        let problem = Problem {
            points,
            outlier_weight,
            outlier_density: outlier_weight / volume,
            rotation0: candidate.pose.rotation,
            grid: grid_for(&s.to_array(), sigma, section_cell_sigmas),
            sight,
            cutoff,
            section_cell_sigmas,
        };
        let x = super::objective::parameters(candidate, sigma);
        Some((problem, x))
    }
}

impl Problem<'_> {
    fn rotation(&self, x: &Vector) -> DQuat {
        DQuat::from_scaled_axis(DVec3::new(x[9], x[10], x[11])) * self.rotation0
    }

    fn shape(x: &Vector) -> [f64; 6] {
        [x[0], x[1], x[2], x[3], x[4], x[5]]
    }

    fn surface(&self, x: &Vector, with_derivatives: bool) -> Surface {
        let shape = Self::shape(x);
        let (rings, sectors) = self.grid;
        let curves = Curves::closed(&shape, rings, sectors);
        let Cells {
            centres: canonical,
            areas,
            normals,
        } = curves.cells(&shape);
        let rotation = self.rotation(x);
        let translation = DVec3::new(x[6], x[7], x[8]);
        let cells: Vec<DVec3> = canonical
            .par_iter()
            .map(|p| rotation * *p + translation)
            .collect();
        // seen from a viewpoint, a cell's share is its area times its view weight (the
        // visibility found once here)
        let world_normals: Vec<DVec3> = match self.sight {
            Some(_) => normals.par_iter().map(|n| rotation * *n).collect(),
            None => Vec::new(),
        };
        let view = self
            .sight
            .map(|v| View::new(&cells, &areas, &world_normals, self.grid, v));
        let areas = match &view {
            Some(view) => view.weights(&areas, &cells, &normals, rotation),
            None => areas,
        };
        let area: f64 = areas.iter().sum();
        let bounds = bounding_box(&cells);
        let kept: Vec<usize> = match view {
            Some(_) => (0..cells.len())
                .into_par_iter()
                .filter(|&j| areas[j] > 0.0)
                .collect(),
            None => (0..cells.len()).collect(),
        };
        let mut d_cells = Vec::new();
        let mut d_log_areas = Vec::new();
        let mut d_log_area = [0.0; 6];
        if with_derivatives {
            let viewpoint_canonical = view
                .as_ref()
                .map(|view| rotation.inverse() * (view.viewpoint - translation));
            // (each kept cell's six derivatives in closed form, `derivatives`)
            (d_cells, d_log_areas) = kept
                .par_iter()
                .map(|&j| {
                    let d = curves.cell(&shape, j / sectors, j % sectors, normals[j]);
                    let d_world = d.centre.map(|c| rotation * c);
                    let mut d_log = d.log_area;
                    if let Some(viewpoint) = viewpoint_canonical {
                        // (the dot products in the body's frame, the viewpoint taken there)
                        let q = canonical[j] - viewpoint;
                        for k in 0..6 {
                            d_log[k] = d_log_view_weight(
                                d.log_area[k],
                                d.centre[k],
                                d.normal[k],
                                normals[j],
                                q,
                            );
                        }
                    }
                    (d_world, d_log)
                })
                .unzip();
            for (&j, d_log) in kept.iter().zip(&d_log_areas) {
                for k in 0..6 {
                    d_log_area[k] += areas[j] * d_log[k] / area;
                }
            }
        }
        let mut d_log_weights_pose = Vec::new();
        let mut d_log_area_pose = [0.0; 6];
        if let (true, Some(Sight { viewpoint: v, .. })) = (with_derivatives, self.sight) {
            d_log_weights_pose = kept
                .par_iter()
                .map(|&j| d_log_view_weight_pose(world_normals[j], cells[j], translation, v))
                .collect();
            for (&j, d) in kept.iter().zip(&d_log_weights_pose) {
                for k in 0..6 {
                    d_log_area_pose[k] += areas[j] * d[k] / area;
                }
            }
        }
        // (without a viewpoint every cell is kept: no copy)
        let (cells, areas) = match view {
            Some(_) => kept.par_iter().map(|&j| (cells[j], areas[j])).unzip(),
            None => (cells, areas),
        };
        Surface {
            bounds,
            cells,
            areas,
            d_cells,
            d_log_areas,
            d_log_area,
            d_log_weights_pose,
            d_log_area_pose,
            area,
        }
    }

    /// The negative mean log-likelihood; with `with_gradient`, also its gradient and the
    /// outer-product (BHHH) approximation of its Hessian, sum_i grad_i grad_i^T / n, from
    /// each point's own gradient of ln p(x_i).
    fn evaluate(&self, x: &Vector, with_gradient: bool) -> (f64, Vector, Matrix) {
        let sigma = x[12].exp();
        let translation = DVec3::new(x[6], x[7], x[8]);
        let surface = self.surface(x, with_gradient);
        let cut = self.cutoff * sigma;
        let buckets = Buckets::within(surface.bounds, &surface.cells, cut);
        let z = (std::f64::consts::TAU * sigma * sigma).powf(1.5);
        let inlier_scale = (1.0 - self.outlier_weight) / (surface.area * z);
        let half_inv_var = 0.5 / (sigma * sigma);
        let var = sigma * sigma;
        let floor = (-0.5 * self.cutoff * self.cutoff).exp();

        // ln p(x_i), and its gradient in the parameters:
        // d ln p = sum_j [c_ij d ln a_j + rho_ij (x - s_j) . d s_j / sigma²] - u_i d ln A
        // and per unit of ln sigma sum_j rho_ij |x - s_j|² / sigma² - 3 u_i, with
        // rho_ij = (1 - w_out) a_j K_ij / (A Z p(x_i)), c_ij the same with the shifted
        // kernel, u_i = sum_j c_ij (the point's inlier share)
        // (one pass over the nearby cells: every term of the gradient carries the point's
        // factor f = inlier_scale / p(x_i), applied once the kernel sum, and so p, is known)
        let point_term = |x: &DVec3| -> (f64, Vector) {
            let mut kernel_sum = 0.0;
            let mut g = Vector::zeros();
            buckets.near(*x, |j| {
                let d = *x - surface.cells[j];
                let d2 = d.length_squared();
                if d2 < cut * cut {
                    let kernel = (-d2 * half_inv_var).exp();
                    // (the shift moves the kernel's value, not its slope)
                    let c = surface.areas[j] * (kernel - floor);
                    kernel_sum += c;
                    if with_gradient {
                        let rho = surface.areas[j] * kernel / var;
                        for k in 0..6 {
                            g[k] +=
                                c * surface.d_log_areas[j][k] + rho * d.dot(surface.d_cells[j][k]);
                        }
                        let offset = rho * d;
                        let turn = (surface.cells[j] - translation).cross(offset);
                        g[6] += offset.x;
                        g[7] += offset.y;
                        g[8] += offset.z;
                        g[9] += turn.x;
                        g[10] += turn.y;
                        g[11] += turn.z;
                        g[12] += rho * d2;
                        if let Some(d) = surface.d_log_weights_pose.get(j) {
                            for k in 0..6 {
                                g[6 + k] += c * d[k];
                            }
                        }
                    }
                }
            });
            let density = inlier_scale * kernel_sum + self.outlier_density;
            if with_gradient {
                let f = inlier_scale / density;
                g *= f;
                let inlier_share = f * kernel_sum;
                for k in 0..6 {
                    g[k] -= inlier_share * surface.d_log_area[k];
                    g[6 + k] -= inlier_share * surface.d_log_area_pose[k];
                }
                g[12] -= 3.0 * inlier_share;
            }
            (density.ln(), g)
        };
        let n = self.points.len() as f64;
        // fixed chunks summed in order: the same sums whatever the threads' schedule, so a
        // seed always gives the same fit
        let partials: Vec<(f64, Vector, Matrix)> = self
            .points
            .par_chunks(128)
            .map(|chunk| {
                let mut sums = (0.0, Vector::zeros(), Matrix::zeros());
                for p in chunk {
                    let (l, g) = point_term(p);
                    sums.0 += l;
                    if with_gradient {
                        sums.1 += g;
                        sums.2 += g * g.transpose();
                    }
                }
                sums
            })
            .collect();
        let (log_likelihood, gradient, outer) = partials
            .into_iter()
            .fold((0.0, Vector::zeros(), Matrix::zeros()), |a, b| {
                (a.0 + b.0, a.1 + b.1, a.2 + b.2)
            });
        (-log_likelihood / n, -gradient / n, outer / n)
    }
}

/// How much of a candidate's surface the points cover: the area share of its cells with a
/// point within [`COVER_SIGMAS`] sigmas (at least twice the points' mean spacing). A full
/// cloud covers nearly all of its surface, a single view the side that faced the sensor.
pub fn surface_coverage(points: &[DVec3], candidate: &Candidate, sigma: f64) -> f64 {
    let shape = candidate.shape.to_array();
    let (rings, sectors) = grid_for(&shape, sigma, CELL_SIGMAS);
    let (canonical, areas, _) = surface_cells(&shape, rings, sectors);
    let pose = &candidate.pose;
    let cells: Vec<DVec3> = canonical.iter().map(|p| pose.to_world(*p)).collect();
    // (or twice the points' mean spacing on the surface, where the noise is small: a
    // thousand points cover a large surface more thinly than three sigmas)
    let total: f64 = areas.iter().sum();
    let spacing = (total / points.len().max(1) as f64).sqrt();
    let cut = (COVER_SIGMAS * sigma).max(2.0 * spacing);
    let buckets = Buckets::new(&cells, cut);
    let mut covered = vec![false; cells.len()];
    for x in points {
        buckets.near(*x, |j| {
            if (*x - cells[j]).length_squared() < cut * cut {
                covered[j] = true;
            }
        });
    }
    let seen: f64 = (0..cells.len())
        .filter(|&j| covered[j])
        .map(|j| areas[j])
        .sum();
    seen / total.max(f64::MIN_POSITIVE)
}

/// A point covers the cells within this many sigmas of it ([`surface_coverage`]).
pub const COVER_SIGMAS: f64 = 3.0;

/// Refines `start` (normalised units, a shape with a hole) on `points` from the noise
/// estimate `sigma`, with the outlier share `outlier_weight` of the points spread over
/// their box along their principal axes (`outlier_volume`). None when the start is not a
/// shape this model covers (a4 <= 1) or the cloud is too small.
///
/// Levenberg-Marquardt on the BHHH Hessian (the outer product of the points' gradients,
/// the Fisher information near the optimum): from a least-squares fit it converges in
/// about ten steps.
pub fn refine(
    points: &[DVec3],
    start: &Candidate,
    sigma: f64,
    outlier_weight: f64,
    sight: Option<Sight>,
    limits: &Limits,
    max_iterations: usize,
) -> Option<Refined> {
    let problem = Problem::at(
        points,
        start,
        sigma,
        outlier_weight,
        sight,
        CUTOFF,
        CELL_SIGMAS,
    )?;
    refine_problem(problem, start, sigma, limits, max_iterations)
}

/// The signature of [`refine`] and [`refine_finely`].
pub type Refine =
    fn(&[DVec3], &Candidate, f64, f64, Option<Sight>, &Limits, usize) -> Option<Refined>;

/// [`refine`] on a grid twice as fine along the section
/// ([`FINE_SECTION_CELL_SIGMAS`]): an optimum without the coarse grid's bias, at about
/// twice the cost per step, for the fit's last polish.
pub fn refine_finely(
    points: &[DVec3],
    start: &Candidate,
    sigma: f64,
    outlier_weight: f64,
    sight: Option<Sight>,
    limits: &Limits,
    max_iterations: usize,
) -> Option<Refined> {
    let problem = Problem::at(
        points,
        start,
        sigma,
        outlier_weight,
        sight,
        CUTOFF,
        FINE_SECTION_CELL_SIGMAS,
    )?;
    refine_problem(problem, start, sigma, limits, max_iterations)
}

fn refine_problem(
    (problem, x): (Problem, Vector),
    start: &Candidate,
    sigma: f64,
    limits: &Limits,
    max_iterations: usize,
) -> Option<Refined> {
    let mut problem = Bounded {
        problem,
        bounds: limits.bounds,
        sigma,
        previous: None,
    };
    let stopping = Stopping {
        max_iterations,
        decrease: STOP_DECREASE,
        step: 1e-6,
        predicted: WITHIN_NATS / problem.problem.points.len() as f64,
        deadline: limits.deadline,
    };
    let minimum = minimise(&mut problem, x, &limits.held(start), &stopping);
    let x = minimum.x;
    let shape = Shape::new(x[0], x[1], x[2], x[3], x[4], x[5]);
    let pose = Pose::new(
        problem.problem.rotation(&x).normalize(),
        DVec3::new(x[6], x[7], x[8]),
    );
    Some(Refined {
        candidate: Candidate { shape, pose },
        sigma: x[12].exp(),
        iterations: minimum.iterations,
        objective: minimum.value,
    })
}

/// The problem within the shape's box (a4 > 1.01: the model needs its hole, sigma
/// within 1e-3 and 1e2 of the start's): a step outside is rejected.
struct Bounded<'a> {
    problem: Problem<'a>,
    bounds: Bounds,
    sigma: f64,
    /// the reference before the last accepted step: rotation and grid
    previous: Option<(DQuat, (usize, usize))>,
}

impl LikelihoodProblem for Bounded<'_> {
    fn evaluate(&self, x: &Vector, with_gradient: bool) -> (f64, Vector, Matrix) {
        self.problem.evaluate(x, with_gradient)
    }

    fn admit(&self, x: Vector) -> Option<Vector> {
        let b = &self.bounds;
        let feasible = (0..6).all(|k| x[k] > b.lower[k] && x[k] < b.upper[k])
            && x[3] > 1.01
            && x[12] > (1e-3 * self.sigma).ln()
            && x[12] < (1e2 * self.sigma).ln();
        feasible.then_some(x)
    }

    fn accept(&mut self, mut x: Vector) -> (Vector, bool) {
        // the turn folds into the starting rotation (the gradient is the left
        // perturbation's at zero)
        let problem = &mut self.problem;
        self.previous = Some((problem.rotation0, problem.grid));
        problem.rotation0 = fold_turn(&mut x, problem.rotation0);
        let grid = problem.grid;
        problem.grid = regrid(
            grid,
            grid_for(
                &Problem::shape(&x),
                x[12].exp(),
                problem.section_cell_sigmas,
            ),
        );
        (x, problem.grid == grid)
    }

    /// (the grid is kept on most steps ([`regrid`]), and the gradient at a trial is the
    /// left perturbation's, as the folded reference's is)
    fn trial_gradients(&self) -> bool {
        true
    }

    fn restore(&mut self) {
        if let Some((rotation0, grid)) = self.previous.take() {
            (self.problem.rotation0, self.problem.grid) = (rotation0, grid);
        }
    }
}

pub use crate::solve::likelihood::PARAMETERS;

/// The kernel's cutoff for [`scores`], in sigmas: far enough that the kernel is the
/// Gaussian itself (e^-18 at the cutoff). The fit's [`CUTOFF`] makes a lighter-tailed
/// kernel whose scores, on points with Gaussian noise, are off near the cutoff: they
/// overstated the information about sigma twofold on a test torus.
const SCORE_CUTOFF: f64 = 6.0;

/// The model's Fisher information per point at `candidate` and `sigma` (normalised units,
/// parameters as in [`PARAMETERS`]), estimated by the mean outer product of the points'
/// scores (gradients of ln p(x_i)). Times the number of points, its inverse is the
/// Cramér-Rao bound: the smallest covariance an unbiased estimator can reach on clouds
/// drawn from this model ([`crate::suite::attainable`]). The points should be drawn at these
/// parameters; `outlier_weight` as in [`refine`]. None where [`refine`] would not run.
pub fn scores(
    points: &[DVec3],
    candidate: &Candidate,
    sigma: f64,
    outlier_weight: f64,
    sight: Option<Sight>,
) -> Option<Scores> {
    let (problem, x) = Problem::at(
        points,
        candidate,
        sigma,
        outlier_weight,
        sight,
        SCORE_CUTOFF,
        CELL_SIGMAS,
    )?;
    let (_, gradient, outer) = problem.evaluate(&x, true);
    (outer.iter().chain(gradient.iter()).all(|v| v.is_finite())).then_some(Scores {
        mean: -gradient,
        information: outer,
    })
}

/// The model's mean negative log-likelihood of `points` at `candidate` and `sigma`
/// (normalised units; `outlier_weight` as in [`refine`]), without the gradient: what
/// [`Refined::objective`] reports, for comparing fits made on other samples. None where
/// [`refine`] would not run.
pub fn objective(
    points: &[DVec3],
    candidate: &Candidate,
    sigma: f64,
    outlier_weight: f64,
    sight: Option<Sight>,
) -> Option<f64> {
    let (problem, x) = Problem::at(
        points,
        candidate,
        sigma,
        outlier_weight,
        sight,
        CUTOFF,
        CELL_SIGMAS,
    )?;
    Some(problem.evaluate(&x, false).0)
}

/// The points' scores at one parameter vector ([`scores`]).
#[derive(Clone, Copy, Debug)]
pub struct Scores {
    /// the mean score, the gradient of the mean ln p(x_i): zero in expectation at the
    /// parameters the points were drawn at, if the model describes them
    pub mean: SVector<f64, N>,
    /// the mean outer product of the scores: the Fisher information per point
    pub information: SMatrix<f64, N, N>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cell_areas_add_up_to_the_torus_area() {
        // a circular torus (eps = 1, a1 = a2 = a3 = r, a4 = R / r): area 4 pi² R r
        let (r, big_r) = (0.2, 0.6);
        let (_, areas, _) = surface_cells(&[r, r, r, big_r / r, 1.0, 1.0], 200, 400);
        let area: f64 = areas.iter().sum();
        let exact = 4.0 * std::f64::consts::PI.powi(2) * big_r * r;
        assert!((area / exact - 1.0).abs() < 1e-3, "{area} vs {exact}");
    }

    #[test]
    fn a_full_sample_covers_its_surface_and_half_of_it_about_half() {
        let shape = Shape::new(0.3, 0.25, 0.12, 2.0, 0.7, 1.3);
        let candidate = Candidate {
            shape,
            pose: Pose::default(),
        };
        let mut rng = crate::synth::rng(3);
        let points = crate::synth::sample_surface(&shape, &candidate.pose, 2000, &mut rng);
        let full = surface_coverage(&points, &candidate, 0.01);
        let half: Vec<DVec3> = points.iter().copied().filter(|p| p.x > 0.0).collect();
        let half = surface_coverage(&half, &candidate, 0.01);
        assert!(full > 0.95, "full sample covers {full}");
        assert!((0.4..0.6).contains(&half), "half sample covers {half}");
    }

    /// From a start with a biased section, the model moves a3 and eps back towards the
    /// truth; what the caller holds (a known a1, a known hole axis) does not move.
    #[test]
    fn refinement_recovers_the_section_and_keeps_what_is_held() {
        let shape = Shape::new(0.3, 0.3, 0.08, 2.0, 0.6, 1.0);
        let pose = Pose::new(
            DQuat::from_scaled_axis(DVec3::new(0.4, 0.1, -0.3)),
            DVec3::new(0.1, 0.0, -0.05),
        );
        let mut rng = crate::synth::rng(11);
        let mut points = crate::synth::sample_surface(&shape, &pose, 1500, &mut rng);
        crate::synth::add_noise(&mut points, 0.02, &mut rng);
        // least squares' kind of bias: a thicker, rounder section
        let start = Candidate {
            shape: Shape::new(0.3, 0.3, 0.095, 2.0, 0.8, 1.0),
            pose,
        };
        let limits = Limits {
            bounds: Bounds::new(1e-3, 5.0, 10.0, 0.1, 2.0),
            fixed_shape: [true, false, false, false, false, false],
            fixed_axis: true,
            deadline: None,
        };
        let r = refine(&points, &start, 0.02, 0.05, None, &limits, MAX_ITERATIONS).unwrap();
        let s = r.candidate.shape;
        assert!((s.a3 - 0.08).abs() < 0.004, "a3 {}", s.a3);
        assert!((s.eps1 - 0.6).abs() < 0.08, "eps1 {}", s.eps1);
        assert!((r.sigma / 0.02 - 1.0).abs() < 0.15, "sigma {}", r.sigma);
        assert_eq!(s.a1, 0.3);
        let axis_drift = r.candidate.pose.axis().dot(pose.axis()).abs();
        assert!(axis_drift > 1.0 - 1e-9, "axis moved: cos {axis_drift}");
    }

    /// Where a depth sensor's points fall, by the cosine of their incidence: the model's
    /// visible density (cells facing the sensor, not hidden, weighted cos / range²)
    /// against a rendered view. Culling no back faces, or keeping only the nearest sliver
    /// of a grazing face per pixel, put twice the points between cos 0.1 and 0.4 or half.
    #[test]
    fn the_visible_density_matches_a_rendered_view() {
        let shape = Shape::new(0.08, 0.06, 0.03, 2.0, 0.8, 1.2);
        let pose = Pose::new(
            DQuat::from_scaled_axis(DVec3::new(0.3, -0.5, 0.2)),
            DVec3::new(0.05, -0.1, 0.7),
        );
        let camera = crate::synth::Camera::random_view(
            &shape,
            &pose,
            crate::synth::Intrinsics::REALSENSE_640X480,
            &mut crate::synth::rng(99),
        );
        let view = crate::synth::render_view(&shape, &pose, &camera, 0.0001).unwrap();
        let points = crate::synth::subsample(&view.points, 3000, &mut crate::synth::rng(1));
        let viewpoint = camera.pose.translation;
        let sigma = 0.015 * shape.size();
        let (rings, sectors) = grid_for(&shape.to_array(), sigma, CELL_SIGMAS);
        let (canonical, areas, normals) = surface_cells(&shape.to_array(), rings, sectors);
        let cells: Vec<DVec3> = canonical.iter().map(|c| pose.to_world(*c)).collect();
        let world_normals: Vec<DVec3> = normals.iter().map(|n| pose.rotation * *n).collect();
        let weights = View::new(
            &cells,
            &areas,
            &world_normals,
            (rings, sectors),
            Sight::at(viewpoint),
        )
        .weights(&areas, &cells, &normals, pose.rotation);
        let cos_bin = |j: usize| {
            let cos = world_normals[j]
                .dot((cells[j] - viewpoint).normalize())
                .abs();
            ((cos * 10.0) as usize).min(9)
        };
        let mut data = [0.0; 10];
        for p in &points {
            let nearest = (0..cells.len())
                .min_by(|&a, &b| {
                    (cells[a] - *p)
                        .length_squared()
                        .total_cmp(&(cells[b] - *p).length_squared())
                })
                .unwrap();
            data[cos_bin(nearest)] += 1.0;
        }
        let total: f64 = weights.iter().sum();
        let mut model = [0.0; 10];
        for (j, w) in weights.iter().enumerate() {
            model[cos_bin(j)] += w / total * points.len() as f64;
        }
        let chi2: f64 = (0..10)
            .filter(|&b| model[b] > 0.0)
            .map(|b| (data[b] - model[b]).powi(2) / model[b])
            .sum();
        assert!(
            chi2 < 30.0,
            "chi² {chi2:.1} over 10 bins: data {data:?}, model {model:?}"
        );
    }

    /// The cells the model sees are those no part of the surface hides, on grids of
    /// several sizes: a view from just above the ring's plane, where the near side of the
    /// ring hides the far side of the hole. Judged against rays marched through the exact
    /// surface (eq. 1), as the renderer traces them, and weighted as the model weighs the
    /// cells. The old depth buffer of whole cells, two cells per pixel, hid strips of
    /// seen cells along the occluding edges: 6.4% of the seen weight on the first grid.
    #[test]
    fn the_visible_cells_are_those_no_surface_hides() {
        let shape = Shape::new(0.08, 0.06, 0.025, 1.6, 0.8, 1.2);
        let pose = Pose::new(
            DQuat::from_scaled_axis(DVec3::new(0.2, -0.1, 0.4)),
            DVec3::new(0.01, 0.02, -0.03),
        );
        let viewpoint = pose.to_world(DVec3::new(0.5, 0.1, 0.09));
        let hidden = |cell: DVec3, spacing: f64| {
            let (from, to) = (pose.to_canonical(viewpoint), pose.to_canonical(cell));
            let length = (to - from).length() - 2.0 * spacing;
            let steps = (length / (0.25 * spacing)) as usize;
            (0..steps).any(|k| {
                let p = from + (to - from).normalize() * (k as f64 * 0.25 * spacing);
                shape.section_norm(p) < 1.0
            })
        };
        for (rings, sectors) in [(24, 90), (31, 123), (40, 160)] {
            let (canonical, areas, normals) = surface_cells(&shape.to_array(), rings, sectors);
            let cells: Vec<DVec3> = canonical.iter().map(|c| pose.to_world(*c)).collect();
            let world_normals: Vec<DVec3> = normals.iter().map(|n| pose.rotation * *n).collect();
            let view = View::new(
                &cells,
                &areas,
                &world_normals,
                (rings, sectors),
                Sight::at(viewpoint),
            );
            let spacing = (areas.iter().sum::<f64>() / areas.len() as f64).sqrt();
            let (mut seen, mut occluded, mut wrong) = (0.0, 0.0, 0.0);
            for j in 0..cells.len() {
                let q = cells[j] - viewpoint;
                let cos = -world_normals[j].dot(q) / q.length();
                if cos < 0.2 {
                    continue;
                }
                // the weight the cell has, or would have, in the model
                let weight = areas[j] * cos / q.length_squared();
                let truly_seen = !hidden(cells[j], spacing);
                if truly_seen {
                    seen += weight;
                } else {
                    occluded += weight;
                }
                if truly_seen != view.visible[j] {
                    wrong += weight;
                }
            }
            // the view is one with occlusion: the test means something
            assert!(
                occluded > 0.05 * seen,
                "grid {rings}x{sectors}: occluded {occluded}"
            );
            assert!(
                wrong < 0.01 * seen,
                "grid {rings}x{sectors}: {:.2}% of the seen weight misjudged",
                100.0 * wrong / seen
            );
        }
    }

    #[test]
    fn the_grid_is_kept_unless_too_coarse_or_much_too_fine() {
        // sigma moved the ideal grid by a ring or a few sectors: the grid stays
        assert_eq!(regrid((40, 200), (39, 196)), (40, 200));
        assert_eq!(regrid((40, 200), (37, 182)), (40, 200));
        // coarser than the ideal in either direction: the ideal
        assert_eq!(regrid((40, 200), (41, 190)), (41, 190));
        assert_eq!(regrid((40, 200), (38, 201)), (38, 201));
        // more than 10% finer: the ideal
        assert_eq!(regrid((40, 200), (36, 190)), (36, 190));
        assert_eq!(regrid((40, 200), (39, 180)), (39, 180));
    }

    #[test]
    fn the_gradient_matches_differences_of_the_likelihood() {
        gradient_matches_differences(None);
    }

    /// Seen from a viewpoint the cells' weights (cos(incidence) / range²) move with the
    /// pose as well as the shape.
    #[test]
    fn the_gradient_seen_from_a_viewpoint_matches_differences() {
        gradient_matches_differences(Some(DVec3::new(0.9, -1.4, 1.1)));
    }

    fn gradient_matches_differences(viewpoint: Option<DVec3>) {
        let shape = Shape::new(0.3, 0.25, 0.12, 2.0, 0.7, 1.3);
        let pose = Pose::new(
            DQuat::from_scaled_axis(DVec3::new(0.3, -0.2, 0.5)),
            DVec3::new(0.05, -0.02, 0.1),
        );
        let mut rng = crate::synth::rng(7);
        let mut points = crate::synth::sample_surface(&shape, &pose, 400, &mut rng);
        crate::synth::add_noise(&mut points, 0.03, &mut rng);
        let problem = Problem {
            points: &points,
            outlier_weight: 0.05,
            outlier_density: 0.05 / 8.0,
            rotation0: pose.rotation,
            grid: grid_for(&shape.to_array(), 0.03, CELL_SIGMAS),
            sight: viewpoint.map(Sight::at),
            cutoff: CUTOFF,
            section_cell_sigmas: CELL_SIGMAS,
        };
        let x = Vector::from_column_slice(&[
            0.31,
            0.24,
            0.13,
            2.05,
            0.75,
            1.25,
            0.06,
            -0.03,
            0.1,
            0.0,
            0.0,
            0.0,
            0.035f64.ln(),
        ]);
        let (_, gradient, _) = problem.evaluate(&x, true);
        for k in 0..N {
            let h = 1e-6;
            let (mut up, mut down) = (x, x);
            up[k] += h;
            down[k] -= h;
            let numeric =
                (problem.evaluate(&up, false).0 - problem.evaluate(&down, false).0) / (2.0 * h);
            assert!(
                (numeric - gradient[k]).abs()
                    < 1e-4 * (1.0 + numeric.abs()) * (1.0 + numeric.abs()),
                "parameter {k}: analytic {} numeric {numeric}",
                gradient[k]
            );
        }
    }
}

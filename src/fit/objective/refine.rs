//! The maximum-likelihood fit: Levenberg-Marquardt on the BHHH Hessian (the outer
//! product of the points' scores, the Fisher information near the optimum), within the
//! shape's box, what the caller knows held fixed.

use super::tables::Grid;
use super::{Data, Matrix, Objective, PARAMETERS, Vector, parameters};
use crate::eval::Candidate;
use crate::solve::Bounds;

/// What the caller holds fixed and where the shape may go.
#[derive(Clone, Copy, Debug)]
pub struct Limits {
    pub bounds: Bounds,
    /// shape parameters held at their starting values (the caller's known dimensions)
    pub fixed_shape: [bool; 6],
    /// the hole axis is known: the rotation may only turn about it
    pub fixed_axis: bool,
}

/// The refined candidate and sigma (normalised units), the iterations taken, and the
/// objective there.
#[derive(Clone, Copy, Debug)]
pub struct Refined {
    pub candidate: Candidate,
    pub sigma: f64,
    pub iterations: usize,
    pub objective: f64,
}

/// Two steps in a row that lower the objective by less than this end the refinement.
pub const STOP_DECREASE: f64 = 1e-4;

/// Maximises the likelihood from `start` and `sigma` by Levenberg-Marquardt on the BHHH
/// Hessian, at most `max_iterations` steps.
pub fn refine(
    data: &Data,
    start: &Candidate,
    sigma: f64,
    limits: &Limits,
    max_iterations: usize,
) -> Refined {
    refine_on(
        data,
        start,
        sigma,
        limits,
        max_iterations,
        super::normaliser::FINE,
    )
}

/// [`refine`] with the normaliser on `area_grid` ([`super::normaliser::COARSE`]: a
/// quarter of its cost, for a few steps that rank candidates).
pub fn refine_on(
    data: &Data,
    start: &Candidate,
    sigma: f64,
    limits: &Limits,
    max_iterations: usize,
    area_grid: (usize, usize),
) -> Refined {
    let mut objective = Objective {
        area_grid,
        ..Objective::new(data, start, sigma)
    };
    let mut x = parameters(start, sigma);
    objective.hold(&x);
    let axis = start.pose.axis();
    let mut free = [true; PARAMETERS];
    for k in 0..6 {
        free[k] = !limits.fixed_shape[k];
    }
    let b = &limits.bounds;
    // the step is projected into the box (the topology held too: a hole, a4 > 1, or
    // none, the section closing on the axis, whose quadrature is another)
    let holed = start.shape.a4 > 1.0;
    let project = |mut x: Vector| {
        for k in 0..6 {
            let margin = 1e-3 * (b.upper[k] - b.lower[k]);
            x[k] = x[k].clamp(
                b.lower[k] + margin.min(0.5 * b.lower[k].max(1e-9)),
                b.upper[k] - margin,
            );
        }
        x[3] = if holed {
            x[3].max(1.01)
        } else {
            x[3].min(0.99)
        };
        x[12] = x[12].clamp((1e-3 * sigma).ln(), (1e2 * sigma).ln());
        x
    };
    // with a known axis the turn is theta about it alone
    let reduction = limits.fixed_axis.then(|| {
        let mut map = Matrix::identity();
        for k in 9..12 {
            map[(k, k)] = 0.0;
        }
        for (k, a) in axis.to_array().into_iter().enumerate() {
            map[(9 + k, 9)] = a;
        }
        free[10] = false;
        free[11] = false;
        map
    });
    let solve_step = |g: &Vector, h: &Matrix, lambda: f64| -> Option<Vector> {
        match &reduction {
            Some(map) => {
                let step = lm_solve(
                    &(map.transpose() * g),
                    &(map.transpose() * h * map),
                    lambda,
                    &free,
                )?;
                Some(map * step)
            }
            None => lm_solve(g, h, lambda, &free),
        }
    };
    let (mut f, mut g, mut h) = objective.evaluate(&x, true);
    let mut lambda = 1e-3;
    let mut iterations = 0;
    let mut small_steps = 0;
    while iterations < max_iterations {
        iterations += 1;
        let Some(step) = solve_step(&g, &h, lambda) else {
            break;
        };
        let trial = project(x + step);
        let step = trial - x;
        let f_trial = objective.evaluate(&trial, false).0;
        if f_trial < f {
            let decrease = f - f_trial;
            x = trial;
            objective.rotation0 = objective.rotation(&x).normalize();
            x[9] = 0.0;
            x[10] = 0.0;
            x[11] = 0.0;
            objective.grid = Grid::for_shape(&Objective::shape(&x), x[12].exp());
            objective.hold(&x);
            (f, g, h) = objective.evaluate(&x, true);
            lambda = (lambda / 3.0).max(1e-9);
            small_steps = if decrease < STOP_DECREASE {
                small_steps + 1
            } else {
                0
            };
            if small_steps >= 2 || step.norm() < 1e-7 {
                break;
            }
        } else {
            lambda *= 4.0;
            if lambda > 1e6 {
                break;
            }
        }
    }
    Refined {
        candidate: objective.candidate(&x),
        sigma: x[12].exp(),
        iterations,
        objective: f,
    }
}

/// The objective at a candidate and sigma, without a gradient, its normaliser on the
/// fine grid (as [`refine`] reports it).
pub fn value(data: &Data, candidate: &Candidate, sigma: f64) -> f64 {
    value_on(data, candidate, sigma, super::normaliser::FINE)
}

/// [`value`] with the normaliser on `area_grid` ([`super::normaliser::COARSE`] ranks
/// candidates at a quarter of the cost).
pub fn value_on(data: &Data, candidate: &Candidate, sigma: f64, area_grid: (usize, usize)) -> f64 {
    let objective = Objective {
        area_grid,
        ..Objective::new(data, candidate, sigma)
    };
    objective.evaluate(&parameters(candidate, sigma), false).0
}

/// (H + lambda diag H) step = -g over the free parameters (the others do not move).
fn lm_solve(g: &Vector, h: &Matrix, lambda: f64, free: &[bool; PARAMETERS]) -> Option<Vector> {
    let mut a = *h;
    let mut b = -*g;
    for k in 0..PARAMETERS {
        if free[k] {
            a[(k, k)] += lambda * h[(k, k)].max(1e-12);
        } else {
            for j in 0..PARAMETERS {
                a[(k, j)] = 0.0;
                a[(j, k)] = 0.0;
            }
            a[(k, k)] = 1.0;
            b[k] = 0.0;
        }
    }
    let step = a.cholesky()?.solve(&b);
    step.iter().all(|v| v.is_finite()).then_some(step)
}

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
pub const STOP_DECREASE: f64 = 2e-5;

/// Maximises the likelihood from `start` and `sigma` by Levenberg-Marquardt on the BHHH
/// Hessian, at most `max_iterations` steps.
pub fn refine(
    data: &Data,
    start: &Candidate,
    sigma: f64,
    limits: &Limits,
    max_iterations: usize,
) -> Refined {
    let mut objective = Objective::new(data, start, sigma);
    let mut x = parameters(start, sigma);
    let axis = start.pose.axis();
    let mut free = [true; PARAMETERS];
    for k in 0..6 {
        free[k] = !limits.fixed_shape[k];
    }
    let b = &limits.bounds;
    let feasible = |x: &Vector| {
        (0..6).all(|k| x[k] > b.lower[k] && x[k] < b.upper[k])
            && x[12] > (1e-3 * sigma).ln()
            && x[12] < (1e2 * sigma).ln()
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
        let trial = x + step;
        let f_trial = if feasible(&trial) {
            objective.evaluate(&trial, false).0
        } else {
            f64::INFINITY
        };
        if f_trial < f {
            let decrease = f - f_trial;
            x = trial;
            objective.rotation0 = objective.rotation(&x).normalize();
            x[9] = 0.0;
            x[10] = 0.0;
            x[11] = 0.0;
            objective.grid = Grid::for_shape(&Objective::shape(&x), x[12].exp());
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

/// The objective at a candidate and sigma, without a gradient.
pub fn value(data: &Data, candidate: &Candidate, sigma: f64) -> f64 {
    let objective = Objective::new(data, candidate, sigma);
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

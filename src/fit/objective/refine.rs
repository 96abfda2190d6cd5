//! The maximum-likelihood fit: Levenberg-Marquardt on the BHHH Hessian (the outer
//! product of the points' scores, the Fisher information near the optimum), within the
//! shape's box, what the caller knows held fixed.

use super::tables::Grid;
use super::{Data, Matrix, Objective, PARAMETERS, Vector, parameters};
use crate::eval::Candidate;
use crate::solve::Bounds;
use crate::solve::likelihood::{Held, LikelihoodProblem, Stopping, fold_turn, minimise};

/// What the caller holds fixed and where the shape may go (both noise models'
/// refinements take it).
#[derive(Clone, Copy, Debug)]
pub struct Limits {
    pub bounds: Bounds,
    /// shape parameters held at their starting values (the caller's known dimensions)
    pub fixed_shape: [bool; 6],
    /// the hole axis is known: the rotation may only turn about it
    pub fixed_axis: bool,
    /// no step is taken past this time ([`crate::fit::FitOptions::time_budget_ms`])
    pub deadline: Option<std::time::Instant>,
}

impl Limits {
    /// What the solver holds, refining from `start`: the known shape parameters, and
    /// with a known axis every turn but the one about the start's axis.
    pub(crate) fn held(&self, start: &Candidate) -> Held {
        let mut parameters = [false; PARAMETERS];
        parameters[..6].copy_from_slice(&self.fixed_shape);
        Held {
            parameters,
            axis: self.fixed_axis.then(|| start.pose.axis()),
        }
    }
}

/// The refined candidate and sigma (normalised units), the iterations taken, and the
/// objective there: the negative mean log-likelihood of the points (lower is better;
/// comparable between refinements of the same points).
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
        STOP_DECREASE,
    )
}

/// [`refine`] with the normaliser on `area_grid` ([`super::normaliser::COARSE`]: a
/// quarter of its cost, for a few steps that rank candidates), ended by two steps in a
/// row that lower the objective by less than `decrease` (nats a point; [`STOP_DECREASE`]
/// unless the caller has reason for another).
pub fn refine_on(
    data: &Data,
    start: &Candidate,
    sigma: f64,
    limits: &Limits,
    max_iterations: usize,
    area_grid: (usize, usize),
    decrease: f64,
) -> Refined {
    let mut objective = Objective {
        area_grid,
        ..Objective::new(data, start, sigma)
    };
    let x = parameters(start, sigma);
    objective.hold(&x);
    let mut problem = Boxed {
        objective,
        bounds: limits.bounds,
        sigma,
        holed: start.shape.a4 > 1.0,
        previous: None,
    };
    let stopping = Stopping {
        max_iterations,
        decrease,
        step: 1e-7,
        // (candidates are ranked by their values here: each is refined on to the
        // decrease test, not stopped a standard error short)
        predicted: 0.0,
        deadline: limits.deadline,
    };
    let minimum = minimise(&mut problem, x, &limits.held(start), &stopping);
    Refined {
        candidate: problem.objective.candidate(&minimum.x),
        sigma: minimum.x[12].exp(),
        iterations: minimum.iterations,
        objective: minimum.value,
    }
}

/// The objective within the shape's box: a step is projected into it, the topology held
/// too (a hole, a4 > 1, or none, the section closing on the axis, whose quadrature is
/// another).
struct Boxed<'a> {
    objective: Objective<'a>,
    bounds: Bounds,
    sigma: f64,
    holed: bool,
    /// the reference before the last accepted step: rotation, grid, held visibility
    previous: Option<(glam::DQuat, Grid, Option<Vec<bool>>)>,
}

impl LikelihoodProblem for Boxed<'_> {
    fn evaluate(&self, x: &Vector, with_gradient: bool) -> (f64, Vector, Matrix) {
        self.objective.evaluate(x, with_gradient)
    }

    fn admit(&self, mut x: Vector) -> Option<Vector> {
        let b = &self.bounds;
        for k in 0..6 {
            let margin = 1e-3 * (b.upper[k] - b.lower[k]);
            x[k] = x[k].clamp(
                b.lower[k] + margin.min(0.5 * b.lower[k].max(1e-9)),
                b.upper[k] - margin,
            );
        }
        x[3] = if self.holed {
            x[3].max(1.01)
        } else {
            x[3].min(0.99)
        };
        x[12] = x[12].clamp((1e-3 * self.sigma).ln(), (1e2 * self.sigma).ln());
        Some(x)
    }

    fn accept(&mut self, mut x: Vector) -> (Vector, bool) {
        let objective = &mut self.objective;
        let rotation0 = objective.rotation0;
        objective.rotation0 = fold_turn(&mut x, rotation0);
        let grid = std::mem::replace(
            &mut objective.grid,
            Grid::for_shape(&Objective::shape(&x), x[12].exp()),
        );
        let visible = objective.visible.take();
        objective.hold(&x);
        self.previous = Some((rotation0, grid, visible));
        (x, false)
    }

    fn restore(&mut self) {
        if let Some((rotation0, grid, visible)) = self.previous.take() {
            let o = &mut self.objective;
            (o.rotation0, o.grid, o.visible) = (rotation0, grid, visible);
        }
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

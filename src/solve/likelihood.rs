//! Levenberg-Marquardt for a likelihood: the fit's two noise models (the objective's
//! quadrature and the polish's surface grid) maximise theirs with this one loop. The
//! Hessian is the BHHH outer product of the points' scores (the Fisher information near
//! the optimum), so a problem gives its value, gradient and that product; the loop damps,
//! projects, accepts (or takes a step back) and stops.
//!
//! Parameters (13): shape a1 a2 a3 a4 eps1 eps2, translation, a turn (rotation vector on
//! the left of the problem's reference rotation, world frame), ln sigma. After each
//! accepted step the problem folds the turn into its reference ([`LikelihoodProblem::accept`]),
//! so the turn starts from zero every iteration, as in the least-squares solver.

use glam::{DQuat, DVec3};
use nalgebra::{SMatrix, SVector};

/// The number of parameters (see the module docs).
pub const PARAMETERS: usize = 13;
pub type Vector = SVector<f64, PARAMETERS>;
pub type Matrix = SMatrix<f64, PARAMETERS, PARAMETERS>;

/// A negative mean log-likelihood the loop minimises.
pub trait LikelihoodProblem {
    /// The value at `x`; with `with_gradient` also its gradient and the BHHH Hessian.
    fn evaluate(&self, x: &Vector, with_gradient: bool) -> (f64, Vector, Matrix);
    /// Where a trial point may go: `x` moved into the feasible set, or None where it is
    /// rejected outright.
    fn admit(&self, x: Vector) -> Option<Vector>;
    /// Takes the accepted point `x` as the new reference (the turn folded into the
    /// rotation, the quadrature regridded) and returns it in the new reference's terms,
    /// and whether the problem there is the one `x` was evaluated on (nothing regridded or
    /// held anew), so that the trial's evaluation stands for it.
    fn accept(&mut self, x: Vector) -> (Vector, bool);
    /// Whether trials are evaluated with their gradient: worth it where most accepted
    /// trials' evaluations stand ([`LikelihoodProblem::accept`]), which then spares the
    /// new reference's evaluation, at the cost of a gradient on each rejected trial.
    fn trial_gradients(&self) -> bool {
        false
    }
    /// Goes back to the reference (rotation, grid, held visibility) the last
    /// [`LikelihoodProblem::accept`] left.
    fn restore(&mut self);
}

/// Folds the turn of `x` (parameters 9-11) into `rotation`, the reference it is applied
/// on the left of, and sets it to zero: what a problem's [`LikelihoodProblem::accept`]
/// does with its rotation. Returns the new reference.
pub fn fold_turn(x: &mut Vector, rotation: DQuat) -> DQuat {
    let folded = (DQuat::from_scaled_axis(DVec3::new(x[9], x[10], x[11])) * rotation).normalize();
    x[9] = 0.0;
    x[10] = 0.0;
    x[11] = 0.0;
    folded
}

/// When the loop stops.
#[derive(Clone, Copy, Debug)]
pub struct Stopping {
    pub max_iterations: usize,
    /// two accepted steps in a row that lower the value by less than this
    pub decrease: f64,
    /// an accepted step shorter than this
    pub step: f64,
    /// the decrease the undamped step predicts, g·H⁻¹g / 2 (the quadratic model's way
    /// to its minimum), below which the point is taken as the minimum (0: never)
    pub predicted: f64,
    /// no step is tried past this time (the caller's time budget); None: no limit
    pub deadline: Option<std::time::Instant>,
}

/// What the loop held fixed.
#[derive(Clone, Copy, Debug)]
pub struct Held {
    /// parameters that take no step (the caller's known dimensions)
    pub parameters: [bool; PARAMETERS],
    /// the hole axis is known (world frame): the turn is about it alone
    pub axis: Option<DVec3>,
}

/// The minimum found: the parameters (in the problem's last reference), the value there
/// and the iterations taken.
#[derive(Clone, Copy, Debug)]
pub struct Minimum {
    pub x: Vector,
    pub value: f64,
    pub iterations: usize,
}

/// Minimises `problem` from `x` by Levenberg-Marquardt (damping 1e-3 at the start,
/// scaled by [`accepted_damping_factor`] after an accepted step; after an uphill trial
/// set so that the next step is as long as [`backtracking_fraction`] says, x4 after one
/// outside the feasible set; stopping above 1e6). A step whose value in its own new
/// reference is above the last accepted value counts as rejected, and the problem goes
/// back to the reference it had before ([`LikelihoodProblem::restore`]);
/// [`TAKEN_BACK_IN_A_ROW`] such steps end the loop. It stops too where the undamped step
/// predicts less than [`Stopping::predicted`].
pub fn minimise(
    problem: &mut impl LikelihoodProblem,
    mut x: Vector,
    held: &Held,
    stopping: &Stopping,
) -> Minimum {
    let steps = Steps::new(held);
    let solve_step = |g: &Vector, h: &Matrix, lambda: f64| steps.solve(g, h, lambda);
    let trial_gradients = problem.trial_gradients();
    let (mut f, mut g, mut h) = problem.evaluate(&x, true);
    let at_minimum = |g: &Vector, h: &Matrix| {
        stopping.predicted > 0.0
            && solve_step(g, h, 0.0).is_some_and(|step| -0.5 * g.dot(&step) < stopping.predicted)
    };
    if at_minimum(&g, &h) {
        return Minimum {
            x,
            value: f,
            iterations: 0,
        };
    }
    let mut lambda = 1e-3;
    let mut iterations = 0;
    let mut small_steps = 0;
    let mut taken_back = 0;
    let out_of_time = || {
        stopping
            .deadline
            .is_some_and(|d| std::time::Instant::now() >= d)
    };
    while iterations < stopping.max_iterations && !out_of_time() {
        iterations += 1;
        let Some(step) = solve_step(&g, &h, lambda) else {
            break;
        };
        let trial = problem.admit(x + step);
        let evaluated = trial.map(|t| problem.evaluate(&t, trial_gradients));
        match (trial, evaluated) {
            (Some(trial), Some(evaluated)) if evaluated.0 < f => {
                let decrease = f - evaluated.0;
                let step = trial - x;
                let predicted = -(g.dot(&step) + 0.5 * step.dot(&(h * step)));
                let before = (x, f, g, h);
                let damping_before = lambda;
                let stands;
                (x, stands) = problem.accept(trial);
                lambda = (lambda * accepted_damping_factor(decrease, predicted)).max(1e-9);
                small_steps = if decrease < stopping.decrease {
                    small_steps + 1
                } else {
                    0
                };
                let last = small_steps >= 2
                    || step.norm() < stopping.step
                    || iterations == stopping.max_iterations
                    || out_of_time();
                // (the value in the new reference; a step no one takes needs no gradient)
                (f, g, h) = if stands && (last || trial_gradients) {
                    evaluated
                } else {
                    problem.evaluate(&x, !last)
                };
                // (a step that went downhill only on the old reference's grid and view
                // is no step: the function minimised is the one each point is
                // evaluated on in its own reference)
                if !stands && f > before.1 {
                    problem.restore();
                    (x, f, g, h) = before;
                    lambda = damping_before * 4.0;
                    taken_back += 1;
                    if last || lambda > 1e6 || taken_back == TAKEN_BACK_IN_A_ROW {
                        break;
                    }
                    continue;
                }
                taken_back = 0;
                if last || at_minimum(&g, &h) {
                    break;
                }
            }
            (Some(trial), Some((value, ..))) => {
                let fraction = backtracking_fraction(g.dot(&(trial - x)), value - f);
                // (the step solved at this damping, before any clamping into the bounds)
                let length = fraction * step.norm();
                lambda = damping_for_length(|l| solve_step(&g, &h, l), lambda, length);
                if lambda > 1e6 {
                    break;
                }
            }
            _ => {
                lambda *= 4.0;
                if lambda > 1e6 {
                    break;
                }
            }
        }
    }
    Minimum {
        x,
        value: f,
        iterations,
    }
}

/// The damped step in the parameters that move: those not held, and with a known axis
/// the turn about it alone.
struct Steps {
    free: [bool; PARAMETERS],
    /// with a known axis, the map from the reduced parameters (whose turn is theta about
    /// the axis: column 9 is the axis, 10 and 11 empty) to the full ones
    reduction: Option<Matrix>,
}

impl Steps {
    fn new(held: &Held) -> Self {
        let mut free = held.parameters.map(|h| !h);
        let reduction = held.axis.map(|axis| {
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
        Self { free, reduction }
    }

    /// The step at damping `lambda` from gradient `g` and Hessian `h`; None where the
    /// damped system is singular.
    fn solve(&self, g: &Vector, h: &Matrix, lambda: f64) -> Option<Vector> {
        match &self.reduction {
            Some(map) => {
                let step = damped_step(
                    &(map.transpose() * g),
                    &(map.transpose() * h * map),
                    lambda,
                    &self.free,
                )?;
                Some(map * step)
            }
            None => damped_step(g, h, lambda, &self.free),
        }
    }
}

/// Steps taken back in a row (each downhill on its old reference, uphill on its new one)
/// that end the loop: the point is then a minimum to within what a change of grid or
/// view moves the value, and a smaller step changes little (the damping must grow about
/// tenfold to shorten a step much). Going on instead (up to the iteration cap) changed no
/// fit of suite sets 1700000 and 1710000 (360 single views and full clouds, camera frame,
/// no options) and 124 against 125 of broadened views 4200000 and 4210000 (160); ending
/// here cut the broadened views' mean time by 18-20% and the suite's by 10%.
pub const TAKEN_BACK_IN_A_ROW: usize = 2;

/// The damping's factor after an accepted step, by its gain ratio rho (the decrease it
/// made over the decrease the quadratic model g·s + s·H·s/2 predicted): Nielsen's
/// max(1/3, 1 - (2 rho - 1)^3) (Madsen, Nielsen and Tingleff, *Methods for non-linear
/// least squares problems*, 2004, §3.2). A step that made at least what the model
/// predicted (rho >= 1) cuts the damping by 3, one that made half of it keeps it, one
/// that made little of it raises it up to twice: the BHHH Hessian is rough away from the
/// optimum, and cutting by 3 after every accepted step made about every second trial a
/// rejected one (measured in `docs/fit.md`).
fn accepted_damping_factor(decrease: f64, predicted: f64) -> f64 {
    if !(predicted > 0.0) {
        return 1.0 / 3.0;
    }
    let rho = decrease / predicted;
    (1.0 - (2.0 * rho - 1.0).powi(3)).max(1.0 / 3.0)
}

/// How much of an uphill trial's step the next one takes: the minimum of the parabola
/// through the value, its `slope` along the step (g·s) and the trial's `rise` above it,
/// within [`BACKTRACKING_FRACTIONS`]. The BHHH Hessian underrates some curvatures (on a
/// scene object's polish the value's minimum along the undamped step lay at a quarter of
/// it), and raising the damping fourfold a trial took up to seven uphill trials,
/// each a whole evaluation, to shorten a step enough: a refinement screened after five
/// iterations (the polish's other reading of a top view) could spend all five there and
/// be dropped unmoved (`docs/fit.md`).
fn backtracking_fraction(slope: f64, rise: f64) -> f64 {
    let (shortest, longest) = BACKTRACKING_FRACTIONS;
    let curvature = rise - slope;
    if slope < 0.0 && curvature > 0.0 {
        (-slope / (2.0 * curvature)).clamp(shortest, longest)
    } else {
        longest
    }
}

/// The shortest and longest share of an uphill trial's step that the next trial takes:
/// a backtracking line search's safeguards (Nocedal and Wright, *Numerical
/// Optimization*, §3.5), so that a parabola fitted to a rough value neither stalls the
/// loop nor retries nearly the same step.
pub const BACKTRACKING_FRACTIONS: (f64, f64) = (0.1, 0.5);

/// The damping above `lambda` at which the step `step_at(damping)` is `length` long, by
/// bisection on its logarithm up to 1e6 (where the loop stops). A damped step's length
/// falls monotonically with the damping, and a 13x13 solve costs microseconds against
/// an evaluation's milliseconds.
fn damping_for_length(step_at: impl Fn(f64) -> Option<Vector>, lambda: f64, length: f64) -> f64 {
    // (the upper end lies past 1e6: a length no damping up to there reaches comes back
    // over 1e6, and the caller stops)
    let (mut low, mut high) = (lambda.max(1e-9).ln(), 1e6f64.ln() + 1.0);
    for _ in 0..30 {
        let middle = 0.5 * (low + high);
        match step_at(middle.exp()) {
            Some(s) if s.norm() > length => low = middle,
            _ => high = middle,
        }
    }
    high.exp()
}

/// (H + lambda diag H) step = -g over the free parameters (the others do not move).
fn damped_step(g: &Vector, h: &Matrix, lambda: f64, free: &[bool; PARAMETERS]) -> Option<Vector> {
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A Gaussian's negative mean log-likelihood in 13 independent parameters centred
    /// at `centre`: its minimum is the centre, its BHHH Hessian the identity.
    /// With `trials`, its trials are evaluated with their gradient, whose evaluations
    /// stand; it counts its evaluations with and without a gradient.
    struct Bowl {
        centre: Vector,
        lower: f64,
        trials: bool,
        evaluations: std::cell::Cell<[usize; 2]>,
    }

    impl Bowl {
        fn new(centre: Vector, lower: f64) -> Self {
            Self {
                centre,
                lower,
                trials: false,
                evaluations: Default::default(),
            }
        }
    }

    impl LikelihoodProblem for Bowl {
        fn evaluate(&self, x: &Vector, with_gradient: bool) -> (f64, Vector, Matrix) {
            let mut counts = self.evaluations.get();
            counts[usize::from(with_gradient)] += 1;
            self.evaluations.set(counts);
            let d = x - self.centre;
            (0.5 * d.norm_squared(), d, Matrix::identity())
        }
        fn admit(&self, x: Vector) -> Option<Vector> {
            Some(x.map(|v| v.max(self.lower)))
        }
        fn accept(&mut self, x: Vector) -> (Vector, bool) {
            (x, self.trials)
        }
        fn trial_gradients(&self) -> bool {
            self.trials
        }
        // (accepting a point never changes the bowl)
        fn restore(&mut self) {}
    }

    /// A bowl whose reference moves on every accepted step longer than `threshold` (as
    /// a quadrature regrids): its centre shifts by `drift`, so such a step lands worse
    /// than it started once its new reference is evaluated.
    struct DriftingBowl {
        bowl: Bowl,
        drift: Vector,
        threshold: f64,
        last: Vector,
        previous: Option<(Vector, Vector)>,
    }

    impl DriftingBowl {
        /// Centred at the origin, at `start`, drifting by 3 in every parameter.
        fn starting_at(start: Vector, threshold: f64) -> Self {
            Self {
                bowl: Bowl::new(Vector::zeros(), -10.0),
                drift: Vector::from_element(3.0),
                threshold,
                last: start,
                previous: None,
            }
        }
    }

    fn nothing_held() -> Held {
        Held {
            parameters: [false; PARAMETERS],
            axis: None,
        }
    }

    impl LikelihoodProblem for DriftingBowl {
        fn evaluate(&self, x: &Vector, with_gradient: bool) -> (f64, Vector, Matrix) {
            self.bowl.evaluate(x, with_gradient)
        }
        fn admit(&self, x: Vector) -> Option<Vector> {
            self.bowl.admit(x)
        }
        fn accept(&mut self, x: Vector) -> (Vector, bool) {
            self.previous = Some((self.bowl.centre, self.last));
            let moved = (x - self.last).norm() > self.threshold;
            if moved {
                self.bowl.centre += self.drift;
            }
            self.last = x;
            (x, !moved)
        }
        fn restore(&mut self) {
            (self.bowl.centre, self.last) = self.previous.take().unwrap();
        }
    }

    /// Every full step here moves the bowl's centre away (a grid or view that changes
    /// under a long step): the steps are taken back, and two in a row end the loop where
    /// it started, the centre never moved.
    #[test]
    fn steps_whose_new_reference_is_worse_are_taken_back_and_two_in_a_row_end_the_loop() {
        let start = Vector::from_element(1.0);
        let mut drifting = DriftingBowl::starting_at(start, 0.5);
        let minimum = minimise(&mut drifting, start, &nothing_held(), &stopping());
        assert_eq!(drifting.bowl.centre, Vector::zeros());
        assert_eq!(minimum.x, start);
        assert_eq!(minimum.iterations, TAKEN_BACK_IN_A_ROW, "{minimum:?}");
    }

    /// A step taken back between two that stand does not end the loop: the bowl moves
    /// only on the first long step, and the shorter steps after reach its minimum.
    #[test]
    fn one_step_taken_back_does_not_end_the_loop() {
        let start = Vector::from_element(1.0);
        // (the first step, damped by 1e-3, is 3.602 long and moves the centre; the second,
        // damped fourfold more, is 3.591)
        let mut drifting = DriftingBowl::starting_at(start, 3.595);
        let minimum = minimise(&mut drifting, start, &nothing_held(), &stopping());
        assert_eq!(drifting.bowl.centre, Vector::zeros());
        assert!(minimum.x.norm() < 1e-6, "{minimum:?}");
    }

    #[test]
    fn the_damping_falls_after_a_well_predicted_step_and_rises_after_a_poor_one() {
        let factor = |rho: f64| accepted_damping_factor(rho, 1.0);
        assert!((factor(1.0) - 1.0 / 3.0).abs() < 1e-12);
        assert!((factor(2.0) - 1.0 / 3.0).abs() < 1e-12);
        assert!((factor(0.5) - 1.0).abs() < 1e-12);
        assert!((factor(0.0) - 2.0).abs() < 1e-12);
        // (no predicted decrease to measure against: the plain cut)
        assert!((accepted_damping_factor(0.1, 0.0) - 1.0 / 3.0).abs() < 1e-12);
    }

    /// A bowl whose reported Hessian is a quarter of its curvature (as a BHHH product can
    /// be, away from the optimum), logging each evaluation's gradient flag.
    struct Underestimated {
        log: std::cell::RefCell<Vec<bool>>,
    }

    impl LikelihoodProblem for Underestimated {
        fn evaluate(&self, x: &Vector, with_gradient: bool) -> (f64, Vector, Matrix) {
            self.log.borrow_mut().push(with_gradient);
            (0.5 * x.norm_squared(), *x, 0.25 * Matrix::identity())
        }
        fn admit(&self, x: Vector) -> Option<Vector> {
            Some(x)
        }
        fn accept(&mut self, x: Vector) -> (Vector, bool) {
            (x, false)
        }
        fn restore(&mut self) {}
    }

    /// Once the damping has grown enough for a first step to be accepted, it stays
    /// there: no later trial is rejected (each trial is evaluated without a gradient and,
    /// accepted, followed by the new point's evaluation with one). Cutting the damping by
    /// 3 after every accepted step, every second trial here was a rejected one.
    #[test]
    fn a_rough_hessian_costs_rejected_trials_only_before_the_first_accepted_step() {
        let mut problem = Underestimated {
            log: Default::default(),
        };
        let held = Held {
            parameters: [false; PARAMETERS],
            axis: None,
        };
        let minimum = minimise(&mut problem, Vector::from_element(1.0), &held, &stopping());
        assert!(minimum.x.norm() < 1e-5, "{minimum:?}");
        let log = problem.log.into_inner();
        let first_accepted = log[1..].iter().position(|&g| g).expect("an accepted step") + 1;
        // (the last accepted point is evaluated without a gradient: it ends the loop)
        let later_rejections = log[first_accepted..log.len() - 1]
            .windows(2)
            .filter(|w| !w[0] && !w[1])
            .count();
        assert_eq!(later_rejections, 0, "{log:?}");
    }

    /// Where the undamped step overshoots (the Hessian a quarter of the curvature: it
    /// lands at -3x), the trial after it is the parabola's minimum, the bowl's centre:
    /// one uphill trial, not the five a fourfold damping took to halve the step.
    #[test]
    fn an_uphill_trial_is_followed_by_the_step_to_the_minimum_of_its_parabola() {
        let mut problem = Underestimated {
            log: Default::default(),
        };
        let minimum = minimise(
            &mut problem,
            Vector::from_element(1.0),
            &nothing_held(),
            &stopping(),
        );
        assert!(minimum.x.norm() < 1e-6, "{minimum:?}");
        // (the uphill trial, the step to the centre, two steps too small to go on)
        assert_eq!(minimum.iterations, 4, "{minimum:?}");
        assert!((backtracking_fraction(-4.0, 4.0) - 0.25).abs() < 1e-12);
        // (a trial that rose far: the step shrinks tenfold at most; no slope: halved)
        assert_eq!(backtracking_fraction(-1.0, 1e3), 0.1);
        assert_eq!(backtracking_fraction(0.0, 1.0), 0.5);
    }

    fn stopping() -> Stopping {
        Stopping {
            deadline: None,
            max_iterations: 100,
            decrease: 1e-12,
            step: 1e-12,
            predicted: 0.0,
        }
    }

    /// A deadline already passed takes no step: the start comes back as it was, with its
    /// value; no deadline, the same start goes on to the centre.
    #[test]
    fn a_deadline_passed_takes_no_step() {
        let start = Vector::from_element(0.1);
        let spent = Stopping {
            deadline: Some(std::time::Instant::now()),
            ..stopping()
        };
        let stopped = minimise(
            &mut Bowl::new(Vector::zeros(), -10.0),
            start,
            &nothing_held(),
            &spent,
        );
        assert_eq!(stopped.iterations, 0, "{stopped:?}");
        assert_eq!(stopped.x, start);
        let free = minimise(
            &mut Bowl::new(Vector::zeros(), -10.0),
            start,
            &nothing_held(),
            &stopping(),
        );
        assert!(free.x.norm() < 1e-6, "{free:?}");
    }

    /// The bowl's undamped step predicts |x - centre|² / 2: a start predicting less than
    /// `predicted` takes no step, one predicting more ends its steps within it.
    #[test]
    fn it_stops_where_the_undamped_step_predicts_less_than_asked() {
        let held = nothing_held();
        let start = Vector::from_element(0.1); // predicts 13 * 0.01 / 2 = 0.065
        let asking = |predicted| Stopping {
            predicted,
            ..stopping()
        };
        let near = minimise(
            &mut Bowl::new(Vector::zeros(), -10.0),
            start,
            &held,
            &asking(0.07),
        );
        assert_eq!((near.iterations, near.x), (0, start));
        let far = minimise(
            &mut Bowl::new(Vector::zeros(), -10.0),
            start,
            &held,
            &asking(1e-4),
        );
        assert!(far.iterations > 0);
        assert!(0.5 * far.x.norm_squared() < 1e-4, "{far:?}");
        assert!(
            far.iterations
                < minimise(
                    &mut Bowl::new(Vector::zeros(), -10.0),
                    start,
                    &held,
                    &stopping()
                )
                .iterations
        );
    }

    #[test]
    fn it_reaches_the_minimum_and_leaves_held_parameters_alone() {
        let centre = Vector::from_fn(|k, _| k as f64 * 0.1);
        let mut bowl = Bowl::new(centre, -10.0);
        let mut held = [false; PARAMETERS];
        held[2] = true;
        let minimum = minimise(
            &mut bowl,
            Vector::from_element(1.0),
            &Held {
                parameters: held,
                axis: None,
            },
            &stopping(),
        );
        for k in 0..PARAMETERS {
            let expected = if k == 2 { 1.0 } else { centre[k] };
            assert!(
                (minimum.x[k] - expected).abs() < 1e-6,
                "{k}: {}",
                minimum.x[k]
            );
        }
    }

    #[test]
    fn a_known_axis_turns_the_fit_about_it_alone() {
        let centre = Vector::from_fn(|k, _| if (9..12).contains(&k) { 0.3 } else { 0.0 });
        let mut bowl = Bowl::new(centre, -10.0);
        let minimum = minimise(
            &mut bowl,
            Vector::zeros(),
            &Held {
                parameters: [false; PARAMETERS],
                axis: Some(DVec3::Z),
            },
            &stopping(),
        );
        assert!(minimum.x[9].abs() < 1e-9 && minimum.x[10].abs() < 1e-9);
        assert!((minimum.x[11] - 0.3).abs() < 1e-6, "{}", minimum.x[11]);
    }

    #[test]
    fn a_step_is_projected_where_the_problem_says() {
        let centre = Vector::from_element(-1.0);
        let mut bowl = Bowl::new(centre, 0.0);
        let minimum = minimise(
            &mut bowl,
            Vector::from_element(1.0),
            &Held {
                parameters: [false; PARAMETERS],
                axis: None,
            },
            &stopping(),
        );
        assert!(
            minimum.x.iter().all(|v| (v - 0.0).abs() < 1e-9),
            "{minimum:?}"
        );
    }

    #[test]
    fn a_trials_evaluation_stands_where_the_problem_says_and_the_last_needs_no_gradient() {
        let centre = Vector::from_fn(|k, _| k as f64 * 0.1);
        let held = Held {
            parameters: [false; PARAMETERS],
            axis: None,
        };
        let mut minima = Vec::new();
        for trials in [false, true] {
            let mut bowl = Bowl::new(centre, -10.0);
            bowl.trials = trials;
            let minimum = minimise(&mut bowl, Vector::from_element(1.0), &held, &stopping());
            assert!((minimum.x - centre).norm() < 1e-6, "{minimum:?}");
            minima.push((minimum.iterations, bowl.evaluations.get()));
        }
        let [
            (iterations, [values, gradients]),
            (iterations_t, [values_t, gradients_t]),
        ] = minima[..]
        else {
            unreachable!()
        };
        // one gradient per step taken and none after the last; each trial a value
        assert_eq!(gradients, iterations);
        assert_eq!(values, iterations + 1);
        // with standing trials: the first point and each trial, all with a gradient
        assert_eq!((values_t, gradients_t), (0, iterations_t + 1));
    }
}

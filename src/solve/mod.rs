//! Primal-dual interior-point method for bound-constrained (robust) nonlinear least
//! squares over the 12 supertoroid parameters, run for a batch of starts in lockstep so
//! that every iteration is one batched evaluator call.
//!
//! Per start: Gauss-Newton model H = JtWJ from the evaluator's normal equations,
//! log-barrier on the shape bounds with dual variables z (z_l·(x - l) = mu on the
//! central path), Levenberg-Marquardt damping for global convergence (a trial step is
//! accepted only if the barrier merit decreases, else the damping grows), the
//! fraction-to-boundary rule so iterates stay strictly inside, and the rotation updated
//! on the manifold (R <- R·exp(\[d\]x), the increment starting from 0 every iteration).
//! A trial step is evaluated with its normal equations, not its cost alone: when it is
//! taken (most are), they are the next iteration's model, so an iteration costs one
//! evaluator call (one GPU round trip) instead of two. Measured on the paper's clouds
//! (criterion, CPU): 15-25% faster fits, the same fits.

pub mod likelihood;

use crate::eval::{Candidate, EvalError, Evaluator, Loss, NUM_PARAMS, NormalEquations};
use crate::model::Shape;
use glam::DQuat;
use nalgebra::{SMatrix, SVector};

type Vec12 = SVector<f64, NUM_PARAMS>;
type Mat12 = SMatrix<f64, NUM_PARAMS, NUM_PARAMS>;

/// Box bounds on the six shape parameters (pose parameters are free).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bounds {
    pub lower: [f64; 6],
    pub upper: [f64; 6],
}

impl Bounds {
    /// Sizes in (size_min, size_max), a4 in (0, a4_max), eps in (eps_min, eps_max).
    pub fn new(size_min: f64, size_max: f64, a4_max: f64, eps_min: f64, eps_max: f64) -> Self {
        Self {
            lower: [size_min, size_min, size_min, 0.0, eps_min, eps_min],
            upper: [size_max, size_max, size_max, a4_max, eps_max, eps_max],
        }
    }

    /// Moves a shape strictly inside the bounds (by 1% of each range at least).
    pub fn interior(&self, shape: &Shape) -> Shape {
        let mut v = shape.to_array();
        for i in 0..6 {
            let margin = 0.01 * (self.upper[i] - self.lower[i]);
            // near a small positive lower bound (sizes) keep the value: a thin section's
            // a3 must not be pushed up to a margin of the whole range
            let low_margin = margin.min((0.5 * self.lower[i]).max(1e-6));
            v[i] = v[i].clamp(self.lower[i] + low_margin, self.upper[i] - margin);
        }
        Shape::from_array(v)
    }
}

/// Solver settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SolverOptions {
    pub max_iterations: usize,
    /// stop when the relative decrease of the cost stays below this (and mu is small)
    pub cost_tolerance: f64,
    /// stop when the step is below this (in the normalised frame)
    pub step_tolerance: f64,
    /// stop when the largest gradient component of the barrier merit is below this
    /// times the cost
    pub gradient_tolerance: f64,
    pub loss: Loss,
    /// linear shape prior: count·Σ w_k·shape_k is added to the cost. A negative weight
    /// on a4 is the paper's stage-2 reward for a wider hole on partial clouds; a positive
    /// weight on a3 favours the thinnest section the data allow.
    pub shape_prior: [f64; 6],
    /// optional mask of parameters held fixed (true = fixed), e.g. a known hole axis
    pub fixed: [bool; NUM_PARAMS],
    /// after this many iterations (0: never), stop every start whose cost exceeds
    /// `prune_ratio` times the best one's: multi-start batches spend their time on the
    /// basins that can still win
    pub prune_after: usize,
    pub prune_ratio: f64,
    /// when two running starts of one point set (and one box) come this close (largest
    /// difference of a shape parameter, of a translation component, and rotation angle
    /// in radians; 0: never), the one with the higher cost stops and takes the other's
    /// solution: multi-start batches often send several starts into one basin
    pub merge_tolerance: f64,
}

impl Default for SolverOptions {
    fn default() -> Self {
        Self {
            max_iterations: 60,
            cost_tolerance: 1e-7,
            step_tolerance: 1e-8,
            gradient_tolerance: 1e-9,
            loss: Loss::Squared,
            shape_prior: [0.0; 6],
            fixed: [false; NUM_PARAMS],
            prune_after: 0,
            prune_ratio: 2.0,
            merge_tolerance: 0.0,
        }
    }
}

/// Why a start stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Stop {
    CostChange,
    SmallStep,
    SmallGradient,
    IterationCap,
    NoProgress,
    /// dropped from a batch because its cost was far above the best start's
    Pruned,
    /// met another start of its batch (see [`SolverOptions::merge_tolerance`]) and
    /// reports that start's solution
    Merged,
}

/// One line of the iteration log.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LogLine {
    pub iteration: usize,
    pub cost: f64,
    pub mu: f64,
    pub damping: f64,
    pub step: f64,
}

#[derive(Clone, Debug)]
pub struct Solution {
    pub candidate: Candidate,
    /// sum of rho(r) at the solution (without barrier or reward terms)
    pub cost: f64,
    pub count: u64,
    pub iterations: usize,
    pub stop: Stop,
    pub log: Vec<LogLine>,
}

struct State {
    c: Candidate,
    bounds: Bounds,
    /// the normal equations at `c` (its cost and point count among them)
    normal: NormalEquations,
    z_lower: [f64; 6],
    z_upper: [f64; 6],
    mu: f64,
    damping: f64,
    iterations: usize,
    small_changes: usize,
    stop: Option<Stop>,
    log: Vec<LogLine>,
}

fn barrier(shape: &Shape, b: &Bounds, mu: f64) -> f64 {
    let v = shape.to_array();
    (0..6)
        .map(|i| -mu * ((v[i] - b.lower[i]).ln() + (b.upper[i] - v[i]).ln()))
        .sum()
}

fn merit(cost: f64, count: u64, shape: &Shape, b: &Bounds, mu: f64, o: &SolverOptions) -> f64 {
    let prior: f64 = shape
        .to_array()
        .iter()
        .zip(&o.shape_prior)
        .map(|(v, w)| v * w)
        .sum();
    cost + prior * count as f64 + barrier(shape, b, mu)
}

/// A parameter whose curvature (its diagonal of JᵀJ) is below this share of the largest
/// is one the points do not see: a symmetry of the candidate, such as a round top view
/// turned about its hole axis (every start with a1 = a2 and eps2 = 1). Its gradient is
/// then rounding, and rounding over rounding is any step: the GPU evaluator's f32 sums
/// turned such starts by up to 4.5e4 radians where the CPU's f64 turned them by 4e-3,
/// and the two backends' fits went to different basins. Rounding puts those curvatures at
/// 1e-30 (f64) to 1e-15 (f32) of the largest; a top view 1% off round has one of order
/// (1%)², 1e-4.
const UNSEEN_CURVATURE: f64 = 1e-8;

/// The parameters the points do not see ([`UNSEEN_CURVATURE`]): they take no step in this
/// iteration, as held ones, and move again once the others break the symmetry.
fn unseen_directions(jtj: &[[f64; NUM_PARAMS]; NUM_PARAMS]) -> [bool; NUM_PARAMS] {
    let largest = (0..NUM_PARAMS).map(|k| jtj[k][k]).fold(0.0, f64::max);
    std::array::from_fn(|k| jtj[k][k] < UNSEEN_CURVATURE * largest)
}

/// Applies a parameter step: shape and translation additively, rotation on the manifold.
pub fn apply_step(c: &Candidate, step: &[f64; NUM_PARAMS]) -> Candidate {
    let mut shape = c.shape.to_array();
    for i in 0..6 {
        shape[i] += step[i];
    }
    let mut pose = c.pose;
    pose.translation += glam::DVec3::new(step[6], step[7], step[8]);
    pose.rotation = (pose.rotation
        * DQuat::from_scaled_axis(glam::DVec3::new(step[9], step[10], step[11])))
    .normalize();
    Candidate {
        shape: Shape::from_array(shape),
        pose,
    }
}

/// Solves from every start (batched through the evaluator, all on point set 0) and
/// returns one solution per start.
pub fn solve(
    evaluator: &mut dyn Evaluator,
    starts: &[Candidate],
    bounds: &Bounds,
    o: &SolverOptions,
) -> Result<Vec<Solution>, EvalError> {
    solve_on(
        evaluator,
        starts,
        &vec![0; starts.len()],
        &vec![*bounds; starts.len()],
        o,
    )
}

/// Solves from every start, start k on the evaluator's point set `sets[k]`: the starts of
/// several clouds in lockstep, one batched evaluator call per iteration for all of them.
/// Starts never interact except through pruning, which compares a start only with the
/// best start of its own set; so each cloud's solutions are the ones `solve` gives it
/// alone (bit for bit on the CPU evaluator). Each start has its own box, `bounds[k]`.
pub fn solve_on(
    evaluator: &mut dyn Evaluator,
    starts: &[Candidate],
    sets: &[usize],
    bounds: &[Bounds],
    o: &SolverOptions,
) -> Result<Vec<Solution>, EvalError> {
    if sets.len() != starts.len() || bounds.len() != starts.len() {
        return Err(EvalError::BadSet(format!(
            "{} set indices and {} bounds for {} starts",
            sets.len(),
            bounds.len(),
            starts.len()
        )));
    }
    // normal equations at every start: each state keeps those of its current iterate, and
    // a trial step is evaluated with its normal equations, which the next iteration reuses
    // when the step is taken (one evaluator call per iteration instead of two)
    let inside: Vec<Candidate> = starts
        .iter()
        .zip(bounds)
        .map(|(s, bounds)| Candidate {
            shape: bounds.interior(&s.shape),
            ..*s
        })
        .collect();
    let first = evaluator.normal_equations_on(&inside, sets, o.loss)?;
    let mut states: Vec<State> = inside
        .into_iter()
        .zip(first)
        .zip(bounds)
        .map(|((c, c0), bounds)| State::at(c, c0, *bounds))
        .collect();
    // for each start stopped by merging, the start it met
    let mut merged_into: Vec<Option<usize>> = vec![None; states.len()];

    for iteration in 0..o.max_iterations {
        if o.prune_after > 0 && iteration == o.prune_after && states.len() > 1 {
            prune(&mut states, sets, o.prune_ratio);
        }
        if o.merge_tolerance > 0.0 {
            merge_close_starts(&mut states, sets, o.merge_tolerance, &mut merged_into);
        }
        let active: Vec<usize> = (0..states.len())
            .filter(|&i| states[i].stop.is_none())
            .collect();
        if active.is_empty() {
            break;
        }
        // Newton systems for every active start, then damping retries until each either
        // finds a decrease of its merit or gives up.
        let mut pending: Vec<(usize, Mat12, Vec12)> = active
            .into_iter()
            .filter_map(|i| newton_system(&mut states[i], o).map(|(h, g)| (i, h, g)))
            .collect();
        let mut tries = 0;
        while !pending.is_empty() && tries < 8 {
            tries += 1;
            let trials: Vec<(Candidate, [f64; NUM_PARAMS])> = pending
                .iter()
                .map(|(i, h, g)| damped_trial(&states[*i], h, g))
                .collect();
            let trial_sets: Vec<usize> = pending.iter().map(|p| sets[p.0]).collect();
            let trial_normals = evaluator.normal_equations_on(
                &trials.iter().map(|t| t.0).collect::<Vec<_>>(),
                &trial_sets,
                o.loss,
            )?;
            let mut still = Vec::new();
            for ((entry, (trial, step)), tc) in pending.into_iter().zip(trials).zip(trial_normals) {
                if !states[entry.0].take_or_damp(trial, &step, tc, o) {
                    still.push(entry);
                }
            }
            pending = still;
        }
        for (i, _, _) in pending {
            states[i].stop = Some(Stop::NoProgress);
        }
    }
    let mut solutions: Vec<Solution> = states
        .into_iter()
        .map(|s| Solution {
            candidate: s.c,
            cost: s.normal.cost,
            count: s.normal.count,
            iterations: s.iterations,
            stop: s.stop.unwrap_or(Stop::IterationCap),
            log: s.log,
        })
        .collect();
    follow_merges(&mut solutions, &merged_into);
    Ok(solutions)
}

impl State {
    /// A start at `c` (inside its `bounds`) with its normal equations `c0`: the barrier
    /// weight small against the cost, the duals on the central path.
    fn at(c: Candidate, c0: NormalEquations, bounds: Bounds) -> Self {
        let mu = 1e-3 * c0.cost.max(1e-12) / 12.0;
        let v = c.shape.to_array();
        let mut z_lower = [0.0; 6];
        let mut z_upper = [0.0; 6];
        for i in 0..6 {
            z_lower[i] = mu / (v[i] - bounds.lower[i]);
            z_upper[i] = mu / (bounds.upper[i] - v[i]);
        }
        State {
            c,
            bounds,
            z_lower,
            z_upper,
            mu,
            damping: 1e-3,
            normal: c0,
            iterations: 0,
            small_changes: 0,
            stop: None,
            log: Vec::new(),
        }
    }

    /// Takes the trial `trial` (reached by `step`, its normal equations `tc`) where it
    /// lowers the barrier merit, updating the duals and mu; else raises the damping.
    /// Whether the start is done with this iteration (stepped or stopped).
    fn take_or_damp(
        &mut self,
        trial: Candidate,
        step: &[f64; NUM_PARAMS],
        tc: NormalEquations,
        o: &SolverOptions,
    ) -> bool {
        let s = self;
        let bounds = s.bounds;
        let (cost, count) = (s.normal.cost, s.normal.count);
        let before = merit(cost, count, &s.c.shape, &bounds, s.mu, o);
        let after = merit(tc.cost, tc.count, &trial.shape, &bounds, s.mu, o);
        let step_norm = step.iter().map(|x| x * x).sum::<f64>().sqrt();
        if !(after.is_finite() && tc.count == count && after <= before) {
            s.damping *= 10.0;
            if s.damping > 1e10 || step_norm < o.step_tolerance {
                s.stop = Some(Stop::NoProgress);
                return true;
            }
            return false;
        }
        // dual update towards the central path of the current mu, then a smaller mu from
        // the complementarity that was reached
        let v = trial.shape.to_array();
        let mut gap = 0.0;
        for k in 0..6 {
            let (dl, du) = (v[k] - bounds.lower[k], bounds.upper[k] - v[k]);
            s.z_lower[k] = (s.mu / dl).max(1e-300);
            s.z_upper[k] = (s.mu / du).max(1e-300);
            gap += s.z_lower[k] * dl + s.z_upper[k] * du;
        }
        let relative = (cost - tc.cost).abs() / cost.max(1e-300);
        s.c = trial;
        s.mu = (0.1 * gap / 12.0).max(1e-14 * tc.cost.max(1e-300));
        s.normal = tc;
        s.damping = (s.damping / 3.0).max(1e-9);
        s.log.push(LogLine {
            iteration: s.iterations,
            cost: s.normal.cost,
            mu: s.mu,
            damping: s.damping,
            step: step_norm,
        });
        s.small_changes = if relative < o.cost_tolerance {
            s.small_changes + 1
        } else {
            0
        };
        if s.small_changes >= 2 {
            s.stop = Some(Stop::CostChange);
        } else if step_norm < o.step_tolerance {
            s.stop = Some(Stop::SmallStep);
        }
        true
    }
}

/// Stops the starts of each point set whose cost is over `ratio` times the set's best.
fn prune(states: &mut [State], sets: &[usize], ratio: f64) {
    let mut best = std::collections::HashMap::<usize, f64>::new();
    for (s, &set) in states.iter().zip(sets) {
        let b = best.entry(set).or_insert(f64::INFINITY);
        *b = b.min(s.normal.cost);
    }
    for (s, set) in states.iter_mut().zip(sets) {
        if s.stop.is_none() && s.normal.cost > ratio * best[set] {
            s.stop = Some(Stop::Pruned);
        }
    }
}

/// The Newton system (H, g) of a running start: Gauss-Newton from its normal equations,
/// the shape prior, the log-barrier's terms, held and unseen parameters taken out. None
/// (the start stopped) where its gradient and barrier weight are both negligible.
fn newton_system(s: &mut State, o: &SolverOptions) -> Option<(Mat12, Vec12)> {
    let ne = &s.normal;
    let bounds = s.bounds;
    s.iterations += 1;
    let mut h = Mat12::from_fn(|a, b| ne.jtj[a][b]);
    let unseen = unseen_directions(&ne.jtj);
    let mut g = Vec12::from_fn(|a, _| ne.jtr[a]);
    for k in 0..6 {
        g[k] += o.shape_prior[k] * ne.count as f64;
    }
    let v = s.c.shape.to_array();
    for k in 0..6 {
        let (dl, du) = (v[k] - bounds.lower[k], bounds.upper[k] - v[k]);
        g[k] += -s.mu / dl + s.mu / du;
        h[(k, k)] += s.z_lower[k] / dl + s.z_upper[k] / du;
    }
    for k in 0..NUM_PARAMS {
        if o.fixed[k] || unseen[k] {
            g[k] = 0.0;
            for j in 0..NUM_PARAMS {
                h[(k, j)] = 0.0;
                h[(j, k)] = 0.0;
            }
            h[(k, k)] = 1.0;
        }
    }
    let gmax = g.amax();
    if gmax <= o.gradient_tolerance * ne.cost.max(1e-300) && s.mu < 1e-10 * ne.cost.max(1e-300) {
        s.stop = Some(Stop::SmallGradient);
        return None;
    }
    Some((h, g))
}

/// The damped step of a start from its system (h, g), cut by the fraction to the
/// boundary (0.5% of the distance to every bound kept), and where it lands.
fn damped_trial(s: &State, h: &Mat12, g: &Vec12) -> (Candidate, [f64; NUM_PARAMS]) {
    let bounds = s.bounds;
    let mut damped = *h;
    for k in 0..NUM_PARAMS {
        damped[(k, k)] += s.damping * h[(k, k)].max(1e-12);
    }
    let step = damped
        .cholesky()
        .map(|ch| ch.solve(&(-g)))
        .unwrap_or_else(|| -g / (h.diagonal().amax().max(1e-12) * (1.0 + s.damping)));
    let v = s.c.shape.to_array();
    let mut alpha: f64 = 1.0;
    for k in 0..6 {
        if step[k] < 0.0 {
            alpha = alpha.min(-0.995 * (v[k] - bounds.lower[k]) / step[k]);
        } else if step[k] > 0.0 {
            alpha = alpha.min(0.995 * (bounds.upper[k] - v[k]) / step[k]);
        }
    }
    let step: [f64; NUM_PARAMS] = std::array::from_fn(|k| alpha * step[k]);
    (apply_step(&s.c, &step), step)
}

/// Each start that merged into another reports the solution of the one that ran on (a
/// start may have met one that met another later: followed to the end).
fn follow_merges(solutions: &mut [Solution], merged_into: &[Option<usize>]) {
    for i in 0..solutions.len() {
        let mut j = i;
        while let Some(k) = merged_into[j] {
            j = k;
        }
        if j != i {
            let survivor = &solutions[j];
            let (candidate, cost, count) = (survivor.candidate, survivor.cost, survivor.count);
            let s = &mut solutions[i];
            (s.candidate, s.cost, s.count) = (candidate, cost, count);
        }
    }
}

/// Stops every running start that has come within `tolerance` of another running start
/// of its point set and box with a lower cost, recording which one in `merged_into`
/// (see [`SolverOptions::merge_tolerance`]).
fn merge_close_starts(
    states: &mut [State],
    sets: &[usize],
    tolerance: f64,
    merged_into: &mut [Option<usize>],
) {
    let close = |a: &State, b: &State| {
        let (x, y) = (a.c.shape.to_array(), b.c.shape.to_array());
        let shape = x.iter().zip(y).all(|(x, y)| (x - y).abs() <= tolerance);
        let translation = (a.c.pose.translation - b.c.pose.translation)
            .abs()
            .max_element();
        let angle = a.c.pose.rotation.angle_between(b.c.pose.rotation);
        shape && translation <= tolerance && angle <= tolerance && a.bounds == b.bounds
    };
    for i in 0..states.len() {
        if states[i].stop.is_some() {
            continue;
        }
        for j in 0..states.len() {
            if j == i || sets[j] != sets[i] || states[j].stop.is_some() {
                continue;
            }
            // the higher cost gives way (ties: the later start)
            let (ci, cj) = (states[i].normal.cost, states[j].normal.cost);
            if (ci > cj || (ci == cj && i > j)) && close(&states[i], &states[j]) {
                states[i].stop = Some(Stop::Merged);
                merged_into[i] = Some(j);
                break;
            }
        }
    }
}

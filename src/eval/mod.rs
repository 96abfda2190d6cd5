//! Evaluators: the per-point work of every solver iteration. For a set of points and a
//! batch of candidate parameter sets they return, per candidate, the Gauss-Newton normal
//! equations (JtWJ, JtWr), the robust cost and the number of valid points; or only the
//! costs (line searches); or the residuals themselves.
//!
//! Two implementations with one interface, so the solver never knows which one runs:
//! [`CpuEvaluator`] (f64, rayon; the reference and fallback) and [`GpuEvaluator`] (WGSL
//! compute shaders through wgpu, f32 on the device, partial sums finished in f64).
//!
//! Points are given in a normalised frame (centred and scaled, see [`Normalization`]);
//! the candidates are expressed in that same frame.
//!
//! The fit's objective (`fit::objective`) runs its per-point sums where the search's
//! evaluator says ([`Evaluator::objective_device`]): the GPU evaluator's adapter
//! ([`GpuObjective`], `shaders/objective.wgsl`), or the objective's own f64 loop.

mod cpu;
mod gpu;
mod gpu_objective;

pub use cpu::CpuEvaluator;
pub use gpu::{AdapterChoice, GpuContext, GpuEvaluator};
pub use gpu_objective::{
    FLAG_GRADIENT, FLAG_SENSOR, FLAG_VISIBILITY, GpuObjective, OBJECTIVE_PARAMETERS,
    OBJECTIVE_SHADER_SOURCE, ObjectiveJob, ObjectiveParams, ObjectiveSums,
};

use crate::model::{Pose, Shape};
use glam::DVec3;

/// Number of parameters: a1 a2 a3 a4 eps1 eps2 | tx ty tz | dx dy dz (rotation increment
/// applied on the right: R <- R·exp(\[d\]x)).
pub const NUM_PARAMS: usize = 12;
/// Upper-triangle entries of a 12 x 12 symmetric matrix.
pub const NUM_UPPER: usize = NUM_PARAMS * (NUM_PARAMS + 1) / 2;

/// One parameter set to evaluate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Candidate {
    pub shape: Shape,
    pub pose: Pose,
}

/// Robust loss rho(r) and its IRLS weight rho'(r)/r.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub enum Loss {
    /// rho = r^2/2
    #[default]
    Squared,
    /// quadratic within k, linear beyond
    Huber(f64),
    /// rho = k^2/2·ln(1 + (r/k)^2)
    Cauchy(f64),
}

impl Loss {
    /// (rho(r), w(r) = rho'(r)/r)
    pub fn eval(self, r: f64) -> (f64, f64) {
        match self {
            Loss::Squared => (0.5 * r * r, 1.0),
            Loss::Huber(k) => {
                let a = r.abs();
                if a <= k {
                    (0.5 * r * r, 1.0)
                } else {
                    (k * a - 0.5 * k * k, k / a)
                }
            }
            Loss::Cauchy(k) => {
                let t = r / k;
                (0.5 * k * k * (1.0 + t * t).ln(), 1.0 / (1.0 + t * t))
            }
        }
    }

    pub(crate) fn code(self) -> (u32, f32) {
        match self {
            Loss::Squared => (0, 1.0),
            Loss::Huber(k) => (1, k as f32),
            Loss::Cauchy(k) => (2, k as f32),
        }
    }
}

/// Normal equations of one candidate: JtWJ (full symmetric), JtWr, cost = sum rho(r_i),
/// and the number of points with a finite residual and Jacobian.
#[derive(Clone, Debug, PartialEq)]
pub struct NormalEquations {
    pub jtj: [[f64; NUM_PARAMS]; NUM_PARAMS],
    pub jtr: [f64; NUM_PARAMS],
    pub cost: f64,
    pub count: u64,
}

impl NormalEquations {
    pub fn zero() -> Self {
        Self {
            jtj: [[0.0; NUM_PARAMS]; NUM_PARAMS],
            jtr: [0.0; NUM_PARAMS],
            cost: 0.0,
            count: 0,
        }
    }

    /// Builds from the packed layout the GPU returns: 78 upper-triangle entries (row by
    /// row), 12 JtWr, cost, count.
    pub(crate) fn from_packed(packed: &[f64]) -> Self {
        let mut ne = Self::zero();
        let mut idx = 0;
        for a in 0..NUM_PARAMS {
            for b in a..NUM_PARAMS {
                ne.jtj[a][b] = packed[idx];
                ne.jtj[b][a] = packed[idx];
                idx += 1;
            }
        }
        ne.jtr
            .copy_from_slice(&packed[NUM_UPPER..NUM_UPPER + NUM_PARAMS]);
        ne.cost = packed[NUM_UPPER + NUM_PARAMS];
        ne.count = packed[NUM_UPPER + NUM_PARAMS + 1].round() as u64;
        ne
    }
}

/// Cost and valid-point count of one candidate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cost {
    pub cost: f64,
    pub count: u64,
}

#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    #[error("no points were set")]
    NoPoints,
    #[error("no GPU adapter: {0}")]
    NoAdapter(String),
    #[error("GPU error: {0}")]
    Device(String),
    #[error("input too large for the device: {0}")]
    TooLarge(String),
    #[error("bad point-set index: {0}")]
    BadSet(String),
}

/// One point set: points on the surface, and optionally *free-space* points, known to lie
/// outside the object (on the lines of sight in front of a depth sensor's returns). A
/// surface point's residual is the signed meridian distance r; a free-space point's is
/// min(r, 0): nothing while it is outside the candidate, its depth inside otherwise.
/// Free-space points add to the cost and the normal equations, not to the point count,
/// and have no entry in `residuals_on`.
#[derive(Clone, Copy, Debug, Default)]
pub struct PointSet<'a> {
    pub surface: &'a [DVec3],
    pub free_space: &'a [DVec3],
}

impl<'a> PointSet<'a> {
    /// A set of surface points only.
    pub fn surface(points: &'a [DVec3]) -> Self {
        Self {
            surface: points,
            free_space: &[],
        }
    }
}

/// The residual of a point (see [`PointSet`]): a free-space point counts only inside.
#[inline]
pub fn point_residual(signed: f64, free_space: bool) -> f64 {
    if free_space { signed.min(0.0) } else { signed }
}

/// The evaluator interface the solver talks to.
///
/// Points are uploaded as one or more *point sets* (a batch of clouds, or one cloud's
/// stage sample); every candidate is evaluated on the set it names, so the starts of many
/// clouds go through the same batched call (one dispatch on the GPU). The `_on` methods
/// take one set index per candidate; the plain ones evaluate every candidate on set 0.
pub trait Evaluator: Send {
    /// "cpu" or "gpu"
    fn kind(&self) -> &'static str;
    /// Human-readable device name (the adapter's name for the GPU).
    fn device_name(&self) -> String;
    /// Uploads the (normalised) point sets once; they stay for all following evaluations.
    fn set_point_sets_with_free_space(&mut self, sets: &[PointSet]) -> Result<(), EvalError>;
    /// Normal equations of every candidate on its point set (`sets[k]` for candidate k).
    fn normal_equations_on(
        &mut self,
        candidates: &[Candidate],
        sets: &[usize],
        loss: Loss,
    ) -> Result<Vec<NormalEquations>, EvalError>;
    /// Costs only, a fraction of the work of normal equations: for scoring candidates.
    /// (The solver does not call it: it evaluates each trial step with its normal
    /// equations, which the next iteration reuses.)
    fn costs_on(
        &mut self,
        candidates: &[Candidate],
        sets: &[usize],
        loss: Loss,
    ) -> Result<Vec<Cost>, EvalError>;
    /// Signed residuals, one block per candidate of one value per surface point of its set.
    fn residuals_on(
        &mut self,
        candidates: &[Candidate],
        sets: &[usize],
    ) -> Result<Vec<f64>, EvalError>;

    /// The GPU the fit's objective runs its per-point sums on, where this evaluator has
    /// one (`fit::objective`; none: its f64 loop).
    fn objective_device(&self) -> Option<std::sync::Arc<GpuObjective>> {
        None
    }

    /// Point sets of surface points only.
    fn set_point_sets(&mut self, sets: &[&[DVec3]]) -> Result<(), EvalError> {
        let sets: Vec<PointSet> = sets.iter().map(|s| PointSet::surface(s)).collect();
        self.set_point_sets_with_free_space(&sets)
    }
    /// One point set.
    fn set_points(&mut self, points: &[DVec3]) -> Result<(), EvalError> {
        self.set_point_sets(&[points])
    }
    fn normal_equations(
        &mut self,
        candidates: &[Candidate],
        loss: Loss,
    ) -> Result<Vec<NormalEquations>, EvalError> {
        self.normal_equations_on(candidates, &vec![0; candidates.len()], loss)
    }
    fn costs(&mut self, candidates: &[Candidate], loss: Loss) -> Result<Vec<Cost>, EvalError> {
        self.costs_on(candidates, &vec![0; candidates.len()], loss)
    }
    /// Signed residuals on set 0, `candidates.len()` blocks of one value per point.
    fn residuals(&mut self, candidates: &[Candidate]) -> Result<Vec<f64>, EvalError> {
        self.residuals_on(candidates, &vec![0; candidates.len()])
    }
}

/// Checks one set index per candidate against the sizes of the uploaded sets: every named
/// set must exist and hold points.
pub(crate) fn check_sets(
    candidates: usize,
    sets: &[usize],
    sizes: &[usize],
) -> Result<(), EvalError> {
    if sets.len() != candidates {
        return Err(EvalError::BadSet(format!(
            "{} set indices for {candidates} candidates",
            sets.len()
        )));
    }
    for &s in sets {
        match sizes.get(s) {
            None if sizes.is_empty() => return Err(EvalError::NoPoints),
            None => {
                return Err(EvalError::BadSet(format!(
                    "set {s} named, {} uploaded",
                    sizes.len()
                )));
            }
            Some(0) => return Err(EvalError::NoPoints),
            Some(_) => {}
        }
    }
    Ok(())
}

/// Centre and scale that map world points into the evaluators' frame: p' = (p - c)/s.
/// The scale is the RMS distance of the points from their centroid, so normalised clouds
/// have unit spread and f32 keeps about seven significant digits of every coordinate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Normalization {
    pub centre: DVec3,
    pub scale: f64,
}

impl Normalization {
    pub fn of(points: &[DVec3]) -> Self {
        if points.is_empty() {
            return Self {
                centre: DVec3::ZERO,
                scale: 1.0,
            };
        }
        let n = points.len() as f64;
        let centre = points.iter().copied().sum::<DVec3>() / n;
        let rms = (points
            .iter()
            .map(|p| (*p - centre).length_squared())
            .sum::<f64>()
            / n)
            .sqrt();
        Self {
            centre,
            scale: if rms > 0.0 && rms.is_finite() {
                rms
            } else {
                1.0
            },
        }
    }

    pub fn point(&self, p: DVec3) -> DVec3 {
        (p - self.centre) / self.scale
    }

    pub fn points(&self, points: &[DVec3]) -> Vec<DVec3> {
        points.iter().map(|p| self.point(*p)).collect()
    }

    /// A world-frame candidate expressed in the normalised frame.
    pub fn candidate(&self, shape: &Shape, pose: &Pose) -> Candidate {
        let s = self.scale;
        Candidate {
            shape: Shape {
                a1: shape.a1 / s,
                a2: shape.a2 / s,
                a3: shape.a3 / s,
                ..*shape
            },
            pose: Pose::new(pose.rotation, (pose.translation - self.centre) / s),
        }
    }

    /// A normalised-frame candidate back in world units.
    pub fn to_world(&self, c: &Candidate) -> (Shape, Pose) {
        let s = self.scale;
        (
            Shape {
                a1: c.shape.a1 * s,
                a2: c.shape.a2 * s,
                a3: c.shape.a3 * s,
                ..c.shape
            },
            Pose::new(c.pose.rotation, c.pose.translation * s + self.centre),
        )
    }
}

/// Which evaluator to run: `auto` takes a GPU adapter when one is found and falls back to
/// the CPU evaluator otherwise.
#[derive(
    Clone,
    Copy,
    Debug,
    PartialEq,
    Eq,
    Default,
    clap::ValueEnum,
    serde::Serialize,
    serde::Deserialize,
    utoipa::ToSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum Backend {
    #[default]
    Auto,
    Gpu,
    Cpu,
}

impl Backend {
    /// From `SUPERTOROID_BACKEND` (auto|gpu|cpu), if set.
    pub fn from_env() -> Option<Self> {
        match std::env::var("SUPERTOROID_BACKEND")
            .ok()?
            .to_ascii_lowercase()
            .as_str()
        {
            "auto" => Some(Self::Auto),
            "gpu" => Some(Self::Gpu),
            "cpu" => Some(Self::Cpu),
            _ => None,
        }
    }
}

/// Points per CPU thread from which `auto` sends a fit to a hardware GPU. Whole fits are
/// many small dispatches, each waiting for its result, so a GPU pays off only on large
/// stage-2 samples. Measured on an H100 against the 16 threads of its host (Vulkan,
/// `--stage2-points` N on a 300k-point cloud, median of 5 seeds): N = 1000: CPU 11.8 ms,
/// GPU 31.0 ms; 16000: 15.0 vs 26.7; 64000: 22.3 vs 33.7; 300000: 56.2 vs 49.0. The
/// crossover near 200k points on 16 threads scales with the threads the CPU has.
pub const AUTO_GPU_POINTS_PER_THREAD: usize = 12_000;

/// Whether `auto` takes a hardware GPU for fits that evaluate `points_per_candidate`
/// points per candidate (the stage-2 sample): see [`AUTO_GPU_POINTS_PER_THREAD`].
pub fn auto_prefers_gpu(points_per_candidate: usize) -> bool {
    points_per_candidate >= AUTO_GPU_POINTS_PER_THREAD * rayon::current_num_threads()
}

/// Makes the evaluator a backend choice asks for, for work of `points_per_candidate`
/// points per candidate. `Gpu` fails when no adapter is found. `Auto` takes a hardware
/// GPU when the work is large enough for one to win ([`auto_prefers_gpu`]), and the f64
/// CPU evaluator otherwise. It never takes a software adapter: lavapipe runs the same
/// cores as the CPU evaluator, and whole fits (150-1000 points, many small dispatches)
/// measured slower on it (about 40 ms against 27 ms per paper cloud).
pub fn make_evaluator(
    backend: Backend,
    points_per_candidate: usize,
) -> Result<Box<dyn Evaluator>, EvalError> {
    match backend {
        Backend::Cpu => Ok(Box::new(CpuEvaluator::new())),
        Backend::Gpu => Ok(Box::new(GpuEvaluator::new(GpuContext::shared(
            &AdapterChoice::from_env(),
        )?))),
        Backend::Auto if !auto_prefers_gpu(points_per_candidate) => {
            Ok(Box::new(CpuEvaluator::new()))
        }
        Backend::Auto => match GpuContext::shared(&AdapterChoice::from_env()) {
            Ok(ctx) if !ctx.is_software() => Ok(Box::new(GpuEvaluator::new(ctx))),
            _ => Ok(Box::new(CpuEvaluator::new())),
        },
    }
}

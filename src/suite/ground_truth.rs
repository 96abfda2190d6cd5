//! The ground-truth suite: random supertoroids (`make_case`'s ranges), clouds full or
//! single-view partial, with noise and outliers, and the success rule (centre within 5%
//! of the size, hole axis within 5 degrees, each a_i within 10%, each eps within 0.15,
//! up to the shape's symmetries: axis sign, and the a1/a2 swap with a quarter turn);
//! superellipsoids beside them, judged by their surfaces ([`super::chamfer`]).

use crate::eval::Normalization;
use crate::fit::{FitOptions, LIKELIHOOD_OUTLIER_WEIGHT, Sight, likelihood};
use crate::model::{Pose, Shape};
use crate::synth::{self, Camera, Intrinsics};
use glam::{DQuat, DVec3};
use rand::Rng;

#[derive(Clone, Debug)]
pub struct Case {
    pub shape: Shape,
    pub pose: Pose,
    pub partial: bool,
    /// noise sigma as a fraction of the size
    pub noise: f64,
    pub outlier_fraction: f64,
    /// the cloud: its first `inliers` points are the (noisy) surface points, the rest the
    /// outliers
    pub points: Vec<DVec3>,
    pub inliers: usize,
    /// the camera's position for a single-view cloud
    pub viewpoint: Option<DVec3>,
}

impl Case {
    /// A single view's cloud in its camera's optical frame (as a sensor writes it), with
    /// the camera's pose (world from camera, the camera `make_case` rendered from); None
    /// for a full cloud.
    pub fn in_camera_frame(&self) -> Option<(Vec<DVec3>, Pose)> {
        let camera = Camera::look_at(
            Intrinsics::REALSENSE_640X480,
            self.viewpoint?,
            self.pose.translation,
            DVec3::Z,
        );
        let points = self
            .points
            .iter()
            .map(|&p| camera.pose.to_canonical(p))
            .collect();
        Some((points, camera.pose))
    }
}

/// A shape in the suite's ranges and a random rotation axis for it.
pub fn random_shape(rng: &mut synth::SeededRng) -> (Shape, DVec3) {
    let shape = Shape::new(
        rng.random_range(0.03..0.12),
        rng.random_range(0.03..0.12),
        rng.random_range(0.01..0.06),
        rng.random_range(1.2..3.0),
        rng.random_range(0.3..1.8),
        rng.random_range(0.3..1.8),
    );
    (shape, random_axis(rng))
}

/// A superellipsoid (a4 = 0) in the ranges of the model-choice suite: sizes 0.02-0.15,
/// eps 0.1-1.9 (boxes, cans, bottles, pebbles), and a random rotation axis.
pub fn random_superellipsoid(rng: &mut synth::SeededRng) -> (Shape, DVec3) {
    let shape = Shape::new(
        rng.random_range(0.02..0.15),
        rng.random_range(0.02..0.15),
        rng.random_range(0.02..0.15),
        0.0,
        rng.random_range(0.1..1.9),
        rng.random_range(0.1..1.9),
    );
    (shape, random_axis(rng))
}

/// A rotation axis drawn from the cube [-1, 1]^3, normalised.
fn random_axis(rng: &mut synth::SeededRng) -> DVec3 {
    DVec3::new(
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
    )
    .normalize_or(DVec3::Z)
}

/// What a case's object is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Kind {
    /// a supertoroid with a hole ([`random_shape`])
    Holed,
    /// a superellipsoid ([`random_superellipsoid`])
    Superellipsoid,
}

/// One seeded case of the given category.
pub fn make_case(seed: u64, partial: bool, noise: f64, outlier_fraction: f64) -> Case {
    make_case_of(Kind::Holed, seed, partial, noise, outlier_fraction)
}

/// One seeded case of the given kind and category.
pub fn make_case_of(
    kind: Kind,
    seed: u64,
    partial: bool,
    noise: f64,
    outlier_fraction: f64,
) -> Case {
    let mut rng = synth::rng(seed);
    let (shape, axis) = match kind {
        Kind::Holed => random_shape(&mut rng),
        Kind::Superellipsoid => random_superellipsoid(&mut rng),
    };
    let pose = Pose::new(
        DQuat::from_axis_angle(axis, rng.random_range(-3.1..3.1)),
        DVec3::new(
            rng.random_range(-0.3..0.3),
            rng.random_range(-0.3..0.3),
            rng.random_range(0.4..1.0),
        ),
    );
    let (mut points, viewpoint) = if partial {
        let camera = Camera::random_view(&shape, &pose, Intrinsics::REALSENSE_640X480, &mut rng);
        let view =
            synth::render_view(&shape, &pose, &camera, 0.0001).expect("valid shape and camera");
        (
            synth::subsample(&view.points, 2000, &mut rng),
            Some(camera.pose.translation),
        )
    } else {
        (synth::sample_surface(&shape, &pose, 2000, &mut rng), None)
    };
    synth::add_noise(&mut points, noise * shape.size(), &mut rng);
    let inliers = points.len();
    synth::add_outliers(&mut points, &shape, &pose, outlier_fraction, &mut rng);
    Case {
        shape,
        pose,
        partial,
        noise,
        outlier_fraction,
        points,
        inliers,
        viewpoint,
    }
}

/// Errors of a fit against the truth, after resolving the symmetries.
#[derive(Clone, Copy, Debug)]
pub struct Errors {
    /// centre distance / size
    pub centre: f64,
    /// degrees between the hole axes (sign ignored)
    pub axis_degrees: f64,
    /// largest relative error of a1, a2, a3
    pub sizes: f64,
    /// a4 relative error
    pub a4: f64,
    /// largest absolute error of eps1, eps2
    pub eps: f64,
}

/// The success bounds on the pose: centre error / size, and hole-axis error in degrees.
pub const CENTRE_BOUND: f64 = 0.05;
pub const AXIS_BOUND_DEGREES: f64 = 5.0;

impl Errors {
    pub fn success(&self) -> bool {
        self.centre < CENTRE_BOUND
            && self.axis_degrees < AXIS_BOUND_DEGREES
            && self.sizes < 0.10
            && self.a4 < 0.10
            && self.eps < 0.15
    }
}

pub fn compare(truth: (&Shape, &Pose), fitted: (&Shape, &Pose)) -> Errors {
    let (ts, tp) = truth;
    let (fs, fp) = fitted;
    let size = ts.size();
    let centre = (tp.translation - fp.translation).length() / size;
    let cos = tp.axis().dot(fp.axis()).abs().min(1.0);
    let axis_degrees = cos.acos().to_degrees();
    // a1/a2 swap with a quarter turn: decide by which fitted in-plane axis follows the true x
    let fitted_x = fp.rotation * DVec3::X;
    let fitted_y = fp.rotation * DVec3::Y;
    let true_x = tp.rotation * DVec3::X;
    let (fa1, fa2) = if true_x.dot(fitted_x).abs() >= true_x.dot(fitted_y).abs() {
        (fs.a1, fs.a2)
    } else {
        (fs.a2, fs.a1)
    };
    let rel = |a: f64, b: f64| (a - b).abs() / b;
    let sizes = rel(fa1, ts.a1).max(rel(fa2, ts.a2)).max(rel(fs.a3, ts.a3));
    // a4 scales a1/a2: compare the mean-superellipse radii a1·a4, a2·a4 too
    let a4 = rel(fs.a4, ts.a4);
    let eps = (fs.eps1 - ts.eps1).abs().max((fs.eps2 - ts.eps2).abs());
    Errors {
        centre,
        axis_degrees,
        sizes,
        a4,
        eps,
    }
}

/// Which points [`model_from_truth`] refines on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TruthPoints {
    /// every point of the cloud, as the fit's last polish sees a cloud of the suite
    /// (`FitOptions::polish_points` is above its size)
    All,
    /// the stage-2 sample the fit draws with this seed (`fit::prepare`'s draw: the
    /// stage-1 sample first, then stage 2's, from the case's seed)
    Stage2Sample(u64),
}

/// The likelihood's limits with nothing held: the options' bounds alone.
fn free_limits(options: &FitOptions) -> likelihood::Limits {
    likelihood::Limits {
        bounds: options.bounds(),
        fixed_shape: [false; 6],
        fixed_axis: false,
        deadline: None,
    }
}

/// The fit's own estimator started at the answer: the noise model (`fit::likelihood`)
/// refined from the true parameters and the true noise sigma of a noisy case, judged by
/// the success rule. A case that fails here fails because the estimator's optimum near
/// the truth is out of tolerance, whatever the search: it is the ceiling of any search
/// for that estimator. `finely` refines on the grid the fit's last polish uses
/// ([`likelihood::refine_finely`]), otherwise on the coarser one of stage 2's model.
///
/// None for a noise-free case (the model never runs on one, and the truth is an exact
/// optimum of the least-squares fit that does) and for a shape the model does not cover
/// (a4 <= 1).
pub fn model_from_truth(
    case: &Case,
    points: TruthPoints,
    finely: bool,
    options: &FitOptions,
) -> Option<Errors> {
    if case.noise == 0.0 {
        return None;
    }
    let norm = Normalization::of(&case.points);
    let mut normalised = norm.points(&case.points);
    if let TruthPoints::Stage2Sample(seed) = points {
        // a change to `fit::prepare`'s draw must be made here too
        let mut rng = synth::rng(seed);
        let _stage1 = synth::subsample(&normalised, options.stage1_points, &mut rng);
        normalised = synth::subsample(&normalised, options.stage2_points, &mut rng);
    }
    let truth = norm.candidate(&case.shape, &case.pose);
    let sigma = case.noise * case.shape.size() / norm.scale;
    let limits = free_limits(options);
    let refine: likelihood::Refine = if finely {
        likelihood::refine_finely
    } else {
        likelihood::refine
    };
    let refined = refine(
        &normalised,
        &truth,
        sigma,
        LIKELIHOOD_OUTLIER_WEIGHT,
        case.viewpoint.map(|v| Sight::at(norm.point(v))),
        &limits,
        2 * likelihood::MAX_ITERATIONS,
    )?;
    let (shape, pose) = norm.to_world(&refined.candidate);
    Some(compare((&case.shape, &case.pose), (&shape, &pose)))
}

/// Whether the fit's estimator started at the answer lands within the tolerances
/// ([`model_from_truth`] on all points or the sample): a noise-free case counts as within
/// (its truth is an exact optimum of the least-squares fit that runs on it), a noisy one
/// the model cannot refine as not.
pub fn recovered_from_truth(
    case: &Case,
    points: TruthPoints,
    finely: bool,
    options: &FitOptions,
) -> bool {
    model_from_truth(case, points, finely, options)
        .map_or(case.noise == 0.0, |errors| errors.success())
}

/// How much likelier the truth's basin is than a fit's under the fit's own noise model:
/// the mean log-likelihood per point of [`likelihood::refine_finely`] started at the
/// truth, less that of the same refinement started at the fit (every point of the cloud,
/// the fit's noise estimate `sigma` in world units, seen from the case's camera). Above
/// zero, a fit in another basin than the truth's is the search's miss: the objective
/// prefers the truth's, the search never got there. At or below zero the fit is at least
/// as likely, and a miss is the estimator's. None for a noise-free case and where either
/// start is not a shape the model covers (a4 <= 1: a fit that lost its hole).
pub fn basin_gap(
    case: &Case,
    fitted: (&Shape, &Pose),
    sigma: f64,
    options: &FitOptions,
) -> Option<f64> {
    if case.noise == 0.0 {
        return None;
    }
    let norm = Normalization::of(&case.points);
    let points = norm.points(&case.points);
    let limits = free_limits(options);
    let from = |start| {
        likelihood::refine_finely(
            &points,
            &start,
            sigma / norm.scale,
            LIKELIHOOD_OUTLIER_WEIGHT,
            case.viewpoint.map(|v| Sight::at(norm.point(v))),
            &limits,
            2 * likelihood::MAX_ITERATIONS,
        )
        .map(|refined| refined.objective)
    };
    // (objectives are negative mean log-likelihoods: lower is likelier)
    Some(from(norm.candidate(fitted.0, fitted.1))? - from(norm.candidate(&case.shape, &case.pose))?)
}

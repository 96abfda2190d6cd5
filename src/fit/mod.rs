//! The fit: one bounded search on one objective ([`search`]), then the noise model's
//! polish ([`search::polish`]), for many clouds in lockstep. Each stage is a module:
//!
//! 0. Take the cloud in ([`input`]: checked, a large one thinned, its stray points set
//!    aside by [`isolated`]) and screen it ([`planarity`]: points on one plane within
//!    their noise around no hole are no object).
//! 1. Resolve its viewpoint ([`viewpoint`]); normalise it and draw its samples, free
//!    space and starts once ([`prepare`], [`starts`]).
//! 2. The search ([`search`]): least squares from the broad start set in lockstep, the
//!    candidates ranked and cut down by the likelihood of the cloud ([`objective`]), the
//!    finalists refined by the estimator their noise calls for, the likeliest kept.
//! 3. The polish: a fit the likelihood refined, refined by the noise model's grid on more
//!    of the cloud's points ([`likelihood`]), its top view read both ways.
//! 4. The report ([`report`]): quality against every input point, the noise estimate,
//!    the viewpoint used, the standard errors ([`uncertainty`]) and the warnings.
//! 5. For `model: auto`, the supertoroid's and the superellipsoid's fits weighed
//!    ([`model_choice`]).
//!
//! `Method::Paper` runs the paper's own two stages (§V) as the baseline ([`paper`]):
//! three starts along the frame's axes, plain least squares on 150 and 1000 points.
//!
//! [`fit_batch`] fits many clouds together (each cloud's sample is a point set of the
//! evaluator, each start names its cloud's set), so one batched evaluation per solver
//! iteration serves every cloud; [`fit`] is a batch of one.

pub mod ablation;
pub mod coverage;
pub mod free_space;
mod inferred_view;
mod input;
pub mod isolated;
pub mod likelihood;
pub mod model_choice;
pub mod objective;
mod options;
mod paper;
pub mod planarity;
mod prepare;
mod report;
pub mod scatter;
mod search;
mod sight;
pub mod starts;
pub mod uncertainty;
pub mod viewpoint;

use ablation::Stage;
use inferred_view::{inferred, with_resolved};
use input::{Cleaned, cleaned};
pub use input::{FitError, MAX_FIT_POINTS, MIN_POINTS, check_cloud, principal_axes};
use model_choice::fits_of_model;
pub use model_choice::{Model, ModelOut};
pub use options::{
    FitOptions, Method, PAPER_A4_REWARD, SHAPE_NAMES, known_with_a3, parse_known_shape,
};
use paper::fit_batch_paper;
use planarity::screen_for_an_object;
pub use prepare::{MAX_OVERREACH, overreach};
use prepare::{Prepared, StartSet, prepare};
pub use report::{
    BackendOut, FitReport, Iterations, PointsOut, PoseOut, Quality, SearchOut, Timing, noise_sigma,
    parse_report_json, quality,
};
use report::{Searched, report};
pub use search::basins::DISTINCT_THICKNESS;
pub use search::batch::VIEWPOINT_IGNORED;
pub use search::estimator::{
    LIKELIHOOD_MIN_COVERAGE, LIKELIHOOD_NOISE_RATIO, LIKELIHOOD_OUTLIER_WEIGHT,
    LIKELIHOOD_VIEW_NOISE_RATIO, MAX_SIGMA_GROWTH, MIN_SECTION_SIGMAS,
};
pub use search::polish::{
    MISFIT_OF_SIZE, MISFIT_OVER_SCATTER, OFF_ITS_POINTS_WARNING, POLISH_POINTS, PRECISE_MISFIT,
};
pub use sight::{FieldOfView, Sight};
use viewpoint::resolve_viewpoints;
pub use viewpoint::{Viewpoint, ViewpointSource, ViewpointUsed};

use crate::eval::{Candidate, EvalError, Evaluator, Loss, Normalization, PointSet};
use crate::model::{Pose, Shape};
use crate::solve::{Bounds, Solution, SolverOptions, Stop, solve_on};
use crate::synth;
use glam::{DMat3, DQuat, DVec3};
use rayon::prelude::*;
use std::time::Instant;

/// Fits one supertoroid to a cloud (world units in, world units out).
pub fn fit(
    evaluator: &mut dyn Evaluator,
    points: &[DVec3],
    o: &FitOptions,
) -> Result<FitReport, FitError> {
    fit_batch(evaluator, &[(points, o)])?
        .pop()
        .expect("one result per cloud")
}

/// Fits many clouds together: the stage-1 starts of every cloud are solved in lockstep,
/// one batched evaluator call per solver iteration for all of them (one dispatch on the
/// GPU), then the stage-2 finalists of every cloud likewise. Clouds whose options give
/// different solver settings (method, priors, loss) go in separate lockstep groups.
///
/// Each cloud's viewpoint is resolved first ([`viewpoint::resolve`]: given, none, or the
/// frame's origin for a cloud in front of it); then the search and the polish
/// ([`search::batch`]).
///
/// Each cloud gets the fit [`fit`] gives it alone (bit for bit on the CPU evaluator);
/// its `timing_ms` is its group's, since the clouds share every evaluation. The outer
/// error is the evaluator's (it fails the whole batch); a cloud that cannot be fitted
/// (too few points, planar, bad options) gets its own error and the others go on.
///
/// Before any of it, each cloud is screened for an object ([`planarity`]): points on one
/// plane within their noise and around no hole get [`FitError::NoObject`].
pub fn fit_batch(
    evaluator: &mut dyn Evaluator,
    clouds: &[(&[DVec3], &FitOptions)],
) -> Result<Vec<Result<FitReport, FitError>>, FitError> {
    // (the screen and the fit see each cloud thinned and its stray points set aside)
    let cleaned: Vec<Cleaned> = clouds.iter().map(|(p, o)| cleaned(p, o)).collect();
    let inputs: Vec<usize> = clouds.iter().map(|(points, _)| points.len()).collect();
    let clouds: Vec<(&[DVec3], &FitOptions)> = clouds
        .iter()
        .zip(&cleaned)
        .map(|((points, o), c)| (c.kept.as_deref().unwrap_or(points), *o))
        .collect();
    let clouds = &clouds[..];
    // each cloud with an object in it: its model's fit, or both models' for auto
    let plans: Vec<Result<Vec<FitOptions>, FitError>> = clouds
        .iter()
        .map(|(points, o)| {
            screen_for_an_object(points, o.seed)?;
            fits_of_model(o)
        })
        .collect();
    let jobs: Vec<(&[DVec3], &FitOptions)> = clouds
        .iter()
        .zip(&plans)
        .filter_map(|((points, _), plan)| Some((*points, plan.as_ref().ok()?)))
        .flat_map(|(points, fits)| fits.iter().map(move |o| (points, o)))
        .collect();
    let mut fits = fit_batch_unscreened(evaluator, &jobs)?.into_iter();
    // each cloud's fits, in the order its jobs were made
    type Fits = Result<(Vec<FitOptions>, Vec<Result<FitReport, FitError>>), FitError>;
    let per_cloud: Vec<Fits> = plans
        .into_iter()
        .map(|plan| {
            let options = plan?;
            let reports = options
                .iter()
                .map(|_| fits.next().expect("one fit per job"))
                .collect();
            Ok((options, reports))
        })
        .collect();
    // (the clouds' models weighed side by side: each weighing is a few dozen scores of
    // the objective)
    Ok(clouds
        .par_iter()
        .zip(per_cloud)
        .zip(inputs)
        .zip(&cleaned)
        .map(|((((points, _), fitted), input), cleaned)| {
            let (options, reports) = fitted?;
            let mut answer = answer(points, &options, reports)?;
            answer.points.isolated = cleaned.read - points.len();
            answer.points.input = input;
            answer.points.thinned_to = (cleaned.read < input).then_some(cleaned.read);
            if let Some(spent) = cleaned.isolated_ms {
                answer.timing_ms.total += spent;
                answer
                    .timing_ms
                    .stages
                    .insert(ablation::name(Stage::SetAsideIsolatedPoints), spent);
            }
            Ok(answer)
        })
        .collect())
}

/// A cloud's answer from the fits its model asked for ([`fits_of_model`]): the one fit,
/// or for `model: auto` the supertoroid's and the superellipsoid's weighed
/// ([`model_choice::choose`]), or the one of them that could be fitted.
fn answer(
    points: &[DVec3],
    options: &[FitOptions],
    reports: Vec<Result<FitReport, FitError>>,
) -> Result<FitReport, FitError> {
    let mut reports = reports.into_iter();
    match (reports.next(), reports.next()) {
        (Some(holed), Some(genus0)) => match (holed, genus0) {
            (Ok(h), Ok(g)) => Ok(model_choice::choose(points, options[0].field_of_view, h, g)),
            (Ok(one), Err(_)) | (Err(_), Ok(one)) => Ok(one),
            (Err(e), Err(_)) => Err(e),
        },
        (Some(one), None) => one.map(|mut r| {
            r.model = ModelOut::requested(&r.shape);
            r
        }),
        _ => unreachable!("one or two fits per screened cloud"),
    }
}

/// [`fit_batch`] without the screen for an object.
fn fit_batch_unscreened(
    evaluator: &mut dyn Evaluator,
    clouds: &[(&[DVec3], &FitOptions)],
) -> Result<Vec<Result<FitReport, FitError>>, FitError> {
    if clouds.is_empty() {
        return Ok(Vec::new());
    }
    search::batch::fit_batch_by_method(evaluator, clouds)
}

/// The items of a batch that belong to `cloud` (`sets`: each item's cloud).
fn of_cloud<'a, T>(items: &'a [T], sets: &'a [usize], cloud: usize) -> impl Iterator<Item = &'a T> {
    items
        .iter()
        .zip(sets)
        .filter(move |(_, s)| **s == cloud)
        .map(|(item, _)| item)
}

/// Concatenates per-cloud candidate lists, with the cloud index of each candidate.
fn flatten(lists: impl Iterator<Item = Vec<Candidate>>) -> (Vec<Candidate>, Vec<usize>) {
    let mut all = Vec::new();
    let mut sets = Vec::new();
    for (cloud, list) in lists.enumerate() {
        sets.extend(std::iter::repeat_n(cloud, list.len()));
        all.extend(list);
    }
    (all, sets)
}

//! What a fit tells its caller: the report (`supertoroid fit`'s JSON and the service's
//! answer, documented in the README), the quality of the fit against all input points,
//! and the warnings a fit carries when its numbers should not be taken at face value.

use super::prepare::Prepared;
use super::{Method, ModelOut, ViewpointUsed, coverage, free_space, search, uncertainty};
use crate::eval::Candidate;
use crate::model::{Pose, Shape, meridian_distance, meridian_residual_with_gradient};
use glam::DVec3;
use serde::Serialize;

#[derive(Clone, Debug, Serialize, utoipa::ToSchema)]
pub struct PoseOut {
    pub translation: [f64; 3],
    /// row-major R, world = R·canonical + t
    pub rotation: [[f64; 3]; 3],
    pub quaternion_wxyz: [f64; 4],
}

#[derive(Clone, Debug, Serialize, utoipa::ToSchema)]
pub struct Quality {
    pub rms_distance: f64,
    pub median_distance: f64,
    /// rms distance / object size
    pub relative_rms: f64,
    /// fraction of the input within 2% of the object size of the surface
    pub inlier_fraction: f64,
    /// robust estimate of the sensor noise: 1.4826 · the median first-order Euclidean
    /// distance of the points to the surface (the standard deviation for Gaussian noise,
    /// unmoved by outliers)
    pub noise_sigma: f64,
    /// with a viewpoint: the fraction of the fitted surface the sensor would have seen
    /// that has points at its depth (see [`coverage`]); absent without one
    #[serde(skip_serializing_if = "Option::is_none")]
    pub visible_coverage: Option<f64>,
    /// how tightly the points pin the shape down ([`super::uncertainty`]); absent where
    /// the points are too few
    #[serde(skip_serializing_if = "Option::is_none")]
    pub standard_errors: Option<super::uncertainty::StandardErrors>,
}

/// Where a fit's time went (milliseconds): the search's least-squares round 1
/// (`stage1`) and its later rounds (`stage2`, the likelihood's refinement `noise_model`
/// a part of it), then each other stage by name (setting isolated points aside and the
/// polish as their [`super::ablation::Stage`]s are named, `model_choice`); `total` is all
/// of it.
#[derive(Clone, Debug, Default, Serialize, utoipa::ToSchema)]
pub struct Timing {
    pub stage1: f64,
    pub stage2: f64,
    /// the noise model's share of stage 2
    pub noise_model: f64,
    #[serde(skip_serializing_if = "std::collections::BTreeMap::is_empty")]
    pub stages: std::collections::BTreeMap<String, f64>,
    /// the stages that did not run, or were cut short, because the fit's time had
    /// reached its budget ([`super::FitOptions::time_budget_ms`]): `search` where its
    /// likelihood steps stopped there, `polish-on-more-points` where the polish did not
    /// start
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub over_budget: Vec<String>,
    pub total: f64,
}

#[derive(Clone, Debug, Serialize, utoipa::ToSchema)]
pub struct Iterations {
    pub stage1: usize,
    pub stage2: usize,
}

#[derive(Clone, Debug, Serialize, utoipa::ToSchema)]
pub struct BackendOut {
    pub kind: String,
    pub adapter: String,
}

impl BackendOut {
    /// The evaluator a fit ran on.
    pub fn of(evaluator: &dyn crate::eval::Evaluator) -> Self {
        Self {
            kind: evaluator.kind().into(),
            adapter: evaluator.device_name(),
        }
    }
}

#[derive(Clone, Debug, Serialize, utoipa::ToSchema)]
pub struct PointsOut {
    pub input: usize,
    pub stage1: usize,
    pub stage2: usize,
    /// the points of the final polish, where one ran (the noise model's, or a precise
    /// misfit's; see [`super::FitOptions::polish_points`])
    #[serde(skip_serializing_if = "Option::is_none")]
    pub polish: Option<usize>,
    /// the points far from every other, set aside before the fit
    /// ([`super::isolated`]): the fit and its quality are the other points'
    #[serde(skip_serializing_if = "is_zero")]
    pub isolated: usize,
    /// the even stride of the input the fit read, where the input held more than
    /// [`super::MAX_FIT_POINTS`] points (`isolated` counts among these)
    #[serde(skip_serializing_if = "Option::is_none")]
    pub thinned_to: Option<usize>,
}

fn is_zero(n: &usize) -> bool {
    *n == 0
}

/// What the search tried and what it kept (the default method): the starts of its broad
/// set, the candidates round 1 kept in distinct basins, those round 2 refined and by
/// which estimator, the finalists that converged; for a cloud read two ways (a view
/// from its frame's origin, and from nowhere), how far the reading not taken went.
#[derive(Clone, Debug, Serialize, utoipa::ToSchema)]
pub struct SearchOut {
    pub starts: usize,
    pub kept: usize,
    pub refined: usize,
    /// `likelihood` (a noisy cloud) or `least_squares` (a precise one)
    pub estimator: String,
    pub finalists: usize,
    /// the other reading of an inferred view: `round 1`, `round 2` (dropped after it,
    /// plainly less likely) or `finalists` (searched to the end, less likely)
    #[serde(skip_serializing_if = "Option::is_none")]
    pub other_reading_went_to: Option<String>,
}

/// The result of `supertoroid fit` (and of the service), documented in the README.
#[derive(Clone, Debug, Serialize, utoipa::ToSchema)]
pub struct FitReport {
    pub method: Method,
    /// the model the fit answers with, and how it was chosen
    pub model: super::model_choice::ModelOut,
    pub shape: Shape,
    pub pose: PoseOut,
    pub quality: Quality,
    pub timing_ms: Timing,
    pub iterations: Iterations,
    pub backend: BackendOut,
    /// the viewpoint the fit used, where it came from and why
    pub viewpoint: super::ViewpointUsed,
    pub points: PointsOut,
    /// what the search tried and kept; absent for `method=paper`
    #[serde(skip_serializing_if = "Option::is_none")]
    pub search: Option<SearchOut>,
    /// what the caller should know about this fit (e.g. a viewpoint that was ignored);
    /// absent when there is nothing
    #[serde(skip_serializing_if = "Vec::is_empty")]
    #[schema(value_type = Option<Vec<String>>)]
    pub warnings: Vec<String>,
    #[serde(skip)]
    pub fitted: (Shape, Pose),
}

/// A fit as the search hands it on to the stages after it: its report, and what those
/// stages read of it that a caller is not given.
pub(super) struct Searched {
    pub report: FitReport,
    /// the fraction of the stage-2 free-space points that lie inside the fit (see
    /// [`super::free_space::violated_fraction`]); None without a viewpoint
    pub free_space_violation: Option<f64>,
    /// the noise model refined this fit at a noise that matters to it, so the polish
    /// takes it on ([`Quality::noise_sigma`] is then the model's)
    pub noise_modelled: bool,
}

/// The warning of a fit that stays off a precise cloud: its median distance above
/// rounding but under [`super::PRECISE_MISFIT`]'s end of the size, where a noise-free cloud
/// (a CAD model's, a simulator's) fitted in the right basin leaves rounding (below 1e-6
/// of the size on the suite's noise-free clouds) and a depth sensor's noise leaves far
/// more. A real sensor with noise under about 0.15% of the object's size would be warned
/// too, which the message says (on the broadened views, half-metre rings seen by a
/// D435-like camera: `docs/fit.md`, "Warnings").
pub(super) fn misfit_warning(shape: &Shape, quality: &Quality) -> Option<String> {
    let relative = quality.median_distance / shape.size();
    super::PRECISE_MISFIT.contains(&relative).then(|| {
        format!(
            "off a precise cloud: the median distance is {relative:.1e} of the size; a \
             noise-free cloud (CAD, simulation) fitted in the right basin leaves rounding, so \
             unless the sensor's noise is about this small (a precise scanner, or an object \
             large against a depth camera's millimetre) the fit is in a wrong basin and sizes \
             and eps may be far off"
        )
    })
}

/// At most this many points, evenly spread, give a fit's report its [`Quality`]
/// distances: a depth mask's tens of thousands tell an RMS and a median no better, and
/// cost the report most of its time.
pub const QUALITY_SAMPLE: usize = 8000;

/// Distances of every input point to the fitted surface, summarised.
pub fn quality(shape: &Shape, pose: &Pose, points: &[DVec3]) -> Quality {
    quality_on(shape, pose, points, usize::MAX)
}

/// [`quality`] on an even stride of at most `sample` of the points.
pub(super) fn quality_on(shape: &Shape, pose: &Pose, points: &[DVec3], sample: usize) -> Quality {
    use rayon::prelude::*;
    let stride = points.len().div_ceil(sample.max(1)).max(1);
    let mut d: Vec<f64> = points
        .par_iter()
        .step_by(stride)
        .map(|p| meridian_distance(shape, pose.to_canonical(*p)).distance)
        .collect();
    let rms = (d.iter().map(|x| x * x).sum::<f64>() / d.len().max(1) as f64).sqrt();
    let size = shape.size();
    let inliers = d.iter().filter(|&&x| x <= 0.02 * size).count() as f64 / d.len().max(1) as f64;
    Quality {
        rms_distance: rms,
        median_distance: median(&mut d),
        relative_rms: rms / size,
        inlier_fraction: inliers,
        noise_sigma: noise_sigma(shape, pose, points, NOISE_SAMPLE),
        visible_coverage: None,
        standard_errors: None,
    }
}

/// At most this many points, evenly spread, estimate [`Quality::noise_sigma`]: a median
/// needs no more, and the gradient costs thrice the distance.
pub const NOISE_SAMPLE: usize = 2000;

/// The noise sigma about a fit: 1.4826 · the median first-order Euclidean distance
/// |r| / |grad r| over at most `sample` evenly spread points. (The meridian distance runs
/// along a ray from the section centre; off a thin section's flat faces that ray meets
/// the surface at a glancing angle and stretches the noise: 1 mm of noise on a 2 x 10 cm
/// section reads 1.75 mm.)
pub fn noise_sigma(shape: &Shape, pose: &Pose, points: &[DVec3], sample: usize) -> f64 {
    use rayon::prelude::*;
    let stride = points.len().div_ceil(sample.max(1)).max(1);
    let mut euclidean: Vec<f64> = points
        .par_iter()
        .step_by(stride)
        .map(|p| {
            let g = meridian_residual_with_gradient(shape, pose.to_canonical(*p));
            let slope = g.d_point.length();
            let r = g.residual.abs();
            // (never more than the meridian distance, itself a distance to a surface point)
            if slope > 1.0 { r / slope } else { r }
        })
        .collect();
    1.4826 * median(&mut euclidean)
}

/// The upper median (0 for no values); reorders `values`.
pub(crate) fn median(values: &mut [f64]) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    let half = values.len() / 2;
    *values.select_nth_unstable_by(half, f64::total_cmp).1
}

/// Reads shape and pose back from the JSON of a [`FitReport`] (what `supertoroid fit`
/// prints and the service answers): `shape`, `pose.translation`, `pose.quaternion_wxyz`.
pub fn parse_report_json(bytes: &[u8]) -> Result<(Shape, Pose), String> {
    let object: crate::model::FittedObject =
        serde_json::from_slice(bytes).map_err(|e| e.to_string())?;
    object.validated()
}

/// The report of one cloud's chosen solution, in world units, with what the stages
/// after the search read of it.
pub(super) fn report(
    p: &Prepared,
    candidate: &Candidate,
    stage2_iterations: usize,
    modelled_sigma: Option<f64>,
    stage1_iterations: usize,
    backend: BackendOut,
) -> Searched {
    let (shape, pose) = p.norm.to_world(candidate);
    let mut quality = quality_on(&shape, &pose, p.points, QUALITY_SAMPLE);
    // the noise model's sigma, where it ran, is the better estimate (the first-order
    // distance reads noise off a thin section's curved faces short)
    if let Some(sigma) = modelled_sigma {
        quality.noise_sigma = sigma * p.norm.scale;
    }
    quality.visible_coverage = p
        .sight()
        .map(|s| coverage::visible_coverage(candidate, &p.stage2_pts, s));
    quality.standard_errors =
        uncertainty::standard_errors(&shape, &pose, p.points, &p.known.map(|k| k.is_some()));
    // a fit the likelihood refined: each error as loose as the likelihood leaves it
    if let (Some(errors), Some(sigma)) = (quality.standard_errors.as_mut(), modelled_sigma) {
        let sample = search::Sample::new(&p.stage2_pts, p.sight(), false);
        let data = sample.data();
        let held = p.known.map(|k| k.is_some());
        if let Some(by_likelihood) =
            uncertainty::likelihood_errors(&data, candidate, sigma, p.points.len(), &held)
        {
            *errors = errors.max(by_likelihood);
        }
    }
    let warnings = quality
        .standard_errors
        .as_ref()
        .and_then(uncertainty::warning)
        .into_iter()
        .chain(misfit_warning(&shape, &quality))
        .collect();
    let r = pose.matrix();
    let q = pose.rotation;
    let report = FitReport {
        method: p.method,
        model: ModelOut::requested(&shape),
        shape,
        pose: PoseOut {
            translation: pose.translation.to_array(),
            rotation: [
                r.row(0).to_array(),
                r.row(1).to_array(),
                r.row(2).to_array(),
            ],
            quaternion_wxyz: [q.w, q.x, q.y, q.z],
        },
        quality,
        // set by the caller once every report of the group is done
        timing_ms: Timing::default(),
        iterations: Iterations {
            stage1: stage1_iterations,
            stage2: stage2_iterations,
        },
        backend,
        // set by `fit_batch` from the viewpoint's resolution
        viewpoint: ViewpointUsed::default(),
        points: PointsOut {
            input: p.points.len(),
            stage1: p.stage1_pts.len(),
            stage2: p.stage2_pts.len(),
            polish: None,
            isolated: 0,
            thinned_to: None,
        },
        // set by the search
        search: None,
        warnings,
        fitted: (shape, pose),
    };
    Searched {
        report,
        free_space_violation: (!p.stage2_free.is_empty())
            .then(|| free_space::violated_fraction(candidate, &p.stage2_free)),
        noise_modelled: modelled_sigma.is_some(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_a_fit_off_a_precise_cloud_by_more_than_rounding_is_warned() {
        let shape = Shape::new(0.05, 0.05, 0.02, 2.0, 1.0, 1.0);
        let at = |relative: f64| Quality {
            rms_distance: 0.0,
            median_distance: relative * shape.size(),
            relative_rms: 0.0,
            inlier_fraction: 1.0,
            noise_sigma: 0.0,
            visible_coverage: None,
            standard_errors: None,
        };
        // rounding, a wrong basin of a noise-free cloud, a sensor's noise
        assert!(misfit_warning(&shape, &at(1e-8)).is_none());
        let warned = misfit_warning(&shape, &at(1e-4)).expect("a misfit of 1e-4 is warned");
        assert!(warned.starts_with("off a precise cloud"), "{warned}");
        assert!(warned.contains("1.0e-4"), "{warned}");
        // from the band's end `off its points` judges it against the cloud's scatter
        assert!(misfit_warning(&shape, &at(super::super::PRECISE_MISFIT.end)).is_none());
        assert!(misfit_warning(&shape, &at(5e-3)).is_none());
    }
}

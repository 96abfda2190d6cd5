//! Viewpoints the fit inferred rather than was given ([`super::Viewpoint::Auto`] resolved
//! to the frame's origin): the test that keeps or drops one, and what the report says of
//! the viewpoint a fit used.

use super::{
    FitError, FitOptions, FitReport, LIKELIHOOD_OUTLIER_WEIGHT, VIEWPOINT_IGNORED, Viewpoint,
    ViewpointSource, ViewpointUsed, coverage, fit_batch_once, likelihood,
};
use crate::eval::{Evaluator, Normalization};
use glam::DVec3;
use std::time::Instant;

/// Points of the cloud the test of [`more_likely_all_round`] scores (an even stride).
const VIEW_TEST_POINTS: usize = 1000;
/// The least sigma (normalised units) the test scores at: a noise-free cloud's fit
/// leaves rounding, and the model's grid would grow without bound.
const VIEW_TEST_MIN_SIGMA: f64 = 0.01;

/// Whether the noise model finds the points more likely spread all round a fit made
/// from an inferred viewpoint than seen from that viewpoint. A view's points lie on the
/// side that faced the sensor, so spreading the density over the whole surface roughly
/// halves it; an all-round cloud's far side is all but impossible as a view, unless its
/// section is thinner than the noise. False where the model does not run (no hole).
/// The cloud normalised, and an even stride of about `count` of its points in that frame.
pub(super) fn normalised_stride(points: &[DVec3], count: usize) -> (Normalization, Vec<DVec3>) {
    let norm = Normalization::of(points);
    let sample = points
        .iter()
        .step_by(points.len().div_ceil(count).max(1))
        .map(|p| norm.point(*p))
        .collect();
    (norm, sample)
}

fn more_likely_all_round(points: &[DVec3], options: &FitOptions, r: &FitReport) -> bool {
    let Some(viewpoint) = options.viewpoint.position() else {
        return false;
    };
    let (norm, sample) = normalised_stride(points, VIEW_TEST_POINTS);
    let candidate = norm.candidate(&r.fitted.0, &r.fitted.1);
    let sigma = (r.quality.noise_sigma / norm.scale).max(VIEW_TEST_MIN_SIGMA);
    let score = |v| likelihood::objective(&sample, &candidate, sigma, LIKELIHOOD_OUTLIER_WEIGHT, v);
    match (score(None), score(Some(norm.point(viewpoint)))) {
        (Some(all_round), Some(view)) => all_round < view,
        _ => false,
    }
}

/// A viewpoint only inferred stands unless the points are more likely all round the fit
/// made from it ([`more_likely_all_round`]): such a cloud is fitted again as a view from
/// nowhere (one more fit). Returns the clouds so refitted.
pub(super) fn settle_inferred_viewpoints(
    evaluator: &mut dyn Evaluator,
    clouds: &[(&[DVec3], &FitOptions)],
    results: &mut [Result<FitReport, FitError>],
) -> Result<Vec<usize>, FitError> {
    let start = Instant::now();
    let all_round: Vec<usize> = (0..clouds.len())
        .filter(|&i| {
            let (points, options) = clouds[i];
            // a fit that leaves its visible surface bare is the retries' to mend first:
            // its view is no fair test
            inferred(options)
                && results[i].as_ref().is_ok_and(|r| {
                    r.quality
                        .visible_coverage
                        .is_some_and(|c| c >= coverage::MIN_VISIBLE_COVERAGE)
                        && more_likely_all_round(points, options, r)
                })
        })
        .collect();
    let options = options_without_viewpoint(clouds, &all_round);
    let refits = fit_batch_once(evaluator, &batch_of(clouds, &all_round, &options))?;
    let waited = start.elapsed().as_secs_f64() * 1e3;
    for (i, r) in results.iter_mut().enumerate() {
        if let (true, Ok(r)) = (inferred(clouds[i].1), r) {
            r.timing_ms.total += waited;
        }
    }
    for (&i, refit) in all_round.iter().zip(refits) {
        let spent = results[i].as_ref().map_or(0.0, |r| r.timing_ms.total);
        results[i] = refit.map(|mut r| {
            r.timing_ms.total = spent;
            r
        });
    }
    Ok(all_round)
}

/// Whether `options` hold a viewpoint that was only inferred ([`Viewpoint::Auto`]
/// resolved to the frame's origin).
pub(super) fn inferred(options: &FitOptions) -> bool {
    matches!(
        options.viewpoint,
        Viewpoint::At(_, ViewpointSource::FrameOrigin)
    )
}

/// The clouds with their resolved options.
pub(super) fn with_resolved<'a>(
    clouds: &[(&'a [DVec3], &FitOptions)],
    resolved: &'a [(FitOptions, ViewpointUsed)],
) -> Vec<(&'a [DVec3], &'a FitOptions)> {
    clouds
        .iter()
        .zip(resolved)
        .map(|((points, _), (o, _))| (*points, o))
        .collect()
}

/// What the report says of the viewpoint: as resolved, unless the fit found it
/// contradicted by the points and fitted without it
/// (`refit_without_inconsistent_viewpoints`). A viewpoint only inferred is then no
/// warning, only a reason: nobody told the fit it was there.
pub(super) fn report_viewpoint(used: ViewpointUsed, r: &mut FitReport) {
    let ignored = r
        .warnings
        .iter()
        .position(|w| w.starts_with(VIEWPOINT_IGNORED));
    r.viewpoint = match ignored {
        Some(k) if used.position.is_some() => {
            let warning = if used.source == ViewpointSource::FrameOrigin {
                r.warnings.remove(k)
            } else {
                r.warnings[k].clone()
            };
            ViewpointUsed {
                position: None,
                source: ViewpointSource::None,
                reason: format!("{}, but {warning}", used.reason),
            }
        }
        _ => used,
    };
}

/// The options of the clouds `indices` without their viewpoint, to fit them again as
/// views from nowhere.
pub(super) fn options_without_viewpoint(
    clouds: &[(&[DVec3], &FitOptions)],
    indices: &[usize],
) -> Vec<FitOptions> {
    indices
        .iter()
        .map(|&i| FitOptions {
            viewpoint: Viewpoint::None,
            ..clouds[i].1.clone()
        })
        .collect()
}

/// The clouds `indices`, each with its options from `options` (in the same order).
pub(super) fn batch_of<'a>(
    clouds: &[(&'a [DVec3], &FitOptions)],
    indices: &[usize],
    options: &'a [FitOptions],
) -> Vec<(&'a [DVec3], &'a FitOptions)> {
    indices
        .iter()
        .zip(options)
        .map(|(&i, o)| (clouds[i].0, o))
        .collect()
}

//! The search's last step: the fit the likelihood refined, refined once more by the noise
//! model's surface grid ([`likelihood::refine_finely`]) on up to
//! [`FitOptions::polish_points`] of the cloud's points, its top view read both ways; and
//! the warning of a fit left far off its points.
//!
//! Why a second estimator of the same model: the search's per-point quadrature
//! ([`super::objective`]) ranks candidates fast, but on noisy single views its optimum
//! sits off the grid model's (eps off by 0.15-0.5 on thin sections, where the grid's
//! cells at most 2 sigma across describe the blur better). Measured (camera frame, no
//! options, CPU; `docs/fit.md`): the search alone 95.6% of sets 420000/440000's views,
//! with the polish 97.8%.

use super::*;

/// The default of [`FitOptions::polish_points`]: every point of the suite's clouds (2000
/// surface points and up to 10% outliers), a few times the stage-2 sample of a robot's
/// cloud.
pub const POLISH_POINTS: usize = 4000;

/// How much more likely (mean log-likelihood per point) the other reading of a top view
/// must be than the polished fit to replace it: on all 2000 points of the suite's noisy
/// single views the wrong reading was never the more likely one, so the likelier wins.
pub const POLISH_DUAL_MARGIN: f64 = 0.0;

/// A top view whose eps2 is within this of 1 (an ellipse) is not read the other way: its
/// other reading (2 - eps2) is within the suite's eps tolerance of 0.15 of it.
pub const DUAL_MIN_ROUNDNESS_GAP: f64 = 0.07;
/// The other reading goes on to convergence only when it is more likely than the model's
/// fit after this many iterations. Interleaved on fresh sets 1020000 and 1030000 (camera
/// frame, no options, 360 cases): 5 against 8 changed no case and took the polish's mean
/// from 63 to 56 ms. With a 500-point stage 2, 3 iterations lost a case of sets
/// 950000/960000, and leaving the other reading out (a polish's mean of 39 ms) lost 3 of
/// sets 930000/940000's 360 cases.
const DUAL_FIRST_ITERATIONS: usize = 5;

/// Polishes each modelled fit of `results` (see the module docs) unless its time so far
/// is over its [`FitOptions::time_budget_ms`]. The polished fit replaces the fit unless
/// it breaks the free space the fit kept; its time is reported under the stage's name.
/// The clouds are polished side by side (a batch's, a scene's objects): each polish is
/// its own, so a cloud's fit is the same alone or in a batch.
pub(super) fn polish(
    clouds: &[(&[DVec3], &FitOptions)],
    results: &mut [Result<Searched, FitError>],
) {
    results
        .par_iter_mut()
        .zip(clouds)
        .for_each(|(result, (cloud, options))| polish_one(cloud, options, result));
}

/// [`polish`] of one cloud's fit.
fn polish_one(cloud: &[DVec3], options: &FitOptions, result: &mut Result<Searched, FitError>) {
    let Ok(searched) = result.as_mut() else {
        return;
    };
    if !searched.noise_modelled
        || options.polish_points == 0
        || options.skip.contains(&Stage::PolishOnMorePoints)
    {
        return;
    }
    if options
        .time_budget_ms
        .is_some_and(|budget| searched.report.timing_ms.total > budget)
    {
        searched
            .report
            .timing_ms
            .over_budget
            .push(ablation::name(Stage::PolishOnMorePoints));
        return;
    }
    let fitted = &searched.report;
    let start = Instant::now();
    let polish_options = FitOptions {
        stage2_points: options.polish_points,
        // (what is left of the budget bounds the polish's own steps)
        time_budget_ms: options.budget_left(fitted.timing_ms.total),
        ..(*options).clone()
    };
    let Ok(p) = prepare(cloud, &polish_options, StartSet::Usual) else {
        return;
    };
    let c = p.norm.candidate(&fitted.fitted.0, &fitted.fitted.1);
    let sigma = fitted.quality.noise_sigma / p.norm.scale;
    let Some(refined) = refine_both_readings(&p, &c, sigma, POLISH_DUAL_MARGIN) else {
        return;
    };
    let refined_by = Instant::now();
    let mut polished = report(
        &p,
        &refined.candidate,
        fitted.iterations.stage2 + refined.iterations,
        Some(refined.sigma),
        fitted.iterations.stage1,
        fitted.backend.clone(),
    );
    let keeps_free_space = |r: &Searched| {
        r.free_space_violation
            .is_none_or(|v| v <= free_space::MAX_VIOLATED_FRACTION)
    };
    if keeps_free_space(searched) && !keeps_free_space(&polished) {
        return;
    }
    let report = &mut polished.report;
    warn_off_its_points(report, &p);
    let spent = start.elapsed().as_secs_f64() * 1e3;
    report.timing_ms = fitted.timing_ms.clone();
    if p.deadline.is_some_and(|d| refined_by >= d) {
        report
            .timing_ms
            .over_budget
            .push(ablation::name(Stage::PolishOnMorePoints));
    }
    report.timing_ms.total += spent;
    report
        .timing_ms
        .stages
        .insert(ablation::name(Stage::PolishOnMorePoints), spent);
    report.points = PointsOut {
        polish: Some(p.stage2_pts.len()),
        ..fitted.points.clone()
    };
    report.search = fitted.search.clone();
    *searched = polished;
}

/// The noise model's maximum-likelihood fit from `c` at noise `sigma` (normalised units)
/// on the sample of `p`, and from the other reading of its top view
/// ([`Prepared::turned_dual`]), which replaces it when more likely by `dual_margin`
/// (mean log-likelihood per point); none where the model collapses.
fn refine_both_readings(
    p: &Prepared,
    c: &Candidate,
    sigma: f64,
    dual_margin: f64,
) -> Option<likelihood::Refined> {
    let limits = p.likelihood_limits(c);
    let refine = |start: &Candidate, sigma: f64, iterations: usize| {
        likelihood::refine_finely(
            &p.stage2_pts,
            start,
            sigma,
            LIKELIHOOD_OUTLIER_WEIGHT,
            p.sight(),
            &limits,
            iterations,
        )
    };
    // (a model that explains the points only by blurring them far more than the fit
    // found is a collapsed one)
    let not_collapsed =
        |r: &likelihood::Refined| r.sigma <= MAX_SIGMA_GROWTH * sigma && !collapsed_section(r);
    let mut refined = refine(c, sigma, likelihood::MAX_ITERATIONS).filter(not_collapsed);
    // the top view's other reading; a few steps tell the plainly less likely ones, which
    // go no further
    let (model_fit, model_sigma) = refined.map_or((*c, sigma), |r| (r.candidate, r.sigma));
    if !p.skip.contains(&Stage::DualReading)
        && let Some(dual) = p.turned_dual(&model_fit)
        && let Some(first) = refine(&dual, model_sigma, DUAL_FIRST_ITERATIONS)
        && refined.is_none_or(|best| first.objective < best.objective)
        && let Some(r) =
            refine(&first.candidate, first.sigma, likelihood::MAX_ITERATIONS).filter(not_collapsed)
        && refined.is_none_or(|best| r.objective + dual_margin < best.objective)
    {
        refined = Some(likelihood::Refined {
            iterations: first.iterations + r.iterations,
            ..r
        });
    }
    refined
}

/// Adds [`off_its_points`]'s warning to the report `r` of a fit of `p`.
pub(super) fn warn_off_its_points(r: &mut FitReport, p: &Prepared) {
    let (median, size) = (r.quality.median_distance, r.fitted.0.size());
    r.warnings.extend(off_its_points(median, size, || {
        p.scatter().map(|s| s * p.norm.scale)
    }));
}

/// A fit whose median distance is at least [`PRECISE_MISFIT`]'s end of its size (where
/// `off a precise cloud` stops warning) and more than [`MISFIT_OVER_SCATTER`] times the
/// cloud's own scatter ([`scatter::local_scatter`]) is in a wrong basin, or the object is
/// not a supertoroid; one over [`MISFIT_OF_SIZE`] of its size fits no surface the points
/// pin down: the warning that says so.
fn off_its_points(median: f64, size: f64, scatter: impl FnOnce() -> Option<f64>) -> Option<String> {
    if median / size < PRECISE_MISFIT.end {
        return None;
    }
    if median > MISFIT_OF_SIZE * size {
        return Some(format!(
            "{OFF_ITS_POINTS_WARNING}: the median distance is {:.0}% of the size (over {:.0}%), \
             so the points are far noisier than the shape's detail or do not lie on one \
             surface (a volume of points, a wrong column read as depth); shape and pose may be \
             far off",
            100.0 * median / size,
            100.0 * MISFIT_OF_SIZE
        ));
    }
    let scatter = scatter()?;
    (median > MISFIT_OVER_SCATTER * scatter).then(|| {
        format!(
            "{OFF_ITS_POINTS_WARNING}: the median distance is {:.0} times the points' own \
             scatter about a smooth surface (over {MISFIT_OVER_SCATTER}), so the fit is in a \
             wrong basin or the object is not a supertoroid; shape and pose may be far off",
            median / scatter
        )
    })
}

/// The largest median distance of a fit, as a share of its size, that carries no
/// warning whatever the cloud's scatter: no right fit of the suite's noisiest clouds
/// (2% noise, the meridian distance stretched off thin sections) leaves over 4.1%, while
/// points that fill a volume leave 8-12% (a solid ball, a cube, a Gaussian blob of
/// random points), and their scatter grows with them.
pub const MISFIT_OF_SIZE: f64 = 0.06;

/// How the warning of [`off_its_points`] begins.
pub const OFF_ITS_POINTS_WARNING: &str = "off its points";

/// A median distance over the size in this band is above rounding on a precise cloud: a
/// noise-free cloud fitted in the right basin leaves rounding (below 1e-6 of the size on
/// the suite's noise-free clouds), a depth sensor's noise far more. Within it a fit is
/// warned `off a precise cloud` ([`report`]'s `misfit_warning`); from its end the
/// cloud's own scatter is the reference instead ([`MISFIT_OVER_SCATTER`]), which tells a
/// real sensor's noise from a wrong basin, so every median distance above rounding
/// meets one test or the other.
pub const PRECISE_MISFIT: std::ops::Range<f64> = 1e-5..1e-3;

/// The largest median distance of a fit over the cloud's own scatter (an RMS: a
/// Gaussian's median distance is 0.67 of it) that carries no warning. On the suite's
/// single views the right fits left at most 2.5 (outliers raise the median), the wrong
/// basins 4.2 to 72; a real object is never exactly a supertoroid: the paper's pot
/// leaves 5.5 (its wall and rim), the roll 2.7, the gear 2.0.
pub const MISFIT_OVER_SCATTER: f64 = 10.0;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_fit_is_judged_against_its_scatter_from_where_the_precise_band_ends() {
        let size = 0.1;
        let median = |relative: f64| relative * size;
        // within the precise band the other warning judges it: the scatter is not asked
        let unasked = || -> Option<f64> { panic!("the scatter was asked for") };
        assert!(off_its_points(median(5e-4), size, unasked).is_none());
        // from its end on: far over the cloud's scatter is warned, a sensor's noise is not
        let at_end = median(PRECISE_MISFIT.end);
        let warned = off_its_points(at_end, size, || Some(at_end / 15.0)).expect("warned");
        assert!(warned.starts_with(OFF_ITS_POINTS_WARNING), "{warned}");
        assert!(warned.contains("15 times"), "{warned}");
        assert!(off_its_points(at_end, size, || Some(at_end / 2.0)).is_none());
        // a cloud too small for a scatter is not judged
        assert!(off_its_points(median(1e-2), size, || None).is_none());
    }

    #[test]
    fn a_fit_far_off_its_points_for_its_size_is_warned_whatever_their_scatter() {
        let size = 0.1;
        let far = 1.5 * MISFIT_OF_SIZE * size;
        let unasked = || -> Option<f64> { panic!("the scatter was asked for") };
        let warned = off_its_points(far, size, unasked).expect("warned");
        assert!(warned.starts_with(OFF_ITS_POINTS_WARNING), "{warned}");
        assert!(warned.contains("9% of the size"), "{warned}");
        // under the bound, a scatter as large as the misfit lets it pass
        let near = 0.5 * MISFIT_OF_SIZE * size;
        assert!(off_its_points(near, size, || Some(near)).is_none());
    }
}

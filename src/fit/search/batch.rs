//! The search for a batch of clouds: their viewpoints resolved, a cloud whose viewpoint
//! was only inferred searched in both readings, a given viewpoint the fit contradicts
//! dropped, the groups of clouds that share solver settings searched ([`search_group`])
//! and reported.

use super::*;

/// [`fit_batch`] for a batch: the clouds of the default method searched, the paper's
/// fitted by its own procedure, the answers in the callers' order.
pub(in crate::fit) fn fit_batch_by_method(
    evaluator: &mut dyn Evaluator,
    clouds: &[(&[DVec3], &FitOptions)],
) -> Result<Vec<Result<FitReport, FitError>>, FitError> {
    let searched: Vec<bool> = clouds
        .iter()
        .map(|(_, o)| o.method == Method::Default)
        .collect();
    let pick = |want: bool| -> Vec<_> {
        clouds
            .iter()
            .zip(&searched)
            .filter(|(_, s)| **s == want)
            .map(|(cloud, _)| *cloud)
            .collect()
    };
    let mut found = fit_batch_searched(evaluator, &pick(true))?.into_iter();
    let mut fitted = fit_batch_paper(evaluator, &pick(false))?.into_iter();
    Ok(searched
        .iter()
        .map(|&s| if s { found.next() } else { fitted.next() })
        .map(|r| r.expect("one answer per cloud"))
        .collect())
}

/// [`fit_batch`] by one bounded search ([`super`]). Each cloud's viewpoint is resolved
/// first; a cloud whose viewpoint was only inferred (the frame's origin) is searched
/// both as a view from there and as a view from nowhere, in the same lockstep batch, and
/// the fit more likely under its own reading of the cloud stands. A given viewpoint that
/// the fit contradicts is dropped with a warning and the cloud searched again. Then the
/// polish ([`polish::polish`]), in the reading each cloud was fitted in.
fn fit_batch_searched(
    evaluator: &mut dyn Evaluator,
    clouds: &[(&[DVec3], &FitOptions)],
) -> Result<Vec<Result<FitReport, FitError>>, FitError> {
    let mut resolved = resolve_viewpoints(clouds);
    // the inferred views' other reading, searched beside them
    let nowhere: Vec<(usize, FitOptions)> = resolved
        .iter()
        .enumerate()
        .filter(|(_, (o, _))| inferred(o) && !o.skip.contains(&Stage::SettleInferredView))
        .map(|(i, (o, _))| {
            (
                i,
                FitOptions {
                    viewpoint: Viewpoint::None,
                    ..o.clone()
                },
            )
        })
        .collect();
    let mut batch = with_resolved(clouds, &resolved);
    batch.extend(nowhere.iter().map(|(i, o)| (clouds[*i].0, o)));
    let twins: Vec<(usize, usize)> = nowhere
        .iter()
        .enumerate()
        .map(|(k, (i, _))| (*i, clouds.len() + k))
        .collect();
    let (mut results, dropped) = searched_once(evaluator, &batch, &twins)?;
    let others = results.split_off(clouds.len());
    settle_inferred_views(
        clouds,
        &nowhere,
        others,
        &dropped,
        &mut resolved,
        &mut results,
    );
    // (the search's own warnings, added once the polish has judged the fit: a viewpoint
    // dropped here, a budget that cut the search short)
    let search_warnings = refit_contradicted_views(evaluator, clouds, &mut resolved, &mut results)?;
    polish::polish(&with_resolved(clouds, &resolved), &mut results);
    let mut reports: Vec<Result<FitReport, FitError>> = results
        .into_iter()
        .map(|r| r.map(|searched| searched.report))
        .collect();
    for (i, warning) in search_warnings {
        if let Ok(r) = &mut reports[i] {
            r.warnings.push(warning);
        }
    }
    for (r, (_, used)) in reports.iter_mut().zip(resolved) {
        if let Ok(r) = r {
            r.viewpoint = used;
            if r.timing_ms
                .over_budget
                .iter()
                .any(|s| s == SEARCH_CUT_SHORT)
            {
                r.warnings.push(BUDGET_CUT_WARNING.into());
            }
        }
    }
    Ok(reports)
}

/// Each inferred view's fit against its other reading's, `others` (the cloud searched as
/// a view from nowhere, `nowhere`): the reading under which its own fit is the likelier
/// stands, in `results` and in the viewpoint `resolved`; either reading's search stopped
/// early for its twin (`dropped`) loses.
fn settle_inferred_views(
    clouds: &[(&[DVec3], &FitOptions)],
    nowhere: &[(usize, FitOptions)],
    others: Vec<Result<Searched, FitError>>,
    dropped: &[Option<&'static str>],
    resolved: &mut [(FitOptions, ViewpointUsed)],
    results: &mut [Result<Searched, FitError>],
) {
    for (k, ((i, options), other)) in nowhere.iter().zip(others).enumerate() {
        let (Ok(view), Ok(other)) = (&results[*i], other) else {
            continue;
        };
        let viewpoint = resolved[*i]
            .0
            .viewpoint
            .position()
            .expect("an inferred viewpoint");
        let test = ViewTest::new(clouds[*i].0, viewpoint, options.stage2_points);
        // (negative log-likelihoods: lower is likelier)
        let (view_stopped, other_stopped) = (dropped[*i], dropped[clouds.len() + k]);
        let all_round = match (view_stopped, other_stopped) {
            (Some(_), _) => true,
            (_, Some(_)) => false,
            _ => test.score(&other.report, false) < test.score(&view.report, true),
        };
        let went_to = if all_round {
            resolved[*i].0.viewpoint = Viewpoint::None;
            resolved[*i].1 = resolved[*i].1.dropped(ALL_ROUND);
            results[*i] = Ok(other);
            view_stopped
        } else {
            other_stopped
        };
        if let Ok(taken) = &mut results[*i]
            && let Some(search) = &mut taken.report.search
        {
            search.other_reading_went_to = Some(went_to.unwrap_or("finalists").into());
        }
    }
}

/// The clouds whose given viewpoint their fit contradicts (more of its free-space
/// points inside the fit than [`free_space::MAX_VIOLATED_FRACTION`]) searched again
/// without it, in `results` and in `resolved`; with the warning each is to carry.
fn refit_contradicted_views(
    evaluator: &mut dyn Evaluator,
    clouds: &[(&[DVec3], &FitOptions)],
    resolved: &mut [(FitOptions, ViewpointUsed)],
    results: &mut [Result<Searched, FitError>],
) -> Result<Vec<(usize, String)>, FitError> {
    let contradicted: Vec<(usize, f64)> = results
        .iter()
        .enumerate()
        .filter_map(|(i, r)| {
            let violated = r.as_ref().ok()?.free_space_violation?;
            (violated > free_space::MAX_VIOLATED_FRACTION
                && !inferred(&resolved[i].0)
                && !resolved[i].0.skip.contains(&Stage::InconsistentViewpoint))
            .then_some((i, violated))
        })
        .collect();
    if contradicted.is_empty() {
        return Ok(Vec::new());
    }
    let total =
        |r: &Result<Searched, FitError>| r.as_ref().map_or(0.0, |r| r.report.timing_ms.total);
    let started = Instant::now();
    let options: Vec<FitOptions> = contradicted
        .iter()
        .map(|&(i, _)| FitOptions {
            viewpoint: Viewpoint::None,
            // (the refit has what is left of the budget)
            time_budget_ms: resolved[i].0.budget_left(total(&results[i])),
            ..resolved[i].0.clone()
        })
        .collect();
    let batch: Vec<(&[DVec3], &FitOptions)> = contradicted
        .iter()
        .zip(&options)
        .map(|(&(i, _), o)| (clouds[i].0, o))
        .collect();
    let (refits, _) = searched_once(evaluator, &batch, &[])?;
    let waited = started.elapsed().as_secs_f64() * 1e3;
    let mut warnings = Vec::new();
    for (&(i, violated), refit) in contradicted.iter().zip(refits) {
        let spent = total(&results[i]) + waited;
        let warning = viewpoint_ignored_warning(violated);
        resolved[i].0.viewpoint = Viewpoint::None;
        resolved[i].1 = resolved[i].1.dropped(&warning);
        warnings.push((i, warning));
        results[i] = refit.map(|mut r| {
            // (the fit with the viewpoint, and the wait for the others' refits)
            let timing = &mut r.report.timing_ms;
            let first = spent - timing.total;
            timing
                .stages
                .insert(ablation::name(Stage::InconsistentViewpoint), first);
            timing.total = spent;
            r
        });
    }
    Ok(warnings)
}

/// How `timing_ms.over_budget` names a search whose likelihood refinements the time
/// budget cut short ([`FitOptions::time_budget_ms`]).
pub const SEARCH_CUT_SHORT: &str = "search";

/// The warning of a search the time budget cut short: its candidates were not refined to
/// the end, and a fit that stopped early is no answer to trust unwarned (on fresh suite
/// sets a budget of 150 ms left 5-7% of the fits wrong that were right without it,
/// `docs/fit.md`, "A time budget").
pub const BUDGET_CUT_WARNING: &str = "cut short by the time budget: the search's likelihood \
     refinements stopped at the budget before they converged, so shape and pose may be off; \
     a larger time_budget_ms, or none, lets them finish";

/// Every cloud prepared, grouped by solver settings, searched and reported; `twins` are
/// pairs of clouds that are one cloud in two readings (see [`TWIN_MARGIN`]).
/// With the round each cloud's search went no further than for its twin (None: to the
/// end).
#[allow(clippy::type_complexity)]
fn searched_once(
    evaluator: &mut dyn Evaluator,
    clouds: &[(&[DVec3], &FitOptions)],
    twins: &[(usize, usize)],
) -> Result<(Vec<Result<Searched, FitError>>, Vec<Option<&'static str>>), FitError> {
    let mut dropped = vec![None; clouds.len()];
    let start = Instant::now();
    let mut results: Vec<Option<Result<Searched, FitError>>> =
        (0..clouds.len()).map(|_| None).collect();
    let mut groups: Vec<Vec<(usize, Prepared)>> = Vec::new();
    for (i, (points, o)) in clouds.iter().enumerate() {
        match prepare(points, o, StartSet::Broad) {
            Ok(p) => match groups.iter_mut().find(|g| {
                let q = &g[0].1;
                (q.bounds, q.opts1, q.opts2) == (p.bounds, p.opts1, p.opts2)
            }) {
                Some(g) => g.push((i, p)),
                None => groups.push(vec![(i, p)]),
            },
            Err(e) => results[i] = Some(Err(e)),
        }
    }
    // (the free fits first: a superellipsoid fit takes the estimator its cloud's free
    // fit took, see [`model_twins`])
    groups.sort_by_key(|g| g[0].1.known[3].is_some());
    let model_twins = model_twins(clouds);
    let mut by_likelihood = vec![false; clouds.len()];
    let mut round1_best: Vec<Option<Round1Best>> = vec![None; clouds.len()];
    let mut free_best: Vec<Option<Candidate>> = vec![None; clouds.len()];
    let backend = BackendOut::of(evaluator);
    let device = evaluator.objective_device();
    for (_, p) in groups.iter_mut().flatten() {
        p.device = device.clone();
    }
    for mut group in groups {
        // a superellipsoid fit starts at its cloud's free fit's outline too (both clouds
        // share one normalisation): where the free fit is an apple without a dimple, the
        // superellipsoid it stands for is there (`model_choice::DIMPLE_SIGMAS`)
        for (i, p) in &mut group {
            if let Some(free) = model_twins[*i].and_then(|free| free_best[free]) {
                let mut start = starts::superellipsoid_outline(&free);
                start.shape = crate::fit::prepare::holding_known(start.shape, &p.known);
                p.starts.push(start);
            }
        }
        let local = |i: usize| group.iter().position(|(j, _)| *j == i);
        let local_twins: Vec<(usize, usize)> = twins
            .iter()
            .filter_map(|&(a, b)| Some((local(a)?, local(b)?)))
            .collect();
        let as_twin: Vec<bool> = group
            .iter()
            .map(|(i, _)| model_twins[*i].is_some_and(|free| by_likelihood[free]))
            .collect();
        // (the preparation and the groups searched before count as stage 1)
        let searched_at = start.elapsed().as_secs_f64() * 1e3;
        let free_fits: Vec<Option<Round1Best>> = group
            .iter()
            .map(|(i, _)| model_twins[*i].and_then(|free| round1_best[free]))
            .collect();
        let found = search_group(evaluator, &group, &local_twins, &as_twin, &free_fits)?;
        let searched_by = Instant::now();
        for ((i, p), f) in group.iter().zip(found) {
            by_likelihood[*i] = f.by_likelihood;
            round1_best[*i] = f.round1_best;
            free_best[*i] = Some(f.best.candidate);
            dropped[*i] = f.stopped_after;
            let best = &f.best;
            let mut r = report(
                p,
                &best.candidate,
                best.iterations,
                best.modelled.then_some(best.sigma),
                f.stage1_iterations,
                backend.clone(),
            );
            // (a fit the likelihood refined to a noise too small for the model to matter
            // is a precise one: the polish passes it by)
            r.noise_modelled = best.modelled && noisy(p, &best.candidate, best.sigma);
            polish::warn_off_its_points(&mut r.report, p);
            r.report.search = Some(f.tried);
            // (and the reports' own checks as stage 2, so that the parts make the total)
            let total = start.elapsed().as_secs_f64() * 1e3;
            let stage1 = searched_at + f.round1_ms;
            r.report.timing_ms = Timing {
                stage1,
                stage2: total - stage1,
                noise_model: f.finalists_ms,
                total,
                ..Default::default()
            };
            // (a search still running at its deadline was cut short there)
            if p.deadline.is_some_and(|d| searched_by >= d) {
                r.report.timing_ms.over_budget.push(SEARCH_CUT_SHORT.into());
            }
            results[*i] = Some(Ok(r));
        }
    }
    Ok((
        results
            .into_iter()
            .map(|r| r.expect("every cloud has a result"))
            .collect(),
        dropped,
    ))
}

/// For each cloud fitted as a superellipsoid (`model` superellipsoid), the same cloud's
/// free fit in this batch (the same points, read from the same viewpoint), if any.
/// `model: auto` fits a cloud both ways and weighs the two fits by their likelihood; a
/// fit least squares refined is not at its likelihood's maximum, so the superellipsoid
/// fit is refined by the likelihood wherever the free one was (the free fit's kept
/// rings can call for it where the superellipsoid's own candidates do not).
fn model_twins(clouds: &[(&[DVec3], &FitOptions)]) -> Vec<Option<usize>> {
    let same_cloud = |a: &(&[DVec3], &FitOptions), b: &(&[DVec3], &FitOptions)| {
        std::ptr::eq(a.0, b.0) && a.1.viewpoint == b.1.viewpoint
    };
    clouds
        .iter()
        .map(|c| {
            (c.1.model == Model::Superellipsoid)
                .then(|| {
                    clouds
                        .iter()
                        .position(|o| o.1.model == Model::Supertoroid && same_cloud(c, o))
                })
                .flatten()
        })
        .collect()
}

/// The start of the warning of a viewpoint the fit found contradicted by its points.
pub const VIEWPOINT_IGNORED: &str = "viewpoint ignored";

/// The warning of a viewpoint that a share `violated` of the lines of sight contradicts.
pub(super) fn viewpoint_ignored_warning(violated: f64) -> String {
    format!(
        "{VIEWPOINT_IGNORED}: {:.0}% of the lines of sight from it to the points pass \
         through the object fitted with it (more than {:.0}%), so the sensor was not \
         there, or the viewpoint is in another frame than the points; fitted without it",
        100.0 * violated,
        100.0 * free_space::MAX_VIOLATED_FRACTION
    )
}

/// Why an inferred viewpoint is dropped for a view from nowhere.
pub(super) const ALL_ROUND: &str = "the points are more likely spread all round the object than \
                          seen from there: fitted as a view from nowhere";

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::CpuEvaluator;

    /// `model: auto`'s two searches of one full cloud of `shape` (from nowhere): the free
    /// fit's and the superellipsoid's.
    fn both_searches(shape: Shape) -> (SearchOut, SearchOut) {
        let pose = Pose::new(DQuat::from_rotation_x(0.4), DVec3::new(0.1, 0.0, 0.5));
        let mut rng = synth::rng(5);
        let mut points = synth::sample_surface(&shape, &pose, 1500, &mut rng);
        synth::add_noise(&mut points, 0.0005, &mut rng);
        let auto = FitOptions {
            model: Model::Auto,
            viewpoint: Viewpoint::None,
            ..Default::default()
        };
        let options = crate::fit::fits_of_model(&auto).unwrap();
        let clouds: Vec<(&[DVec3], &FitOptions)> =
            options.iter().map(|o| (points.as_slice(), o)).collect();
        let (results, _) = searched_once(&mut CpuEvaluator::new(), &clouds, &[]).unwrap();
        let search =
            |r: &Result<Searched, FitError>| r.as_ref().unwrap().report.search.clone().unwrap();
        (search(&results[0]), search(&results[1]))
    }

    /// A ring's superellipsoid fit is far less likely than its free fit after round 1
    /// and goes no further; a can's goes on beside its free fit.
    #[test]
    fn a_superellipsoid_far_behind_the_free_fit_stops_after_round_one() {
        let (free, genus0) = both_searches(Shape::new(0.02, 0.02, 0.015, 2.5, 0.8, 1.0));
        assert!(free.refined > 0, "{free:?}");
        assert_eq!(genus0.refined, 0, "{genus0:?}");
        let (free, genus0) = both_searches(Shape::new(0.04, 0.04, 0.06, 0.0, 0.2, 1.0));
        assert!(
            free.refined > 0 && genus0.refined > 0,
            "{free:?} {genus0:?}"
        );
    }

    /// The superellipsoid's search has every start the free fit's has (a4 held at 0), and
    /// the free fit's outline besides.
    #[test]
    fn the_superellipsoid_search_starts_at_the_free_fits_outline_too() {
        let (free, genus0) = both_searches(Shape::new(0.04, 0.04, 0.06, 0.0, 0.2, 1.0));
        assert_eq!(genus0.starts, free.starts + 1, "{free:?} {genus0:?}");
    }
}

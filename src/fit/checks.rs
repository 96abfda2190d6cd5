//! The checks of the finished fits that [`super::fit_batch`] runs after both stages, in
//! its order: a viewpoint the fit contradicts, edge-on rings, fits whose visible surface is
//! bare or that stay off their points (other downsampling seeds, the sweep across the line
//! of sight), the precise misfits' polishes and refits, closed bodies barely covered, the
//! noise model's last polish on all points, and the warning of a fit off its scatter.

use super::*;

/// The default of [`FitOptions::unseen_surface_retries`]. Measured on the ground-truth
/// suite's single views (three seed sets, 270 cases, with the camera's position):
/// successes 43/40/45 -> 48/44/47 of 90 (noise-free views 25-26 -> 28-29 of 30); the
/// single views' median fit time unchanged, their 90th percentile 34 -> 45-49 ms.
pub const UNSEEN_SURFACE_RETRIES: u64 = 3;
/// The most retries the CLI and the service accept (each costs about one fit).
pub const MAX_UNSEEN_SURFACE_RETRIES: u64 = 16;

/// A fit whose visible surface the points do not cover ([`coverage`]) is almost always
/// wrong (1 of 75 within tolerance on the suite's single views), and on a noise-free view
/// often only because its random samples led the starts into a wrong basin. The same
/// holds for a least-squares fit that the noise model then moved onto the points'
/// surface: covered, but often still in the wrong basin (the retries following it too:
/// 449 -> 452 of the suite's 540), for a fit that stays off a precise cloud by more
/// than rounding ([`precise_but_off`]), and for one whose noise the cloud's own scatter
/// does not show ([`NOISE_OVER_SCATTER`]). Such a cloud is fitted again with
/// `unseen_surface_retries` other seeds (one batch), and the fit that may stand
/// ([`may_stand`]: covered, free space kept), the first among them, with the lowest
/// median distance to all points stands; for a single view noisy enough for the noise
/// model, the most likely under the model ([`judged_by_likelihood`]; with
/// [`FitOptions::thorough`] every such view is retried too); when none may stand, the
/// noise model tries to rescue the first fit ([`rescue_unseen_surface`]), and failing
/// that the first fit stands with its warning. A fit still off a precise cloud goes on
/// to [`retry_lasting_misfits`]. Returns the clouds it retried.
pub(super) fn retry_unseen_surfaces(
    evaluator: &mut dyn Evaluator,
    clouds: &[(&[DVec3], &FitOptions)],
    scatters: &Scatters,
    results: &mut [Result<FitReport, FitError>],
) -> Result<Vec<usize>, FitError> {
    let uncovered: Vec<usize> = results
        .iter()
        .enumerate()
        .filter(|(i, r)| {
            r.as_ref().is_ok_and(|r| {
                r.method == Method::Default
                    && (r
                        .quality
                        .visible_coverage
                        .is_some_and(|c| c < coverage::MIN_VISIBLE_COVERAGE)
                        || r.uncovered_before_model
                        || r.noise_above_scatter
                        || precise_but_off(r, || scatters.of(clouds, *i))
                        || searched_thoroughly(clouds[*i].1, r)
                        || pinned_at_eps_bound(clouds[*i].1, r))
            })
        })
        .map(|(i, _)| i)
        .collect();
    if uncovered.is_empty() {
        return Ok(uncovered);
    }
    let listed: Vec<(usize, RangeInclusive<u64>)> = uncovered
        .iter()
        .map(|&i| (i, 1..=clouds[i].1.unseen_surface_retries))
        .collect();
    let retry_start = Instant::now();
    let retries = fit_retries(evaluator, clouds, &listed)?;
    for &i in &uncovered {
        let first = results[i].as_ref().expect("uncovered fits are fits");
        let (cloud, cloud_options) = clouds[i];
        let best = best_retry(&retries, i, first, clouds[i]).or_else(|| {
            rescue_unseen_surface(evaluator, cloud, cloud_options, first).map(|mut r| {
                r.timing_ms = first.timing_ms.clone();
                r
            })
        });
        // the first fit's time, the retries' (one batch) and the rescue's are the
        // caller's wait, whether they replace the fit or not
        charge_wait(&mut results[i], best, retry_start);
    }
    Ok(uncovered)
}

/// A check's outcome for one cloud: `replacement` (when the check found a better fit) in
/// place of the fit in `result`, whose total time grows by the check's since `start`.
/// The check's time is the caller's wait whether it replaced the fit or not.
pub(super) fn charge_wait(
    result: &mut Result<FitReport, FitError>,
    replacement: Option<FitReport>,
    start: Instant,
) {
    let Ok(current) = result.as_ref() else {
        return;
    };
    let total = current.timing_ms.total + start.elapsed().as_secs_f64() * 1e3;
    if let Some(replacement) = replacement {
        *result = Ok(replacement);
    }
    if let Ok(r) = result {
        r.timing_ms.total = total;
    }
}

/// A single view's fit without an open hole ([`OPEN_HOLE`]) may be a ring seen edge-on
/// whose hole axis the starts missed: the normal lines of its visible band meet the
/// tube's tangent about as well as the hole axis ([`starts::across_line_of_sight`]). On
/// the suite's single views (six seed sets, 540 cases) the normal lines' axis was more
/// than 20 degrees off the hole axis on 137, most of which the other starts still
/// recovered; the five failures without a hole (10089, 20014, 40013, 40099, 60017) were
/// all seen within 12 degrees of edge-on. Such a fit is fitted again from the hole axes
/// across the line of sight alone, and the refit replaces it where it may stand and is
/// better by [`best_retry`]'s measure: 10089, 40013, 40099, 60017 and 60171 recovered,
/// none lost (20014's refit is near the truth but leaves 26% of its visible surface
/// without points). Those starts among the usual ones won stage 1 on other views with
/// giant rings through the visible patch (the six sets lost 9 cases net).
pub(super) fn retry_across_line_of_sight(
    evaluator: &mut dyn Evaluator,
    clouds: &[(&[DVec3], &FitOptions)],
    results: &mut [Result<FitReport, FitError>],
) -> Result<(), FitError> {
    let listed: Vec<usize> = results
        .iter()
        .enumerate()
        .filter(|(i, r)| {
            r.as_ref().is_ok_and(|r| {
                r.method == Method::Default
                    && r.quality.visible_coverage.is_some()
                    && r.fitted.0.a4 < OPEN_HOLE
                    && clouds[*i].1.known_axis.is_none()
            })
        })
        .map(|(i, _)| i)
        .collect();
    if listed.is_empty() {
        return Ok(());
    }
    let start = Instant::now();
    let batch: Vec<(&[DVec3], &FitOptions)> = listed.iter().map(|&i| clouds[i]).collect();
    let refits = fit_batch_from(evaluator, &batch, StartSet::AcrossLineOfSight)?;
    for (&i, refit) in listed.iter().zip(refits) {
        let current = results[i].as_ref().expect("listed fits are fits");
        let Some(Ok(refit)) = refit else { continue };
        let best = best_retry(&[(i, Ok(refit))], i, current, clouds[i]);
        charge_wait(&mut results[i], best, start);
    }
    Ok(())
}

/// Fits each listed cloud again with the retry seeds of its range (one batch): the
/// retries, each with the index of its cloud.
pub(super) fn fit_retries(
    evaluator: &mut dyn Evaluator,
    clouds: &[(&[DVec3], &FitOptions)],
    listed: &[(usize, RangeInclusive<u64>)],
) -> Result<Vec<(usize, Result<FitReport, FitError>)>, FitError> {
    let options: Vec<(usize, FitOptions)> = listed
        .iter()
        .flat_map(|(i, ks)| {
            ks.clone().map(move |k| {
                (
                    *i,
                    FitOptions {
                        seed: clouds[*i]
                            .1
                            .seed
                            .wrapping_add(k.wrapping_mul(0x9E37_79B9_7F4A_7C15)),
                        ..clouds[*i].1.clone()
                    },
                )
            })
        })
        .collect();
    let batch: Vec<(&[DVec3], &FitOptions)> =
        options.iter().map(|(i, o)| (clouds[*i].0, o)).collect();
    let retries = fit_batch_once(evaluator, &batch)?;
    Ok(options.into_iter().map(|(i, _)| i).zip(retries).collect())
}

/// A fit (first or retry) that may stand: with a viewpoint, the points cover its
/// visible surface and it keeps out of the space the sensor saw through.
pub(super) fn may_stand(r: &FitReport) -> bool {
    r.quality
        .visible_coverage
        .is_none_or(|c| c >= coverage::MIN_VISIBLE_COVERAGE)
        && r.free_space_violation
            .is_none_or(|v| v <= free_space::MAX_VIOLATED_FRACTION)
}

/// Of cloud `cloud`'s retries and its `current` fit (last), the one with the lowest
/// `merit` among those that may stand ([`may_stand`]); the first of equals.
pub(super) fn best_standing<'a>(
    retries: &'a [(usize, Result<FitReport, FitError>)],
    cloud: usize,
    current: &'a FitReport,
    merit: impl Fn(&FitReport) -> f64,
) -> Option<&'a FitReport> {
    retries
        .iter()
        .filter(|(of, _)| *of == cloud)
        .filter_map(|(_, r)| r.as_ref().ok())
        .chain(std::iter::once(current))
        .filter(|r| may_stand(r))
        .map(|r| (merit(r), r))
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, r)| r)
}

/// Of cloud `i`'s retries and its `first` fit, the best that may stand
/// ([`best_standing`]): for a single view noisy enough for the noise model
/// ([`judged_by_likelihood`]) the most likely on a common sample ([`CommonSample`]),
/// otherwise the one with the lowest median distance (a noise-free view is told by its
/// distances; the model's premise is noise).
pub(super) fn best_retry(
    retries: &[(usize, Result<FitReport, FitError>)],
    i: usize,
    first: &FitReport,
    (cloud, options): (&[DVec3], &FitOptions),
) -> Option<FitReport> {
    let common = judged_by_likelihood(options, first).then(|| CommonSample::new(cloud, options));
    best_standing(retries, i, first, |r| match &common {
        Some(common) => common.negative_log_likelihood(r),
        None => r.quality.median_distance,
    })
    .cloned()
}

/// Retries in all, at most, of a fit that stays off a precise cloud
/// (`precise_but_off`): where the first [`UNSEEN_SURFACE_RETRIES`] leave it there,
/// `retry_lasting_misfits` goes on up to this many. On the suite, 30051 and 30123 (sizes
/// 240% and 14% off after 3 retries, still 146% and 14% after 8) were recovered to
/// rounding by 16, each fit taking about 400 ms instead of 90.
pub const PRECISE_MISFIT_RETRIES: u64 = MAX_UNSEEN_SURFACE_RETRIES;

/// A fit still off a precise cloud after [`retry_unseen_surfaces`] is fitted again with
/// the further seeds up to [`PRECISE_MISFIT_RETRIES`] (one batch), and the fit with the
/// lowest median distance that may stand ([`may_stand`]) replaces it. So is a fit whose
/// visible surface the points still do not cover ([`still_unseen`]), or that the first
/// retries left off its points' own scatter ([`RETRIED_MISFIT_OVER_SCATTER`]), judged as
/// [`best_retry`] judges the first retries. Nothing is retried where the caller turned
/// the retries off.
pub(super) fn retry_lasting_misfits(
    evaluator: &mut dyn Evaluator,
    clouds: &[(&[DVec3], &FitOptions)],
    scatters: &Scatters,
    retried: &[usize],
    results: &mut [Result<FitReport, FitError>],
) -> Result<(), FitError> {
    let still_off_scatter = |i: usize, r: &FitReport| {
        retried.contains(&i)
            && r.quality.median_distance / r.fitted.0.size() >= PRECISE_MISFIT.end
            && scatters
                .of(clouds, i)
                .is_some_and(|s| r.quality.median_distance > RETRIED_MISFIT_OVER_SCATTER * s)
    };
    let listed: Vec<(usize, RangeInclusive<u64>)> = results
        .iter()
        .enumerate()
        .filter_map(|(i, r)| {
            let r = r.as_ref().ok()?;
            let done = clouds[i].1.unseen_surface_retries;
            (r.method == Method::Default
                && done > 0
                && done < PRECISE_MISFIT_RETRIES
                && (precise_but_off(r, || scatters.of(clouds, i))
                    || still_unseen(r)
                    || still_off_scatter(i, r)
                    || r.noise_above_scatter
                    || pinned_at_eps_bound(clouds[i].1, r)))
            .then_some((i, done + 1..=PRECISE_MISFIT_RETRIES))
        })
        .collect();
    if listed.is_empty() {
        return Ok(());
    }
    let start = Instant::now();
    let retries = fit_retries(evaluator, clouds, &listed)?;
    for (i, _) in &listed {
        let current = results[*i].as_ref().expect("listed fits are fits");
        let best = if precise_but_off(current, || scatters.of(clouds, *i)) {
            best_standing(&retries, *i, current, |r| r.quality.median_distance).cloned()
        } else {
            best_retry(&retries, *i, current, clouds[*i])
        };
        charge_wait(&mut results[*i], best, start);
    }
    Ok(())
}

/// A fit the first retries (`retry_unseen_surfaces`) leave farther than this many times
/// its cloud's scatter from its points ([`scatter::local_scatter`]; a finished fit is
/// warned at [`MISFIT_OVER_SCATTER`]) gets the further seeds. The noisy single views of
/// the suite's right fits sit within 2.2 times their scatter; 40088 (1% noise, 10%
/// outliers) sat at 7.4 after 3 retries, sizes 99% off, and within 3% after 16. A cloud
/// that was not retried is not asked (the paper's pot, not an exact supertoroid, sits at
/// 5.5).
pub const RETRIED_MISFIT_OVER_SCATTER: f64 = 5.0;

/// A fit whose visible surface the points do not cover even after [`retry_unseen_surfaces`]
/// (its retries and the noise model's rescue): on the suite rare (6 of 1980 cases) and
/// mostly wrong (3 of the 6), giant bodies grown into the unseen side of thin rings,
/// which further seeds may start in the right basin (130031: sizes 5 times too large
/// after 3 retries, within 1.2% after 16).
pub(super) fn still_unseen(r: &FitReport) -> bool {
    r.quality
        .visible_coverage
        .is_some_and(|c| c < coverage::MIN_VISIBLE_COVERAGE)
}

/// The default of [`FitOptions::eps_max`]: eps 2 is a diamond section, beyond it a
/// concave one.
pub const DEFAULT_EPS_MAX: f64 = 2.0;

/// A fit whose eps1 or eps2 ends within this of the default upper bound
/// ([`DEFAULT_EPS_MAX`]) is pressed against it.
pub const EPS_BOUND_MARGIN: f64 = 0.03;

/// A fit with an eps pressed against its default upper bound ([`EPS_BOUND_MARGIN`])
/// wanted a shape the model does not hold:
/// on the suite (eleven seed sets, 1980 cases) 2 fits, both wrong. 50035, a noisy view
/// with outliers, ended its first retries in a wrong basin (eps1 at 2, sizes 37% off, its
/// likelihood far below the truth's; the rescue, which finds the truth, runs only where
/// no retry may stand) and is within 4% after the further seeds; 40008's own
/// maximum-likelihood fit is at the bound (an estimator limit), so its retries cost time
/// for nothing. Such a fit is retried as an uncovered one is, and given the further seeds
/// if it stays there. The lower bound is left alone: a square section (a pot's wall, a
/// cylinder) sits near it by right, as the paper's pot does on 3 of its 10 runs (eps1
/// 0.13-0.15 after retries that took 10 -> 120 ms for the same grade). A bound the
/// caller narrowed is the caller's prior: fits against it are not retried. (Running the
/// rescue for every retried noisy view instead, the deeper change, recovered the same
/// cases and cost the single views 22% more mean time.)
pub(super) fn pinned_at_eps_bound(options: &FitOptions, r: &FitReport) -> bool {
    let shape = &r.fitted.0;
    options.eps_max >= DEFAULT_EPS_MAX
        && [shape.eps1, shape.eps2]
            .iter()
            .any(|&e| e > options.eps_max - EPS_BOUND_MARGIN)
}

/// The default of [`FitOptions::polish_points`]: every point of the suite's clouds (2000
/// surface points and up to 10% outliers), a few times the stage-2 sample of a robot's
/// cloud.
pub const POLISH_POINTS: usize = 4000;

/// How much more likely (mean log-likelihood per point) the other reading of a top view
/// must be than the polished fit to replace it ([`DUAL_READING_MARGIN`] on the stage-2
/// sample). On all 2000 points of the suite's noisy single views, the wrong reading was
/// never the more likely one (the closest 0.006 less likely), and four fits in the wrong
/// reading were 0.03 to 0.11 less likely than the right one: on a sample twice as large,
/// the likelier reading wins.
pub const POLISH_DUAL_MARGIN: f64 = 0.0;

/// The polish reads the top view the other way only where, on the fit's own sample, the
/// other reading came within this of the fit (mean log-likelihood per point, after its
/// first iterations), or was not tried there. On the suite's noisy single views (four
/// seed sets, 240 cases) the two samples' gaps agreed within 0.05 where both were
/// positive and below 0.3, every fit the polish turned had a gap below 0 (or none), and
/// the gaps of the others ran to 5; reading those only once saves 40-70 ms of the
/// polish's 8 first iterations each, and changed no fit of the suite.
pub const POLISH_READING_GAP: f64 = 0.25;

/// The noise model's fit was made on the 1000-point stage-2 sample, whose own noise moves
/// the model's optimum: from the true parameters, the model's optimum is within the
/// suite's tolerance on 523 of its 540 cases on the sample and on 532 on all points. So
/// the fit that stands after the retries, where the model refined it, is refined once
/// more from where it is on up to [`FitOptions::polish_points`] of the cloud's points,
/// and its top view read the other way too ([`POLISH_DUAL_MARGIN`]). The polished fit
/// replaces it unless it no longer may stand ([`may_stand`]) where the fit did; its time
/// counts as stage 2's.
///
/// Full clouds too: on the suite's full clouds (eight seed sets, 720 cases) 704 -> 710
/// within tolerance (8 gained, fits with eps 0.16-0.23 off, mostly at 2% noise; 20134
/// and 80149 lost), their median fit time 16 -> 34 ms. (On seeds 10000-60000 it was +4
/// -1, on the fresh sets 80000 and 90000 +4 -1.)
///
/// The polish refines on a grid twice as fine along the section
/// ([`likelihood::refine_finely`]), which takes out the usual grid's bias on thin
/// sections (eps1 high). Nine seed sets (1620 cases): 1574 -> 1579 within tolerance (15
/// gained, 10 lost: a churn among fits at the tolerances' edges), the full clouds' mean
/// |eps1 error| at 2% noise 0.048 -> 0.039 (four sets), the noisy fits' median time up by
/// a quarter to a third. The same grid everywhere in the model also gave 1579, at
/// one and a half to twice the noisy fits' time.
pub(super) fn polish_on_more_points(
    evaluator: &dyn Evaluator,
    clouds: &[(&[DVec3], &FitOptions)],
    results: &mut [Result<FitReport, FitError>],
) {
    for (result, (cloud, options)) in results.iter_mut().zip(clouds) {
        let Ok(fitted) = result.as_ref() else {
            continue;
        };
        if !fitted.noise_modelled || options.polish_points == 0 {
            continue;
        }
        let start = Instant::now();
        let Some(p) = prepare_polish(cloud, options) else {
            continue;
        };
        let c = p.norm.candidate(&fitted.fitted.0, &fitted.fitted.1);
        let sigma = fitted.quality.noise_sigma / p.norm.scale;
        let read_both_ways = fitted
            .other_reading_gap
            .is_none_or(|gap| gap < POLISH_READING_GAP);
        let Some(ModelFit { refined, .. }) = refine_both_readings(
            &p,
            &c,
            sigma,
            read_both_ways.then_some(POLISH_DUAL_MARGIN),
            likelihood::refine_finely,
        ) else {
            continue;
        };
        let polished = report(
            &p,
            &refined.candidate,
            fitted.iterations.stage2 + refined.iterations,
            Some(refined.sigma),
            fitted.iterations.stage1,
            evaluator,
        );
        if may_stand(fitted) && !may_stand(&polished) {
            continue;
        }
        *result = Ok(polish_of(polished, fitted, p.stage2_pts.len(), start));
    }
}

/// The cloud as a stage 2 on the polish's points ([`FitOptions::polish_points`]) would
/// see it: sampled with the fit's seed, the whole cloud where it has no more.
pub(super) fn prepare_polish<'a>(cloud: &'a [DVec3], options: &FitOptions) -> Option<Prepared<'a>> {
    let polish_options = FitOptions {
        stage2_points: options.polish_points,
        ..options.clone()
    };
    prepare(cloud, &polish_options, StartSet::Usual).ok()
}

/// `polished` (on `points` of the cloud, since `start`) in place of `fitted`: the
/// polish's time counts as stage 2's, and the fit's points and checks carry over.
pub(super) fn polish_of(
    mut polished: FitReport,
    fitted: &FitReport,
    points: usize,
    start: Instant,
) -> FitReport {
    let spent = start.elapsed().as_secs_f64() * 1e3;
    polished.timing_ms = Timing {
        total: fitted.timing_ms.total + spent,
        ..fitted.timing_ms.clone()
    };
    polished.points = PointsOut {
        polish: Some(points),
        ..fitted.points.clone()
    };
    polished.uncovered_before_model = fitted.uncovered_before_model;
    polished.rescued = fitted.rescued;
    polished.noise_above_scatter = fitted.noise_above_scatter;
    polished
}

/// A cloud that lies on its surface to a fraction of a per mille (a CAD model's, a
/// precise scanner's) and a fit that still leaves a median distance well above rounding
/// is in the wrong basin: the truth of such a cloud fits it to rounding. Measured on
/// the suite's 180 noise-free clouds after the rounds of `refine_robustly`, before
/// any retry (single views told their camera): the fits within tolerance left median
/// distances below 4e-6 of the size, the failed ones 1e-4 to 4e-4 (one within
/// tolerance, 1.7e-3, was 9% off in size); the 1%-noise clouds leave 7e-3 and more.
/// The retries recover 10048 and bring the noise-free single views' median fit time
/// from 24 to 22 ms (without the rounds, 62: one scale left most of these fits between
/// 1e-5 and 1e-4, and every one was retried). Not wider: up to 5e-3 the retries fitted
/// two held-out noise-free views to rounding (50087 at 3.7e-3, 60171 at 3.4e-3; the six
/// seed sets 1040 -> 1042 of 1080), but the paper's roll, a real scan, sits in that band:
/// it was retried on every seed, 8 -> 150 ms a fit, and came out farther from its points
/// (relative RMS 1.13 -> 1.25%). Above this band the cloud's own scatter is the
/// reference instead ([`MISFIT_OVER_SCATTER`]), which tells the roll's sensor noise from
/// a wrong basin.
pub const PRECISE_MISFIT: std::ops::Range<f64> = 1e-5..3e-3;

/// Above [`PRECISE_MISFIT`] a fit is judged against the cloud's own scatter
/// ([`scatter::local_scatter`]) instead: one whose median distance is more than
/// [`MISFIT_OVER_SCATTER`] times it is off its points, whatever their noise.
pub(super) fn precise_but_off(r: &FitReport, scatter: impl FnOnce() -> Option<f64>) -> bool {
    let median = r.quality.median_distance;
    let relative = median / r.fitted.0.size();
    PRECISE_MISFIT.contains(&relative)
        || (relative >= PRECISE_MISFIT.end
            && scatter().is_some_and(|s| median > MISFIT_OVER_SCATTER * s))
}

/// A finished fit still farther from its points than [`MISFIT_OVER_SCATTER`] times their
/// own scatter (above [`PRECISE_MISFIT`], where [`precise_but_off`] judges by it) says
/// so: a wrong basin the retries did not leave, or an object the model does not
/// describe.
pub(super) fn warn_off_scatter(
    clouds: &[(&[DVec3], &FitOptions)],
    scatters: &Scatters,
    results: &mut [Result<FitReport, FitError>],
) {
    for (i, result) in results.iter_mut().enumerate() {
        let Ok(r) = result else { continue };
        let median = r.quality.median_distance;
        if median / r.fitted.0.size() < PRECISE_MISFIT.end {
            continue;
        }
        if let Some(scatter) = scatters.of(clouds, i)
            && median > MISFIT_OVER_SCATTER * scatter
        {
            r.warnings.push(format!(
                "{OFF_ITS_POINTS_WARNING}: the median distance is {:.0} times the points' own \
                 scatter about a smooth surface (over {MISFIT_OVER_SCATTER}), so the fit is in a \
                 wrong basin or the object is not a supertoroid; shape and pose may be far off",
                median / scatter
            ));
        }
    }
}

/// How the warning of `warn_off_scatter` begins.
pub const OFF_ITS_POINTS_WARNING: &str = "off its points";

/// Each cloud's [`scatter::local_scatter`], measured the first time a check asks for it
/// (about a millisecond on a few thousand points; a fit left within [`PRECISE_MISFIT`]
/// never needs it), with the milliseconds it took.
pub(super) struct Scatters(Vec<std::cell::OnceCell<(Option<f64>, f64)>>);

impl Scatters {
    pub(super) fn new(clouds: &[(&[DVec3], &FitOptions)]) -> Self {
        Self(clouds.iter().map(|_| std::cell::OnceCell::new()).collect())
    }

    fn of(&self, clouds: &[(&[DVec3], &FitOptions)], i: usize) -> Option<f64> {
        self.0[i]
            .get_or_init(|| {
                let start = Instant::now();
                let scatter = scatter::local_scatter(clouds[i].0);
                (scatter, start.elapsed().as_secs_f64() * 1e3)
            })
            .0
    }

    /// Adds the time each cloud's scatter took to its fit's total.
    pub(super) fn charge(&self, results: &mut [Result<FitReport, FitError>]) {
        for (measured, result) in self.0.iter().zip(results) {
            if let (Some((_, ms)), Ok(r)) = (measured.get(), result) {
                r.timing_ms.total += ms;
            }
        }
    }
}

/// The largest median distance of a fit, over the cloud's own scatter
/// ([`scatter::local_scatter`], an RMS: a Gaussian's median distance is 0.67 of it),
/// that is not retried as a wrong basin. On the suite's single views (four seed sets,
/// 360 cases) the right fits left at most 2.5 (outliers raise the median), the wrong
/// basins above [`PRECISE_MISFIT`] 4.2 to 72 (50087 4.2, 40088 7.1, 100153 15, 100123
/// 60, 100051 72). But a real object is never exactly a supertoroid: the paper's pot
/// leaves 5.5 (its wall and rim), the roll 2.7, the gear 2.0, and at 3.5 the pot was
/// retried on every seed (8 -> 140 ms) and one of ten retries ended 88 degrees off. At 10
/// the three noise-free views above 10 are retried and fitted to rounding (100051,
/// 100123, 100153; 60081 too, which the first retries had left above the band), and
/// the paper's clouds are left alone.
pub const MISFIT_OVER_SCATTER: f64 = 10.0;

/// What [`retry_unseen_surfaces`] searches as [`FitOptions::thorough`] does (other seeds,
/// the most likely under the noise model standing): with the noise model on, a
/// single-view fit whose noise is large enough for the model
/// ([`LIKELIHOOD_VIEW_NOISE_RATIO`] of its thinnest half-axis), every one with
/// `thorough`, by default those whose points only just cover their visible surface
/// ([`MARGINAL_COVERAGE`]).
pub(super) fn searched_thoroughly(options: &FitOptions, r: &FitReport) -> bool {
    judged_by_likelihood(options, r)
        && (options.thorough
            || r.quality
                .visible_coverage
                .is_some_and(|c| MARGINAL_COVERAGE.contains(&c)))
}

/// A noisy single view's fit with this share of its visible surface covered by points
/// ([`coverage`]) is searched thoroughly (`searched_thoroughly`): enough to stand, but
/// where a wrong basin's fits sit. On the suite's single views (eleven seed sets, 990
/// views) 28 fits ended in this band and 5 of them wrong against 30 of the 950 above it;
/// the thorough search recovered two of the noisy ones, 40121 (a giant ring through the
/// visible patch, coverage 0.76) and 120067 (0.84), lost none, and the 15 noisy views
/// in the band took 1-3 times as long (60046: 0.3 -> 1.0 s). Over every noisy view it
/// gained the same two, lost 80143 (coverage 1.0), and tripled the single views' median
/// fit time.
pub const MARGINAL_COVERAGE: std::ops::Range<f64> = coverage::MIN_VISIBLE_COVERAGE..0.85;

/// Retries of a single view noisy enough for the noise model
/// ([`LIKELIHOOD_VIEW_NOISE_RATIO`] of its thinnest half-axis) are told apart by the
/// model's likelihood on a common sample, not by their median distances: the model
/// refined them, and least squares' distances are what it corrects. (On the suite, 540
/// cases, a tie: 30065 gained, 30154 lost.)
pub(super) fn judged_by_likelihood(options: &FitOptions, r: &FitReport) -> bool {
    options.noise_model
        && r.quality.visible_coverage.is_some()
        && r.quality.noise_sigma >= LIKELIHOOD_VIEW_NOISE_RATIO * r.fitted.0.thinnest_half_axis()
}

/// One seeded sample of a cloud (`stage2_points` of it, normalised) that every fit of the
/// cloud is scored on, so that fits from other samples compare.
pub(super) struct CommonSample {
    norm: Normalization,
    points: Vec<DVec3>,
    viewpoint: Option<DVec3>,
}

impl CommonSample {
    fn new(cloud: &[DVec3], options: &FitOptions) -> Self {
        let norm = Normalization::of(cloud);
        let points = synth::subsample(
            &norm.points(cloud),
            options.stage2_points,
            &mut synth::rng(options.seed),
        );
        Self {
            norm,
            points,
            viewpoint: options.viewpoint.position().map(|v| norm.point(v)),
        }
    }

    /// The noise model's mean negative log-likelihood of the sample under a fit, at the
    /// fit's own noise estimate; infinite for a fit the model does not cover (no hole).
    fn negative_log_likelihood(&self, r: &FitReport) -> f64 {
        likelihood::objective(
            &self.points,
            &self.norm.candidate(&r.fitted.0, &r.fitted.1),
            (r.quality.noise_sigma / self.norm.scale).max(1e-6),
            LIKELIHOOD_OUTLIER_WEIGHT,
            self.viewpoint,
        )
        .unwrap_or(f64::INFINITY)
    }
}

/// A viewpoint the fit contradicts is not where the sensor was (a cloud in another frame
/// than the one the viewpoint was given in, or a sensor elsewhere): its free-space points
/// would push the object away from the points (measured on the suite's 90 single views:
/// the camera's position 43 successes, the point opposite it 0, one beside it 25, none 36).
/// When more than [`free_space::MAX_VIOLATED_FRACTION`] of the free-space points lie
/// inside the fit, the cloud is fitted again without the viewpoint, and the report says so.
///
/// But a fit in a wrong basin contradicts the right viewpoint too. So the cloud is also
/// fitted again with the viewpoint from `unseen_surface_retries` other samples (one
/// batch), as [`retry_unseen_surfaces`] does, and the retry that may stand
/// ([`may_stand`]) with the lowest merit there keeps the viewpoint when it lies as close
/// to the points (median distance) as the fit without it; a wrong viewpoint's retries
/// fit them worse (the opposite of the camera on seeds 10000: 69 of 90 views caught with
/// or without the retries, 65 without the closeness rule). (60141 of the held-out seed
/// set 60000, a noise-free view with 10% outliers: its first fit put solid where the
/// camera saw through and, fitted without the camera, ended 12 times too large; two of
/// its three retries kept the camera's free space and fitted it to rounding.)
pub(super) fn refit_without_inconsistent_viewpoints(
    evaluator: &mut dyn Evaluator,
    clouds: &[(&[DVec3], &FitOptions)],
    results: &mut [Result<FitReport, FitError>],
) -> Result<(), FitError> {
    let contradicted: Vec<(usize, f64)> = results
        .iter()
        .enumerate()
        .filter_map(|(i, r)| {
            let violated = r.as_ref().ok()?.free_space_violation?;
            (violated > free_space::MAX_VIOLATED_FRACTION).then_some((i, violated))
        })
        .collect();
    if contradicted.is_empty() {
        return Ok(());
    }
    let listed: Vec<(usize, RangeInclusive<u64>)> = contradicted
        .iter()
        .filter(|&&(i, _)| {
            results[i]
                .as_ref()
                .is_ok_and(|r| r.method == Method::Default)
                && clouds[i].1.unseen_surface_retries > 0
                // an inferred viewpoint is not worth retrying for: the cloud is fitted
                // again without it
                && !inferred(clouds[i].1)
        })
        .map(|&(i, _)| (i, 1..=clouds[i].1.unseen_surface_retries))
        .collect();
    let retry_start = Instant::now();
    let retries = if listed.is_empty() {
        Vec::new()
    } else {
        fit_retries(evaluator, clouds, &listed)?
    };
    // the viewpoint's best retry, for each contradicted cloud
    let kept: Vec<Option<FitReport>> = contradicted
        .iter()
        .map(|&(i, _)| {
            let first = results[i].as_ref().expect("contradicted fits are fits");
            best_retry(&retries, i, first, clouds[i])
        })
        .collect();
    let indices: Vec<usize> = contradicted.iter().map(|&(i, _)| i).collect();
    let options = inferred_view::options_without_viewpoint(clouds, &indices);
    let refits = fit_batch_unscreened(
        evaluator,
        &inferred_view::batch_of(clouds, &indices, &options),
    )?;
    for (((i, violated), refit), kept) in contradicted.into_iter().zip(refits).zip(kept) {
        let first_ms = results[i].as_ref().map_or(0.0, |r| r.timing_ms.total);
        let spent = first_ms + retry_start.elapsed().as_secs_f64() * 1e3;
        // the viewpoint stays where a fit that keeps it lies as close to the points as the
        // fit without it (a wrong viewpoint's retries fit them worse)
        if let Some(mut kept) = kept
            && refit
                .as_ref()
                .is_ok_and(|r| kept.quality.median_distance <= r.quality.median_distance)
        {
            kept.timing_ms.total = spent;
            results[i] = Ok(kept);
            continue;
        }
        results[i] = refit.map(|mut r| {
            r.timing_ms.total = spent;
            r.warnings.push(viewpoint_ignored_warning(violated));
            r
        });
    }
    Ok(())
}

//! The search's rounds, each a function with a small result: round 1 (every start, a few
//! least-squares steps, the likeliest in distinct basins kept), round 2 (the kept ones
//! refined by the estimator the cloud's noise calls for) and the finalists (the likeliest
//! converged). `search_group` composes them with the twin cuts between.

use super::*;

/// What round 1 leaves for each cloud of a group.
pub(super) struct Round1 {
    /// the likeliest candidates in distinct basins, most likely first
    pub kept: Vec<Vec<Scored>>,
    /// the cloud (with no viewpoint) covers its object all round
    pub all_round: Vec<bool>,
    pub stage1_iterations: Vec<usize>,
    /// the reading goes no further (a view's reading from nowhere that its points do
    /// not cover all round; see `search_group` for the other cuts)
    pub dropped: Vec<bool>,
}

/// Round 1: every start of every cloud on the stage-1 sample, least squares for
/// [`ROUND1_ITERATIONS`] in one batch, scored by the likelihood; the [`ROUND1_KEPT`]
/// likeliest in distinct basins go on.
pub(super) fn round1(
    evaluator: &mut dyn Evaluator,
    group: &[(usize, Prepared)],
    twins: &[(usize, usize)],
) -> Result<Round1, FitError> {
    let opts1 = group[0].1.opts1;
    let bounds = group[0].1.bounds;
    // (the reading from nowhere of a cloud searched as a view too is all round by its
    // own premise: the likelihood tells the two readings apart)
    let nowhere_twin: Vec<bool> = (0..group.len())
        .map(|c| twins.iter().any(|&(_, b)| b == c))
        .collect();
    let samples1: Vec<Sample> = group
        .iter()
        .map(|(_, p)| Sample::new(&p.stage1_pts, p.sight(), true).on(p.device.clone()))
        .collect();
    let sets1: Vec<PointSet> = group.iter().map(|(_, p)| p.stage1_set()).collect();
    evaluator.set_point_sets_with_free_space(&sets1)?;
    let (starts, sets) = flatten(group.iter().map(|(_, p)| p.starts.clone()));
    // (no pruning by cost: the likelihood does the cutting)
    let round1_options = SolverOptions {
        max_iterations: ROUND1_ITERATIONS,
        prune_after: 0,
        ..opts1
    };
    let round1 = solve_on(
        evaluator,
        &starts,
        &sets,
        &vec![bounds; starts.len()],
        &round1_options,
    )?;
    // (a start merged into another reports that one's solution: one of them is enough)
    let (live, live_sets): (Vec<Solution>, Vec<usize>) = round1
        .into_iter()
        .zip(sets)
        .filter(|(s, _)| !matches!(s.stop, Stop::Merged | Stop::Pruned))
        .unzip();
    let sample_refs: Vec<&Sample> = samples1.iter().collect();
    let scored1 = scored(
        evaluator,
        &live,
        &live_sets,
        &sample_refs,
        |p| p.stage1_pts.len(),
        group,
    )?;
    let stage1_iterations: Vec<usize> = (0..group.len())
        .map(|cloud| {
            of_cloud(&live, &live_sets, cloud)
                .map(|s| s.iterations)
                .max()
                .unwrap_or(0)
        })
        .collect();
    // A cloud from nowhere (and no view's twin) is all round its object where its points
    // cover the surface of the likeliest candidate read so; otherwise no reading but its
    // points' distances holds, and its candidates are ranked by those.
    let from_nowhere: Vec<bool> = group
        .iter()
        .enumerate()
        .map(|(cloud, (_, p))| p.viewpoint.is_none() && !nowhere_twin[cloud])
        .collect();
    // (the same candidates at the same residual scales, scored by their distances alone)
    let by_distances: Vec<Scored> = if from_nowhere.contains(&true) {
        let samples: Vec<Sample> = group
            .iter()
            .map(|(_, p)| Sample::new(&p.stage1_pts, None, false).on(p.device.clone()))
            .collect();
        scored1
            .par_iter()
            .zip(&live_sets)
            .map(|(c, &set)| Scored {
                score: samples[set].score(&c.candidate, c.sigma),
                ..*c
            })
            .collect()
    } else {
        Vec::new()
    };
    let covers = |p: &Prepared, best: &Scored| {
        likelihood::surface_coverage(
            &p.stage2_pts,
            &best.candidate,
            best.sigma.max(REFINE_SIGMA_FLOOR),
        ) >= LIKELIHOOD_MIN_COVERAGE
    };
    let mut all_round = vec![false; group.len()];
    let mut kept: Vec<Vec<Scored>> = Vec::with_capacity(group.len());
    for (cloud, (_, p)) in group.iter().enumerate() {
        let own = of_cloud(&scored1, &live_sets, cloud).copied().collect();
        let likeliest = most_likely_distinct(own, ROUND1_KEPT);
        all_round[cloud] = p.viewpoint.is_none()
            && (nowhere_twin[cloud] || likeliest.first().is_some_and(|b| covers(p, b)));
        if from_nowhere[cloud] && !all_round[cloud] {
            let own = of_cloud(&by_distances, &live_sets, cloud)
                .copied()
                .collect();
            kept.push(most_likely_distinct(own, ROUND1_KEPT));
        } else {
            kept.push(likeliest);
        }
    }
    // A view's reading from nowhere rests on its points covering the object all round.
    // Where they do not cover that reading's likeliest candidate, and it is no likelier
    // than the view's, nothing speaks for it: it goes no further.
    let mut dropped = vec![false; group.len()];
    for &(view, nowhere) in twins {
        if let (Some(as_view), Some(all_round)) = (kept[view].first(), kept[nowhere].first()) {
            dropped[nowhere] =
                all_round.score >= as_view.score && !covers(&group[nowhere].1, all_round);
        }
    }
    Ok(Round1 {
        kept,
        all_round,
        stage1_iterations,
        dropped,
    })
}

/// Each cloud's sample for the likelihood as round 1 read it.
fn sample_of(p: &Prepared, points: &[DVec3], all_round: bool) -> Sample {
    Sample::new(points, p.sight(), all_round).on(p.device.clone())
}

/// Round 2: round 1's kept candidates, and the other reading of the best one's top view,
/// refined by the estimator the cloud's noise calls for (one estimator for all of a
/// cloud's candidates, so that they are compared by one measure: the likelihood where the
/// noise is wide against the likeliest candidate's section or any kept ring's, or with a4
/// held at 0 any kept candidate's), scored on
/// [`ROUND2_POINTS`] of the stage-2 sample. A cloud whose likeliest refinement blurs it
/// by more than [`MAX_SIGMA_GROWTH`] times the noise it shows is refined by least squares
/// instead. A cloud of `by_likelihood` goes the likelihood way whatever its noise. A
/// dropped reading keeps round 1's candidates. With each cloud's estimator: the
/// likelihood (true) or least squares.
pub(super) fn round2(
    evaluator: &mut dyn Evaluator,
    group: &[(usize, Prepared)],
    first: &Round1,
    by_likelihood: &[bool],
) -> Result<(Vec<Vec<Scored>>, Vec<bool>), FitError> {
    let sets2: Vec<PointSet> = group.iter().map(|(_, p)| p.stage2_set()).collect();
    evaluator.set_point_sets_with_free_space(&sets2)?;
    let mids: Vec<Sample> = group
        .iter()
        .enumerate()
        .map(|(cloud, (_, p))| {
            let mid: Vec<DVec3> = p
                .stage2_pts
                .iter()
                .step_by(p.stage2_pts.len().div_ceil(ROUND2_POINTS).max(1))
                .copied()
                .collect();
            sample_of(p, &mid, first.all_round[cloud])
        })
        .collect();
    // The likeliest start straight into the robust rounds of least squares: its residual
    // scale, converged, is the noise the cloud shows that candidate (ten iterations in,
    // it still reads a precise cloud's outliers and distance as noise), and on a precise
    // cloud it is a finalist (outliers pull the Huber fit of a precise view into other
    // basins often enough).
    let mut direct: Vec<Option<Scored>> = Vec::with_capacity(group.len());
    for (cloud, (_, p)) in group.iter().enumerate() {
        direct.push(match first.kept[cloud].first() {
            Some(best) if !first.dropped[cloud] => Some(robust_candidate(
                evaluator,
                p,
                &mids[cloud],
                cloud,
                *best,
                ROUND1_SHORTFALL,
            )?),
            _ => None,
        });
    }
    let noise: Vec<Option<f64>> = group
        .iter()
        .zip(&direct)
        .enumerate()
        .map(|(cloud, ((_, p), direct))| {
            let best = direct.as_ref()?;
            // (the cloud's own scatter, or the fit's residuals where those are the smaller:
            // the scatter reads a precise thin ring's curvature as noise)
            let noise = p.scatter().map_or(best.sigma, |s| s.min(best.sigma));
            // (judged on every ring kept too: least squares reads a thin section blurred
            // by the noise as a thick one, which then looks precise; and a superellipsoid
            // fit's every candidate, a slab or a rod blurred likewise)
            let superellipsoid = p.holds_a4_at_zero();
            let judged = first.kept[cloud]
                .iter()
                .map(|k| &k.candidate)
                .filter(|c| c.shape.a4 > 1.0 || superellipsoid);
            (by_likelihood[cloud] && p.noise_model
                || std::iter::once(&best.candidate)
                    .chain(judged)
                    .any(|c| noisy(p, c, noise)))
            .then_some(noise)
        })
        .collect();
    let mut round2: Vec<Vec<Scored>> = first.kept.clone();
    let mut modelled: Vec<bool> = noise.iter().map(Option::is_some).collect();
    for (cloud, (_, p)) in group.iter().enumerate() {
        if let Some(noise) = noise[cloud].filter(|_| !first.dropped[cloud]) {
            let refined =
                refine_noisy(evaluator, p, cloud, &first.kept[cloud], &mids[cloud], noise)?;
            // (the likelihood's sigma far above the noise the cloud shows: it takes the
            // object's own departure from the model for blur, and the cloud is refined as
            // a precise one below)
            let best = choose(&refined);
            if best.modelled && best.sigma > MAX_SIGMA_GROWTH * noise {
                modelled[cloud] = false;
            } else {
                round2[cloud] = refined;
            }
        }
    }
    let precise: Vec<usize> = (0..group.len())
        .filter(|&c| !modelled[c] && !first.dropped[c])
        .collect();
    if !precise.is_empty() {
        let refined = refine_precise(evaluator, group, &first.kept, &precise, &mids)?;
        for (cloud, mut refined) in precise.into_iter().zip(refined) {
            refined.extend(direct[cloud]);
            round2[cloud] = refined;
        }
    }
    Ok((round2, modelled))
}

/// Round 2 of the `precise` clouds: least squares on the stage-2 sample, every
/// candidate (and the other reading of each cloud's best top view) in one batch, then the
/// robust rounds for the two likeliest in distinct basins; one list per precise cloud.
/// A candidate whose cost is still [`ROUND2_PRUNE_RATIO`] times its cloud's best after
/// [`ROUND2_PRUNE_AFTER`] iterations stops there (and is scored as it stands): on a
/// precise cloud that is a wrong basin, and the batch would otherwise run on for it.
fn refine_precise(
    evaluator: &mut dyn Evaluator,
    group: &[(usize, Prepared)],
    kept: &[Vec<Scored>],
    precise: &[usize],
    mids: &[Sample],
) -> Result<Vec<Vec<Scored>>, FitError> {
    let mut candidates = Vec::new();
    let mut sets = Vec::new();
    for &cloud in precise {
        let p = &group[cloud].1;
        let dual = kept[cloud]
            .first()
            .filter(|_| !p.skip.contains(&Stage::DualReading))
            .and_then(|best| p.turned_dual(&best.candidate));
        let cycled = kept[cloud]
            .first()
            .map_or(Vec::new(), |best| p.axes_cycled(&best.candidate));
        for c in kept[cloud]
            .iter()
            .map(|k| k.candidate)
            .chain(dual)
            .chain(cycled)
        {
            candidates.push(c);
            sets.push(cloud);
        }
    }
    let boxes: Vec<Bounds> = candidates
        .iter()
        .zip(&sets)
        .map(|(c, &cloud)| group[cloud].1.supported_bounds(c))
        .collect();
    let options = SolverOptions {
        prune_after: ROUND2_PRUNE_AFTER,
        prune_ratio: ROUND2_PRUNE_RATIO,
        ..group[0].1.opts2
    };
    let solutions = solve_on(evaluator, &candidates, &sets, &boxes, &options)?;
    let sample_refs: Vec<&Sample> = mids.iter().collect();
    let scored2 = scored(
        evaluator,
        &solutions,
        &sets,
        &sample_refs,
        |p| p.stage2_pts.len(),
        group,
    )?;
    let mut out = Vec::with_capacity(precise.len());
    for &cloud in precise {
        let p = &group[cloud].1;
        let own = of_cloud(&scored2, &sets, cloud).copied().collect();
        let mut refined = Vec::new();
        for c in most_likely_distinct(own, 2) {
            refined.push(robust_candidate(evaluator, p, &mids[cloud], cloud, c, 0)?);
        }
        out.push(refined);
    }
    Ok(out)
}

/// Round 2 of a noisy cloud: each kept candidate refined by the likelihood at `noise`,
/// then the other reading of the likeliest one's top view (least squares cannot tell the
/// two apart: the likelihood can, given the points), after least squares in its own
/// basin.
fn refine_noisy(
    evaluator: &mut dyn Evaluator,
    p: &Prepared,
    cloud: usize,
    kept: &[Scored],
    mid: &Sample,
    noise: f64,
) -> Result<Vec<Scored>, FitError> {
    // (side by side: see `scored`)
    let modelled: Vec<Option<Scored>> = kept
        .par_iter()
        .map(|c| likelihood_candidate(p, mid, *c, noise))
        .collect();
    let mut refined = Vec::with_capacity(kept.len() + 1);
    for (c, r) in kept.iter().zip(modelled) {
        // (a candidate whose likelihood collapses converges by robust least squares
        // instead: left as round 1 left it, ten iterations in, it could still stand)
        let r = match r {
            Some(r) => r,
            None => robust_candidate(evaluator, p, mid, cloud, *c, ROUND1_SHORTFALL)?,
        };
        refined.push(r);
    }
    let best = choose(&refined);
    let dual = p
        .turned_dual(&best.candidate)
        .filter(|_| !p.skip.contains(&Stage::DualReading));
    // the best one's other readings, each after least squares in its own basin, then
    // refined side by side as the kept ones are
    let mut others = Vec::new();
    for other in dual.into_iter().chain(p.axes_cycled(&best.candidate)) {
        let scored = Scored {
            candidate: other,
            ..best
        };
        others.push(robust_candidate(
            evaluator,
            p,
            mid,
            cloud,
            scored,
            ROUND1_SHORTFALL,
        )?);
    }
    refined.par_extend(
        others
            .into_par_iter()
            .map(|other| likelihood_candidate(p, mid, other, noise).unwrap_or(other)),
    );
    Ok(refined)
}

/// Round 2's likeliest ring, where every finalist (round 2's likeliest among them) is
/// closed: it converges beside them ([`finalists`]). A ring and a closed body lying
/// across its hole are told apart only once converged: round 2's few likelihood steps on
/// a sample leave a thin ring seen near edge-on behind the slab that covers it by more
/// than `CLOSE_MARGIN`, so the ring converges whatever its margin, and the likeliest
/// after convergence stands.
fn ring_beside_closed(finalists: &[Scored], round2: &[Scored]) -> Option<Scored> {
    let holed = |s: &Scored| s.candidate.shape.has_hole();
    if finalists.iter().any(holed) {
        return None;
    }
    round2
        .iter()
        .filter(|c| c.modelled && holed(c))
        .min_by(|a, b| a.rank(b))
        .copied()
}

/// Each cloud's fit: its likeliest round-2 candidate, converged on the stage-2 sample
/// where the likelihood refined it (a runner-up within [`CLOSE_MARGIN`] converges too,
/// and the likelier of the two stands: the two readings of a top view are often that
/// close). A closed one seen across its axis has its hollow reading converged beside it
/// ([`reading_finalist`]), and where every finalist is closed round 2's likeliest ring
/// ([`ring_beside_closed`]); a fit still closed then meets the rings it may lie across
/// ([`beside_rings_across`]). The polish then takes it on more of the cloud's points. With
/// the number of finalists converged.
pub(super) fn finalists(
    group: &[(usize, Prepared)],
    round2: &[Vec<Scored>],
    best2: &[Scored],
    all_round: &[bool],
    dropped: &[bool],
) -> Vec<(Scored, usize)> {
    group
        .par_iter()
        .enumerate()
        .map(|(cloud, (_, p))| {
            let best = best2[cloud];
            if dropped[cloud] {
                return (best, 0);
            }
            if !best.modelled {
                return precise_finalist(p, best, all_round[cloud]);
            }
            let sample = sample_of(p, &p.stage2_pts, all_round[cloud]);
            let close: Vec<Scored> = round2[cloud]
                .iter()
                .filter(|c| c.modelled && c.score <= best.score + CLOSE_MARGIN)
                .copied()
                .collect();
            let mut finalists = most_likely_distinct(close, 2);
            if let Some(ring) = ring_beside_closed(&finalists, &round2[cloud]) {
                finalists.push(ring);
            }
            let mut converged: Vec<Scored> = finalists
                .into_par_iter()
                .map(|c| converge(p, &sample, c, REFINE_ITERATIONS))
                .collect();
            converged.sort_by(|a, b| a.rank(b));
            let winner = converged.first().copied().unwrap_or(best);
            let hollow = p
                .hollowed(&winner.candidate)
                .and_then(|opened| reading_finalist(p, &sample, opened, winner, winner))
                .map(|hollow| narrower_where_likelier(p, &sample, hollow));
            let standing = match hollow {
                // (the hollow reading and its narrower hole converged beside the finalists)
                Some(hollow) => (hollow, converged.len() + 2),
                None => (winner, converged.len()),
            };
            beside_rings_across(p, &sample, standing, None)
        })
        .collect()
}

/// A precise cloud's fit after its finalists, `(fit, finalists converged)`: its
/// least-squares fit `best`, converged by the likelihood on the stage-2 sample where a
/// reading of it is weighed (its hollow reading, the rings across it), or where it is a
/// view whose points show noise. A view's converged fit stands where it blurs the points
/// by at most [`MAX_SIGMA_GROWTH`] times the noise they show (so never on a precise
/// view, whose likelihood is floored at [`REFINE_SIGMA_FLOOR`]): least squares weighs
/// neither the sensor's density of points nor the surface it should have seen, and on a
/// depth sensor's view, noisy along its rays and stepped in depth, it ends off the
/// likeliest fit.
fn precise_finalist(p: &Prepared, best: Scored, all_round: bool) -> (Scored, usize) {
    let opened = p.hollowed(&best.candidate);
    // (the noise as round 2 reads it: the view's scatter, or the fit's residual scale
    // where that is the smaller; a precise view, its noise under half the likelihood's
    // floor, keeps its least-squares fit, as does a fit without the noise model)
    let noise = p
        .viewpoint
        .filter(|_| p.noise_model)
        .and(p.scatter())
        .map(|s| s.min(best.sigma))
        .filter(|&noise| noise >= REFINE_SIGMA_FLOOR / MAX_SIGMA_GROWTH)
        .filter(|_| !p.skip.contains(&Stage::ViewLikelihood));
    if opened.is_none() && p.rings_across(&best.candidate).is_empty() && noise.is_none() {
        return (best, 0);
    }
    let sample = sample_of(p, &p.stage2_pts, all_round);
    let Some(converged) = converged_for_comparison(p, &sample, best) else {
        return (best, 0);
    };
    // (the view's converged fit, where it stands, is the finalist its readings meet;
    // otherwise the least-squares fit, weighed as converged)
    let (fit, counted) = if noise.is_some_and(|noise| converged.sigma <= MAX_SIGMA_GROWTH * noise) {
        let fit = Scored {
            modelled: true,
            ..converged
        };
        (fit, 1)
    } else {
        (best, 0)
    };
    let hollow = opened.and_then(|o| reading_finalist(p, &sample, o, fit, converged));
    let standing = match hollow {
        Some(hollow) => (hollow, counted + 2),
        None => (fit, counted),
    };
    beside_rings_across(p, &sample, standing, Some(converged))
}

/// A cloud's fit after its finalists, `(fit, finalists converged)`, against the rings it
/// may lie across where it is closed ([`Prepared::rings_across`]), each converged by the
/// likelihood on `sample` ([`reading_finalist`]): the likeliest ring stands where it is
/// likelier than the fit. A precise cloud's least-squares fit is weighed as `converged`
/// by the likelihood (the caller's, where it has it).
fn beside_rings_across(
    p: &Prepared,
    sample: &Sample,
    standing: (Scored, usize),
    converged: Option<Scored>,
) -> (Scored, usize) {
    let (fit, count) = standing;
    let rings = p.rings_across(&fit.candidate);
    if rings.is_empty() {
        return standing;
    }
    let against = if fit.modelled {
        Some(fit)
    } else {
        converged.or_else(|| converged_for_comparison(p, sample, fit))
    };
    let Some(against) = against else {
        return standing;
    };
    let tried = rings.len() + usize::from(!fit.modelled);
    rings
        .into_par_iter()
        .filter_map(|ring| reading_finalist(p, sample, ring, fit, against))
        .min_by(|a, b| a.rank(b))
        .map_or(standing, |ring| (ring, count + tried))
}

/// `reading`, a holed reading of a closed finalist (its hollow reading,
/// [`Prepared::hollowed`], or a ring across it, [`Prepared::rings_across`]), converged by
/// the likelihood on `sample` from the finalist's noise, where it keeps its hole and is
/// likelier than the finalist `converged` the same way (a precise cloud's finalist,
/// fitted by least squares, converged for the comparison only). None where the reading
/// is not the likelier: a tube seen from the side shows its outside only, which least
/// squares fits as well closed, and only the likelihood weighs whether the sensor should
/// have seen into a hole.
fn reading_finalist(
    p: &Prepared,
    sample: &Sample,
    reading: Candidate,
    finalist: Scored,
    converged: Scored,
) -> Option<Scored> {
    let from = Scored {
        candidate: reading,
        ..comparison_start(finalist)
    };
    let read = moved(converge(p, sample, from, REFINE_ITERATIONS), &reading)?;
    (read.candidate.shape.a4 > 1.0 && read.rank(&converged).is_lt()).then_some(Scored {
        modelled: true,
        ..read
    })
}

/// `hollow`, a noisy cloud's hollow reading that stood, or its outline around a narrower
/// hole ([`Prepared::narrowed`]) converged by the likelihood on `sample`, whichever is
/// the likelier (the hollow reading's start sets its wall, which the likelihood weighs
/// only at the rims).
fn narrower_where_likelier(p: &Prepared, sample: &Sample, hollow: Scored) -> Scored {
    let narrower = p.narrowed(&hollow.candidate);
    reading_finalist(p, sample, narrower, hollow, hollow).unwrap_or(hollow)
}

/// A least-squares `finalist` converged by the likelihood on `sample`, to be weighed
/// against a reading of it, ended at [`VIEW_STOP_DECREASE`]; None where the refinement
/// collapses.
fn converged_for_comparison(p: &Prepared, sample: &Sample, finalist: Scored) -> Option<Scored> {
    let start = comparison_start(finalist);
    moved(
        converge_until(p, sample, start, REFINE_ITERATIONS, VIEW_STOP_DECREASE),
        &finalist.candidate,
    )
}

/// Where a finalist and its readings start their likelihood refinement: at its noise,
/// floored at [`REFINE_SIGMA_FLOOR`].
fn comparison_start(finalist: Scored) -> Scored {
    Scored {
        sigma: finalist.sigma.max(REFINE_SIGMA_FLOOR),
        ..finalist
    }
}

/// A refinement that collapses hands its start back, score and all: no verdict.
fn moved(refined: Scored, from: &Candidate) -> Option<Scored> {
    (refined.candidate.shape != from.shape).then_some(refined)
}

//! The noise model's rescue of a single view whose fit leaves its visible surface bare:
//! bodies collapsed onto the points along the fit's hole axis, and behind the skin the
//! sensor saw, refined by the model, the most likely one the points cover kept.

use super::*;

/// The a4 of the collapsed starts of `rescue_unseen_surface`: a small, a middling and
/// a wide hole (the suite's a4 is in [1.2, 3]).
pub const RESCUE_A4: [f64; 3] = [1.3, 2.0, 3.0];

/// The rescue refines every start this many iterations, and only the [`RESCUE_KEPT`]
/// most likely on to convergence (successive halving: on the suite the same successes,
/// 449 against 448 of 540, at about 15% less time than every start to convergence).
pub(super) const RESCUE_FIRST_ITERATIONS: usize = 8;
/// How many of the rescue's starts go on to convergence (see [`RESCUE_FIRST_ITERATIONS`]).
pub(super) const RESCUE_KEPT: usize = 2;

/// A single-view fit that leaves much of the surface facing the sensor without points
/// ([`coverage::MIN_VISIBLE_COVERAGE`]) even after the retries of `retry_unseen_surfaces`
/// is nearly always a body grown into the side the sensor did not see: least squares
/// prefers it because the meridian distance of a thin, noisy section costs more than that
/// of a thick body through the same points. The noise model, with its visible-surface
/// density, scores such a body low, so the fit is refined by it from itself and from
/// bodies collapsed onto the points along its hole axis ([`prepare::start_for_axis`] with the
/// [`RESCUE_A4`]); the most likely refinement that the points cover and the free space
/// allows replaces the fit. None when the rescue does not apply or finds nothing covered.
pub(super) fn rescue_unseen_surface(
    evaluator: &dyn Evaluator,
    points: &[DVec3],
    options: &FitOptions,
    first: &FitReport,
) -> Option<FitReport> {
    if options.method != Method::Default || !options.noise_model {
        return None;
    }
    // (the first fit's preparation, sample and free-space points again: a few
    // milliseconds against the rescue's hundreds, and the first fit keeps none of it)
    let p = prepare(points, options, StartSet::Usual).ok()?;
    let viewpoint = p.viewpoint?;
    let fitted = p.norm.candidate(&first.fitted.0, &first.fitted.1);
    let mut starts = vec![fitted];
    starts.extend(p.collapsed_starts(&fitted));
    let best = p.most_likely_covered(starts, viewpoint)?;
    // the model's premise is noise that biases least squares: a first fit that sits on
    // the points (a noise-free view grown into a wrong basin) is left to its warning,
    // since the model's optimum there is no better founded than least squares'
    let first_noise = first.quality.noise_sigma / p.norm.scale;
    if first_noise < LIKELIHOOD_VIEW_NOISE_RATIO * best.candidate.shape.thinnest_half_axis() {
        return None;
    }
    let mut rescued = report(
        &p,
        &best.candidate,
        first.iterations.stage2 + best.iterations,
        Some(best.sigma),
        first.iterations.stage1,
        evaluator,
    );
    rescued.rescued = true;
    Some(rescued)
}

/// `start` (centred on the cloud's centroid, the origin of the normalised frame) moved
/// away from the sensor at `viewpoint`, across its hole axis, by its mean radius
/// a1·a4: a single view's centroid lies on the skin the sensor saw, and seen from the
/// side a ring's centre is that far behind it. None for a view into the hole (the axis
/// within [`starts::ALONG_SIGHT_DEGREES`] of the line of sight), whose centroid is on
/// the axis already. On the suite, 60175, a thin ring seen 10 degrees off edge-on, was
/// fitted as a closed body 8 times its size that its points covered 14% of; the
/// collapsed starts on the skin found nothing covered, one of these finds the truth.
pub(super) fn behind_the_skin(start: &Candidate, viewpoint: DVec3) -> Option<Candidate> {
    let axis = start.pose.axis();
    let away = (start.pose.translation - viewpoint).try_normalize()?;
    if away.dot(axis).abs() >= starts::ALONG_SIGHT_DEGREES.to_radians().cos() {
        return None;
    }
    let across = (away - axis * away.dot(axis)).try_normalize()?;
    let mut moved = *start;
    moved.pose.translation += across * (start.shape.a1 * start.shape.a4);
    Some(moved)
}

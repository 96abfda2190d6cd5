//! Which estimator a cloud's noise calls for: least squares on a precise cloud, the
//! likelihood ([`crate::fit::objective`]) where the noise is a sizeable part of the
//! thinnest half-axis, and when a likelihood fit has collapsed into blur.

use super::*;

/// The noise (first-order Euclidean sigma over the smallest of a1, a2, a3) from which a
/// fit without a viewpoint goes through [`likelihood::refine`]. (At 0.05 the full clouds
/// of the suite gained nothing, 140 of 141 below 0.1 were within tolerance already, and
/// the paper's clouds, noise 5-10% of their thinnest half-axis, took 63 ms a fit instead
/// of 9.)
pub const LIKELIHOOD_NOISE_RATIO: f64 = 0.1;
/// Without a viewpoint the noise model runs only where the points cover at least this
/// share of the fit's surface ([`likelihood::surface_coverage`]): a full cloud. Measured
/// on the suite without viewpoints (540 cases): single views 111 of 270 within tolerance
/// without the model, 97 with it everywhere, 102 with this check at 0.7, 111 at 0.85;
/// full clouds 228 without the model, 265 with it (everywhere, and at 0.7 and 0.85). (A
/// viewpoint guessed from the covered side's normals gave 97 again.)
pub const LIKELIHOOD_MIN_COVERAGE: f64 = 0.85;
/// The same with a viewpoint (single views). Measured on the suite's 270 single views
/// (three seed sets): 159 within tolerance at 0.1, 176 at 0.05; their median fit time
/// 27-35 -> 48-62 ms. With the view model as it is, over all 540 cases:
/// 506 at 0.05, 508 at 0.02 and at 0.01 (median single-view time 73-80 ms at 0.02,
/// 72-94 at 0.01).
pub const LIKELIHOOD_VIEW_NOISE_RATIO: f64 = 0.02;
/// The noise model's sigma may grow to this multiple of the least-squares fit's estimate;
/// beyond it the refinement is dropped. (On the suite the model's sigma ended within 0.8-1.2
/// of the truth; given a viewpoint opposite the camera, it squeezed the section to a
/// smallest half-axis of 1.8 mm under a sigma of 10 mm.) Round 2 holds a cloud's
/// likeliest refinement to the same multiple of the noise the cloud shows: the paper's
/// pot, a real object off the model by its open top, read as a view came out a
/// thin-walled tube at 4.3-4.7 times its scatter (Bad on 8 runs of 10); one view of the
/// 160 of the broadened sets 2900000 and 3000000 reaches 2.
pub const MAX_SIGMA_GROWTH: f64 = 2.0;
/// A noise-model fit whose section's thinnest half-axis is under this many of its sigmas
/// has collapsed: blur that wide hides any section, and the model then explains the
/// points by a flat sheet and takes the rest for outliers. (On the thirteen seed sets of
/// the suite, 2340 cases, every noisy case's thinnest half-axis is at least 1.03 sigmas.
/// With the outliers spread over the cloud's own box (`likelihood::outlier_volume`), and
/// so denser, a refinement on the suite could settle on a sheet 0.03 sigmas thick, sizes
/// 98% off.)
pub const MIN_SECTION_SIGMAS: f64 = 0.5;

/// Whether a noise-model fit has collapsed ([`MIN_SECTION_SIGMAS`]).
pub(super) fn collapsed_section(r: &likelihood::Refined) -> bool {
    r.candidate.shape.thinnest_half_axis() < MIN_SECTION_SIGMAS * r.sigma
}

/// Share of the points the likelihood model takes for outliers (spread over the cloud's
/// box along its principal axes, `likelihood::outlier_volume`; measured below with the
/// box along the world's axes). The suite's clouds carry 0, 5 or 10%; over its 540 cases
/// 0.02 gave 434 successes, 0.05 441, 0.1 438.
pub const LIKELIHOOD_OUTLIER_WEIGHT: f64 = 0.05;

/// Whether a fit with noise `sigma` (normalised) is noisy enough for least squares to be
/// biased, so that the likelihood refines it: [`LIKELIHOOD_VIEW_NOISE_RATIO`] of its
/// thinnest half-axis with a viewpoint; without one [`LIKELIHOOD_NOISE_RATIO`], and only
/// where the points cover the surface all round ([`LIKELIHOOD_MIN_COVERAGE`]: a
/// one-sided cloud from nowhere would have its unseen side shrunk).
pub(super) fn noisy(p: &Prepared, c: &Candidate, sigma: f64) -> bool {
    if !p.noise_model {
        return false;
    }
    let thinnest = c.shape.thinnest_half_axis();
    match p.viewpoint {
        Some(_) => sigma >= LIKELIHOOD_VIEW_NOISE_RATIO * thinnest,
        None => {
            sigma >= LIKELIHOOD_NOISE_RATIO * thinnest
                && c.shape.a4 > 1.0
                && likelihood::surface_coverage(&p.stage2_pts, c, sigma) >= LIKELIHOOD_MIN_COVERAGE
        }
    }
}

/// A likelihood fit that explains the points only by blurring them far more than least
/// squares found ([`MAX_SIGMA_GROWTH`]), or whose section is thinner than its blur
/// ([`MIN_SECTION_SIGMAS`]), has collapsed: blur that wide hides any section.
pub(super) fn collapsed(r: &objective::Refined, sigma: f64) -> bool {
    r.candidate.shape.thinnest_half_axis() < MIN_SECTION_SIGMAS * r.sigma
        || r.sigma > MAX_SIGMA_GROWTH * sigma.max(REFINE_SIGMA_FLOOR)
}

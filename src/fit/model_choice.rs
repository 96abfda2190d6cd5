//! Which model a cloud is: a supertoroid (one hole, or an apple's dimple: any a4) or a
//! superellipsoid (a4 = 0, no hole: boxes, cans, bottles). With `model: auto` the cloud
//! is fitted as both, in one batch, and the two fits are scored by the Bayesian
//! information criterion on the noise model's likelihood (the search's objective,
//! [`super::objective`]: seen from the fit's viewpoint where it had one, so a ring whose
//! visible side the sensor should have seen pays for it):
//!
//!   BIC = 2 · n · NLL + k · ln n
//!
//! where NLL is the negative mean log-likelihood per point at the noise sigma that
//! minimises it, n the points scored and k the free parameters (12 for the supertoroid:
//! six of shape, six of pose; 11 for the superellipsoid, whose a4 is fixed). The lower
//! BIC is chosen, the supertoroid only by at least [`MIN_EVIDENCE`], and an apple (a4 < 1)
//! only where its dimple is deeper than the noise ([`DIMPLE_SIGMAS`],
//! [`crate::model::Shape::dimple_depth`]): on a depth sensor's views of boxes the free fit
//! bends its profile to the noise at the edges with a4 and wins the BIC by 3-300 with a
//! dimple a fraction of a noise sigma deep.
//! The report gives both scores and their margin. A superellipsoid is the
//! supertoroid at a4 = 0, so the penalty decides only where the data cannot tell them
//! apart. The BIC wants each model at its likelihood's maximum: the search refines the
//! superellipsoid fit by the likelihood wherever it refines the cloud's free fit so
//! (`search::batch`'s model twins).

use super::search::Sample;
use super::{
    FieldOfView, FitError, FitOptions, FitReport, Sight, ablation::Stage,
    inferred_view::normalised_stride,
};
use serde::Serialize;

/// The most points of a cloud scored (an even stride through it).
pub const CHOICE_POINTS: usize = 1000;
/// Free parameters of each model (shape and pose; the noise sigma is common to both).
pub const SUPERTOROID_PARAMETERS: f64 = 12.0;
pub const SUPERELLIPSOID_PARAMETERS: f64 = 11.0;
/// The noise sigma is searched from the smaller of the two fits' own estimates over this
/// factor to the larger times it.
const SIGMA_RANGE: f64 = 4.0;
/// The least sigma scored (normalised units: 0.1% of the cloud's RMS radius), below any
/// real sensor's noise.
pub const MIN_SIGMA: f64 = 1e-3;
/// The search for that sigma stops once it is pinned within this (in ln sigma): the
/// negative log-likelihood is then within about 1e-4 per point of its least value, a BIC
/// within 0.1 on a thousand points.
const SIGMA_TOLERANCE: f64 = 0.01;
/// Evaluations of that search at most (Brent's method takes about eight).
const SIGMA_EVALUATIONS: usize = 20;
/// The supertoroid is chosen only where its BIC is lower by at least this much: positive
/// evidence on Kass and Raftery's scale of 2 ln(Bayes factor), which the BIC difference
/// approximates (under 2, "not worth more than a bare mention"). Below it the simpler
/// model stands: a free fit a hair better is mostly an apple whose dimple is under the
/// noise.
pub const MIN_EVIDENCE: f64 = 2.0;

/// A free fit without a hole (a4 < 1, an apple) whose dimple is shallower than this many
/// of its noise sigmas shows no sign of one. Set before measuring; the boxes' apple fits
/// of `bench scenes` 900000 had dimples of 0-1.4 sigmas, and on 900000, 910000 and the
/// fresh 920000 the rule took 10, 2 and 3 objects to the right model and fit, none the
/// other way (`docs/scenes.md`).
pub const DIMPLE_SIGMAS: f64 = 2.0;

/// A free fit whose a4 comes out below this is a superellipsoid (the solver stops a
/// margin inside its bounds, not on them), and is reported with a4 = 0.
pub const SUPERELLIPSOID_A4: f64 = 0.01;

/// Whether a shape is a superellipsoid ([`SUPERELLIPSOID_A4`]).
pub fn is_superellipsoid(shape: &crate::model::Shape) -> bool {
    shape.a4 < SUPERELLIPSOID_A4
}

/// Which model a fit answers with.
#[derive(
    Clone,
    Copy,
    Debug,
    Default,
    PartialEq,
    Eq,
    Serialize,
    serde::Deserialize,
    clap::ValueEnum,
    utoipa::ToSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum Model {
    /// both fitted, the lower BIC chosen (the supertoroid's by at least [`MIN_EVIDENCE`])
    #[default]
    Auto,
    /// one hole or none: a4 free
    Supertoroid,
    /// no hole: a4 held at 0
    Superellipsoid,
}

/// The model in a report: which, and how it was chosen.
#[derive(Clone, Debug, Serialize, utoipa::ToSchema)]
pub struct ModelOut {
    /// `supertoroid` or `superellipsoid`
    pub kind: Model,
    /// `requested` (the caller's `model`), `bic`, or `dimple_unseen` (the free fit has no
    /// hole and a dimple shallower than [`DIMPLE_SIGMAS`] noise sigmas, whatever its BIC)
    pub chosen_by: String,
    /// with `model: auto`: both models' BIC (lower is better; in nats, twice the negative
    /// log-likelihood plus the parameters' penalty) and the margin between them
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bic: Option<Bic>,
}

#[derive(Clone, Copy, Debug, Serialize, utoipa::ToSchema)]
pub struct Bic {
    /// absent where the free fit itself came out a superellipsoid (a4 = 0)
    pub supertoroid: Option<f64>,
    pub superellipsoid: f64,
    /// the loser's BIC minus the winner's (> 0)
    pub margin: Option<f64>,
    /// the points scored
    pub points: usize,
}

impl ModelOut {
    /// The model a fit asked for one model came out as ([`is_superellipsoid`]).
    pub fn requested(shape: &crate::model::Shape) -> Self {
        Self {
            kind: if is_superellipsoid(shape) {
                Model::Superellipsoid
            } else {
                Model::Supertoroid
            },
            chosen_by: "requested".into(),
            bic: None,
        }
    }
}

/// A free fit that came out a superellipsoid, standing for that model: its a4 held at 0
/// as the superellipsoid fit's is, so its a4 error (whether the points could hold a
/// hole, which the choice has weighed) and the warning it raised go.
fn with_a4_held(mut report: FitReport) -> FitReport {
    if let Some(errors) = report.quality.standard_errors.as_mut() {
        errors.a4 = 0.0;
        report
            .warnings
            .retain(|w| !w.starts_with(super::uncertainty::WARNING_PREFIX));
        report
            .warnings
            .splice(0..0, super::uncertainty::warning(errors));
    }
    report
}

/// The better of a cloud's two fits by BIC, its report's `model` saying so; its time is
/// the batch's that made both, and the choice's. Seen from a viewpoint, the cloud is
/// scored as what it saw within `field` (its frame's edges), where given.
pub fn choose(
    points: &[glam::DVec3],
    field: Option<FieldOfView>,
    holed: FitReport,
    genus0: FitReport,
) -> FitReport {
    let start = std::time::Instant::now();
    let (norm, sample) = normalised_stride(points, CHOICE_POINTS);
    let n = sample.len() as f64;
    // both fits are scored over one bracket of sigma, not under each fit's own noise
    // estimate, and never below MIN_SIGMA: on a noise-free cloud two fits a rounding
    // apart would otherwise differ by the log of their roundings' ratio at every point
    let sigmas = [&holed, &genus0].map(|r| (r.quality.noise_sigma / norm.scale).max(MIN_SIGMA));
    let lo = (sigmas[0].min(sigmas[1]) / SIGMA_RANGE).max(MIN_SIGMA);
    let hi = sigmas[0].max(sigmas[1]) * SIGMA_RANGE;
    // both under one model of the data: a view where either fit took the cloud for one
    // (the two may settle an inferred viewpoint differently), else the points' distances
    // alone (whether they cover the object all round is not known here)
    let viewpoint = holed
        .viewpoint
        .position
        .or(genus0.viewpoint.position)
        .map(|p| Sight {
            viewpoint: norm.point(p.into()),
            field,
        });
    let scored = Sample::new(&sample, viewpoint, false);
    let bic = |r: &FitReport| {
        let candidate = norm.candidate(&r.fitted.0, &r.fitted.1);
        let nll = least_score(
            |sigma| scored.score(&candidate, sigma),
            scored.continued_below_floor(),
            lo,
            hi,
        );
        let k = if is_superellipsoid(&r.shape) {
            SUPERELLIPSOID_PARAMETERS
        } else {
            SUPERTOROID_PARAMETERS
        };
        // (a NaN score loses)
        let value = 2.0 * n * nll + k * n.ln();
        if value.is_nan() { f64::INFINITY } else { value }
    };
    // (side by side: each score's per-shape tables are one thread's work)
    let (holed_bic, genus0_bic) = rayon::join(|| bic(&holed), || bic(&genus0));
    let both_ms = holed.timing_ms.total.max(genus0.timing_ms.total);
    // a free fit that came out at a4 = 0 is a superellipsoid too: the better of the two
    // then stands for that model, and there is no supertoroid to weigh against it
    let (supertoroid, superellipsoid, mut chosen, kind, chosen_by) =
        if is_superellipsoid(&holed.shape) {
            let (best, value) = if holed_bic < genus0_bic {
                (with_a4_held(holed), holed_bic)
            } else {
                (genus0, genus0_bic)
            };
            (None, value, best, Model::Superellipsoid, "bic")
        } else {
            // (a free fit with no hole whose dimple the noise hides is no evidence of one,
            // whatever its BIC: an apple's a4 bends its profile to the sensor's noise)
            let dimple_unseen =
                holed.shape.dimple_depth() < DIMPLE_SIGMAS * holed.quality.noise_sigma;
            let (kind, chosen_by) = if genus0_bic < holed_bic + MIN_EVIDENCE {
                (Model::Superellipsoid, "bic")
            } else if dimple_unseen {
                (Model::Superellipsoid, "dimple_unseen")
            } else {
                (Model::Supertoroid, "bic")
            };
            let chosen = if kind == Model::Supertoroid {
                holed
            } else {
                genus0
            };
            (Some(holed_bic), genus0_bic, chosen, kind, chosen_by)
        };
    let spent = start.elapsed().as_secs_f64() * 1e3;
    // (the two fits ran in one batch: the other model's, where it took longer, counts
    // with the weighing, so that the parts make the total)
    let choosing = both_ms - chosen.timing_ms.total + spent;
    chosen.timing_ms.total = both_ms + spent;
    chosen
        .timing_ms
        .stages
        .insert("model_choice".into(), choosing);
    if kind == Model::Superellipsoid {
        chosen.shape.a4 = 0.0;
        chosen.fitted.0.a4 = 0.0;
    }
    chosen.model = ModelOut {
        kind,
        chosen_by: chosen_by.into(),
        bic: Some(Bic {
            supertoroid,
            superellipsoid,
            margin: supertoroid.map(|t| (t - superellipsoid).abs()),
            points: sample.len(),
        }),
    };
    chosen
}

/// The least of a fit's `score` (a function of sigma) on [lo, hi]. Where it is
/// `continued` below the noise model's floor ([`super::search::SIGMA_FLOOR`]), the score
/// there is its thin-noise continuation (a line in ln sigma,
/// [`super::search::continued_below_floor`]), least at `lo`; above the floor it is the
/// noise model's, unimodal, searched by [`least_value`] unless it rises from the floor.
/// (Brent's method over the whole bracket would settle in either of the two dips, and
/// two fits could be weighed in different ones.)
fn least_score(score: impl Fn(f64) -> f64, continued: bool, lo: f64, hi: f64) -> f64 {
    let above = |lo: f64| least_value(|ln_sigma| score(ln_sigma.exp()), lo.ln(), hi.ln());
    let floor = super::search::SIGMA_FLOOR;
    if !continued || lo >= floor {
        return above(lo);
    }
    if hi <= floor {
        return score(lo);
    }
    let at_floor = score(floor);
    let below = super::search::continued_below_floor(at_floor, lo);
    let rises = score(floor * (2.0 * SIGMA_TOLERANCE).exp()) >= at_floor;
    if rises {
        below
    } else {
        below.min(above(floor))
    }
}

/// The least value of a unimodal `f` on [lo, hi] by Brent's method: parabolas through the
/// last three points where they step well inside the bracket, golden sections where not.
fn least_value(f: impl Fn(f64) -> f64, mut lo: f64, mut hi: f64) -> f64 {
    const GOLDEN: f64 = 0.381_966_011_250_105; // (3 - sqrt 5) / 2
    let tol = SIGMA_TOLERANCE;
    // x the best so far, w the second best, v the one before
    let mut x = lo + GOLDEN * (hi - lo);
    let (mut w, mut v) = (x, x);
    let mut fx = f(x);
    let (mut fw, mut fv) = (fx, fx);
    // the step taken, and the one before it
    let (mut step, mut previous) = (0.0f64, 0.0f64);
    for _ in 1..SIGMA_EVALUATIONS {
        let middle = 0.5 * (lo + hi);
        if (x - middle).abs() <= 2.0 * tol - 0.5 * (hi - lo) {
            break;
        }
        let mut parabolic = false;
        if previous.abs() > tol {
            let r = (x - w) * (fx - fv);
            let q = (x - v) * (fx - fw);
            let mut p = (x - v) * q - (x - w) * r;
            let mut q = 2.0 * (q - r);
            if q > 0.0 {
                p = -p;
            } else {
                q = -q;
            }
            // (a parabola's step must be less than half the step before last, and inside)
            if p.abs() < (0.5 * q * previous).abs() && p > q * (lo - x) && p < q * (hi - x) {
                previous = step;
                step = p / q;
                let u = x + step;
                if u - lo < 2.0 * tol || hi - u < 2.0 * tol {
                    step = tol.copysign(middle - x);
                }
                parabolic = true;
            }
        }
        if !parabolic {
            previous = if x >= middle { lo - x } else { hi - x };
            step = GOLDEN * previous;
        }
        let u = x + if step.abs() >= tol {
            step
        } else {
            tol.copysign(step)
        };
        let fu = f(u);
        if fu <= fx {
            if u >= x {
                lo = x;
            } else {
                hi = x;
            }
            (v, fv, w, fw, x, fx) = (w, fw, x, fx, u, fu);
        } else {
            if u < x {
                lo = u;
            } else {
                hi = u;
            }
            if fu <= fw || w == x {
                (v, fv, w, fw) = (w, fw, u, fu);
            } else if fu <= fv || v == x || v == w {
                (v, fv) = (u, fu);
            }
        }
    }
    fx
}

/// The fits a cloud's [`Model`] asks for: the supertoroid's (a4 free), the
/// superellipsoid's (a4 held at 0), or both for auto (in that order). A
/// known a4 decides the model itself.
pub(super) fn fits_of_model(o: &FitOptions) -> Result<Vec<FitOptions>, FitError> {
    let as_model = |model: Model| {
        let mut o = FitOptions { model, ..o.clone() };
        if model == Model::Superellipsoid {
            o.known_shape[3] = Some(0.0);
        }
        o
    };
    Ok(match (o.model, o.known_shape[3]) {
        (Model::Superellipsoid, Some(a4)) if a4 != 0.0 => {
            return Err(FitError::InvalidOption(format!(
                "model superellipsoid has a4 = 0, but a4 = {a4} is given as known"
            )));
        }
        (Model::Auto, Some(a4)) if a4 != 0.0 => vec![as_model(Model::Supertoroid)],
        (Model::Auto, Some(_)) | (Model::Superellipsoid, _) => {
            vec![as_model(Model::Superellipsoid)]
        }
        (Model::Supertoroid, _) => vec![o.clone()],
        (Model::Auto, None) => {
            // (the superellipsoid's own fit stands for a closed body here: the free fit
            // does not also try the rings a closed fit may lie across, which cost the
            // superellipsoids of `bench models` 890000 two models and more than twice
            // their time)
            let mut free = as_model(Model::Supertoroid);
            free.skip.push(Stage::RingsAcross);
            vec![free, as_model(Model::Superellipsoid)]
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A score continued below the floor as the sample's is: its least is found in the
    /// lower of its two dips (the bracket's low end, or the noise model's own above the
    /// floor), and a score that rises from the floor costs two evaluations.
    #[test]
    fn the_least_score_is_the_lower_of_its_two_dips() {
        let floor = crate::fit::search::SIGMA_FLOOR;
        let evaluations = std::cell::Cell::new(0);
        // the noise model's shape above the floor, least at s
        let score = |s: f64| {
            let evaluations = &evaluations;
            move |sigma: f64| {
                evaluations.set(evaluations.get() + 1);
                let at = |sigma: f64| sigma.ln() + s * s / (2.0 * sigma * sigma);
                crate::fit::search::continued_below_floor(at(sigma.max(floor)), sigma)
            }
        };
        let (lo, hi) = (floor / 10.0, floor * 40.0);
        // noise four times the floor: its own dip is deeper than the line's end
        let s = 4.0 * floor;
        let own = s.ln() + 0.5;
        let least = least_score(score(s), true, lo, hi);
        let line_end = floor.ln() + s * s / (2.0 * floor * floor) - (floor / lo).ln();
        assert!(
            own < line_end && (least - own).abs() < 1e-4,
            "{least} {own}"
        );
        // noise at a fifth of the floor: the score rises from it, least at lo
        let s = 0.2 * floor;
        evaluations.set(0);
        let least = least_score(score(s), true, lo, hi);
        let at_lo = floor.ln() + 0.02 - (floor / lo).ln();
        assert!((least - at_lo).abs() < 1e-12, "{least} {at_lo}");
        assert_eq!(evaluations.get(), 2);
        // noise a little over the floor: the line's end is the lower dip
        let s = 1.3 * floor;
        let least = least_score(score(s), true, lo, hi);
        let at_lo = floor.ln() + 0.5 * 1.69 - (floor / lo).ln();
        assert!((least - at_lo).abs() < 1e-12, "{least} {at_lo}");
    }

    /// On a parabola, and on the shape of a noise model's negative log-likelihood in ln
    /// sigma (ln sigma + s² / 2 sigma², least at ln s), within the tolerance's value and
    /// in fewer evaluations than golden sections would take.
    #[test]
    fn brents_method_finds_the_least_value() {
        let evaluations = std::cell::Cell::new(0);
        let counted = |f: &dyn Fn(f64) -> f64, x: f64| {
            evaluations.set(evaluations.get() + 1);
            f(x)
        };
        let parabola = |x: f64| (x - 0.3).powi(2) + 2.0;
        let least = least_value(|x| counted(&parabola, x), -1.0, 2.0);
        assert!((least - 2.0).abs() < 1e-4, "{least}");
        let s: f64 = 0.05;
        let nll = |ln_sigma: f64| ln_sigma + s * s / (2.0 * (2.0 * ln_sigma).exp());
        let truth = nll(s.ln());
        for (lo, hi) in [(s.ln() - 2.0, s.ln() + 1.5), (s.ln() - 0.3, s.ln() + 3.0)] {
            evaluations.set(0);
            let least = least_value(|x| counted(&nll, x), lo, hi);
            assert!(
                least >= truth - 1e-12 && least - truth < 1e-4,
                "{least} {truth}"
            );
            assert!(evaluations.get() <= 12, "{}", evaluations.get());
        }
    }
}

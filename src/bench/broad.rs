//! The broadened single-view suite (`supertoroid bench broad`, [`crate::suite::broad`]):
//! tall rolls, thin washers, oval rings and the ground-truth suite's own shapes seen by a
//! D435-like sensor (noise along the ray growing with range², 1 mm steps, flying pixels,
//! outliers over the scene's box on half), fitted as users post the clouds: in the
//! camera's frame, no options.
//!
//! Success by the suite's rule, per family and in all, with the fits' median and p95
//! time and how many wrong and right fits carry a warning. Each miss is also placed: the
//! fit's own estimator started at the truth on all the points misses too
//! ([`model_from_truth`]), and the truth's basin is likelier than the fit's under the fit's
//! noise model by more than [`BASIN_GAP`] ([`basin_gap`]): a miss in a less likely basin
//! than the truth's is the search's, one at least as likely is the estimator's, and one
//! that lost its hole is unscored.

use super::{Report, percentile};
use crate::eval::{Backend, make_evaluator};
use crate::fit::{FitError, FitOptions, fit, scatter};
use crate::suite::attainable;
use crate::suite::broad::{FAMILIES, view};
use crate::suite::ground_truth::{TruthPoints, basin_gap, compare, model_from_truth};
use serde::Serialize;

/// A gap in mean log-likelihood per point above which the truth's basin counts as the
/// likelier (the likelihood's refinements stop at steps of 1e-4).
pub const BASIN_GAP: f64 = 1e-3;

/// Whose a miss is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Miss {
    /// the truth's basin is the likelier: the search did not find it
    Search,
    /// the fit's basin is at least as likely as the truth's: the estimator's optimum
    Estimator,
    /// unscored: a fit that lost its hole (the grid model that weighs the basins needs
    /// one), or a noise-free view
    Unscored,
}

#[derive(Clone, Debug, Serialize)]
pub struct BroadCase {
    pub seed: u64,
    pub family: &'static str,
    /// refused by the object screen (a failed case)
    pub refused: bool,
    pub success: bool,
    /// the warnings' kinds (what precedes each one's colon)
    pub warnings: Vec<String>,
    /// the standard errors' largest share of the success rule's tolerances
    pub uncertainty: f64,
    /// the fit's median distance over its size, and over the cloud's own scatter
    pub median_over_size: f64,
    pub median_over_scatter: f64,
    pub t_total_ms: f64,
    /// the share of fits within the rule of an efficient estimator of this view
    /// ([`attainable::broad_view`]: the Cramér-Rao bound of its inliers); NaN where it has
    /// none
    pub attainable: f64,
    /// for a miss: whose it is, and whether the estimator from the truth misses too
    pub miss: Option<Miss>,
    pub estimator_misses_too: bool,
}

#[derive(Clone, Debug, Serialize)]
pub struct BroadReport {
    pub machine: super::Machine,
    pub cases: Vec<BroadCase>,
}

/// Views `seed` to `seed + cases - 1`, fitted with `base` (its seed each view's).
pub fn run(
    cases: usize,
    seed: u64,
    backend: Backend,
    base: &FitOptions,
) -> Result<BroadReport, String> {
    if cases == 0 {
        return Err("--cases must be at least 1".into());
    }
    let mut evaluator = make_evaluator(backend, base.stage2_points).map_err(|e| e.to_string())?;
    let bar = super::progress(cases as u64, "broadened views");
    let mut out = Vec::with_capacity(cases);
    for case_seed in seed..seed + cases as u64 {
        let options = FitOptions {
            seed: case_seed,
            ..base.clone()
        };
        out.push(judged_view(evaluator.as_mut(), case_seed, &options)?);
        bar.inc(1);
    }
    bar.finish_and_clear();
    Ok(BroadReport {
        machine: super::Machine::probe(),
        cases: out,
    })
}

/// View `seed` fitted with `options` and judged against its truth: a view the object
/// screen refuses is a failed case, any other error stops the run.
fn judged_view(
    evaluator: &mut dyn crate::eval::Evaluator,
    seed: u64,
    options: &FitOptions,
) -> Result<BroadCase, String> {
    let case = view(seed);
    let family = FAMILIES[(seed % 4) as usize];
    let attainable = attainable::broad_view(&case, seed).unwrap_or(f64::NAN);
    let report = match fit(evaluator, &case.points, options) {
        Ok(report) => report,
        Err(FitError::NoObject(_)) => {
            return Ok(BroadCase {
                attainable,
                ..BroadCase::refused(seed, family)
            });
        }
        Err(e) => return Err(format!("case {seed}: {e}")),
    };
    let (shape, pose) = &report.fitted;
    let success = compare((&case.shape, &case.pose), (shape, pose)).success();
    let median = report.quality.median_distance;
    let (miss, estimator_misses_too) = if success {
        (None, false)
    } else {
        let from_truth = model_from_truth(&case, TruthPoints::All, true, options);
        let gap = basin_gap(&case, (shape, pose), report.quality.noise_sigma, options);
        let miss = match gap {
            Some(g) if g > BASIN_GAP => Miss::Search,
            Some(_) => Miss::Estimator,
            None => Miss::Unscored,
        };
        (Some(miss), !from_truth.is_some_and(|e| e.success()))
    };
    Ok(BroadCase {
        seed,
        family,
        refused: false,
        success,
        warnings: report
            .warnings
            .iter()
            .map(|w| w.split(':').next().unwrap_or_default().to_owned())
            .collect(),
        uncertainty: report
            .quality
            .standard_errors
            .as_ref()
            .map_or(f64::NAN, |e| e.share_of_tolerance()),
        median_over_size: median / shape.size(),
        median_over_scatter: scatter::local_scatter(&case.points).map_or(f64::NAN, |s| median / s),
        t_total_ms: report.timing_ms.total,
        attainable,
        miss,
        estimator_misses_too,
    })
}

impl BroadCase {
    fn refused(seed: u64, family: &'static str) -> Self {
        Self {
            seed,
            family,
            refused: true,
            success: false,
            warnings: Vec::new(),
            uncertainty: f64::NAN,
            median_over_size: f64::NAN,
            median_over_scatter: f64::NAN,
            t_total_ms: f64::NAN,
            attainable: f64::NAN,
            miss: None,
            estimator_misses_too: false,
        }
    }

    fn warned(&self) -> bool {
        !self.warnings.is_empty()
    }
}

impl Report for BroadReport {
    fn name(&self) -> &'static str {
        "broad"
    }

    fn csv(&self) -> String {
        let mut s = String::from(
            "seed,family,refused,success,warned,uncertainty,median_over_size,median_over_scatter,t_total_ms,attainable,miss,estimator_misses_too,warnings\n",
        );
        for c in &self.cases {
            s += &format!(
                "{},{},{},{},{},{},{},{},{:.1},{:.4},{},{},{}\n",
                c.seed,
                c.family,
                c.refused,
                c.success,
                c.warned(),
                c.uncertainty,
                c.median_over_size,
                c.median_over_scatter,
                c.t_total_ms,
                c.attainable,
                c.miss
                    .map_or(String::new(), |m| format!("{m:?}").to_lowercase()),
                c.estimator_misses_too,
                c.warnings.join(";")
            );
        }
        s
    }

    fn markdown(&self) -> String {
        let n = self.cases.len();
        let right = self.cases.iter().filter(|c| c.success).count();
        let times: Vec<f64> = self
            .cases
            .iter()
            .map(|c| c.t_total_ms)
            .filter(|t| t.is_finite())
            .collect();
        let mut md = format!(
            "# Broadened single views\n\n{}\n{n} views (seeds {}..) through a D435-like sensor, as users post them (camera frame, no options): {right} right ({:.1}%), {} refused as no object; fit median {:.0} ms, p95 {:.0} ms.\n\n| family | right | an efficient estimator | wrong fits warned | right fits warned |\n|---|---|---|---|---|\n",
            self.machine.markdown(),
            self.cases.first().map_or(0, |c| c.seed),
            100.0 * right as f64 / n.max(1) as f64,
            self.cases.iter().filter(|c| c.refused).count(),
            percentile(times.clone(), 0.5),
            percentile(times, 0.95),
        );
        for family in FAMILIES.iter().copied().chain(["all"]) {
            let kept: Vec<&BroadCase> = self
                .cases
                .iter()
                .filter(|c| family == "all" || c.family == family)
                .collect();
            let (wrong, good): (Vec<&BroadCase>, Vec<&BroadCase>) =
                kept.iter().partition(|c| !c.success);
            let warned = |cases: &[&BroadCase]| cases.iter().filter(|c| c.warned()).count();
            md += &format!(
                "| {family} | {} of {} | {:.1} | {} of {} | {} of {} |\n",
                good.len(),
                kept.len(),
                expected_right(&kept),
                warned(&wrong),
                wrong.len(),
                warned(&good),
                good.len()
            );
        }
        let misses = |m: Miss| self.cases.iter().filter(|c| c.miss == Some(m)).count();
        md += &format!(
            "\nMisses: {} in a basin less likely than the truth's (the search's), {} in one at least as likely (the estimator's), {} unscored (the hole lost); the estimator started at the truth misses {} of them too.\n",
            misses(Miss::Search),
            misses(Miss::Estimator),
            misses(Miss::Unscored),
            self.cases.iter().filter(|c| c.estimator_misses_too).count()
        );
        let beyond = self
            .cases
            .iter()
            .filter(|c| !c.success && c.attainable < 0.5)
            .count();
        md += &format!(
            "\nWhat the views allow (`suite::attainable::broad_view`): an efficient estimator, one that reaches the Cramér-Rao bound of each view's inliers, would be right on {:.1} of the {n} views (the expected count); {beyond} of the misses are views it would miss more often than not. A first-order figure: see the module's caveats.\n",
            expected_right(&self.cases.iter().collect::<Vec<_>>()),
        );
        md
    }
}

/// The expected number of `cases` an efficient estimator gets right (the sum of their
/// `attainable`; a case without one counts as right).
fn expected_right(cases: &[&BroadCase]) -> f64 {
    cases
        .iter()
        .map(|c| {
            if c.attainable.is_nan() {
                1.0
            } else {
                c.attainable
            }
        })
        .sum()
}

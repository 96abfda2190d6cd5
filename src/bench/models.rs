//! The model-choice suite (`supertoroid bench models`): half the cases supertoroids
//! with a hole (the ground-truth suite's shapes), half superellipsoids (sizes
//! 0.02-0.15, eps 0.1-1.9), in the suite's categories (full or a single view, noise,
//! outliers), posted as users post them (a view in its camera's frame, no options) and
//! fitted with the given options' model (`auto` by default here). A case is right when
//! the chosen model is the true one and the fit is within its rule: the suite's
//! parameter rule for a holed shape, the surface chamfer distance for a superellipsoid
//! ([`crate::suite::chamfer`]).

use super::synthetic::{Presentation, category, presented, wilson_interval};
use super::{Report, percentile};
use crate::eval::{Backend, make_evaluator};
use crate::fit::{FitError, FitOptions, FitReport, Model, fit};
use crate::model::Pose;
use crate::suite::chamfer::{CHAMFER_BOUND, relative_chamfer};
use crate::suite::ground_truth::{Case, Kind, compare, make_case_of};
use serde::Serialize;

#[derive(Clone, Debug, Serialize)]
pub struct ModelCase {
    pub seed: u64,
    pub kind: Kind,
    pub partial: bool,
    pub noise: f64,
    pub outliers: f64,
    /// the model the fit answered with; None where the object screen refused the cloud
    /// (`no_object_found`: a failed case)
    pub chosen: Option<Model>,
    pub model_right: bool,
    /// within the kind's rule (the model right too)
    pub success: bool,
    /// the surface chamfer distance over the true size
    pub chamfer: f64,
    /// the BIC margin of the choice (NaN where only one model was fitted)
    pub margin: f64,
    pub t_total_ms: f64,
    /// whether the fit carried any warning
    pub warned: bool,
}

impl ModelCase {
    /// A case of `kind` in `category` (partial, noise, outliers) with no fit: failed.
    fn failed(seed: u64, kind: Kind, category: (bool, f64, f64)) -> Self {
        let (partial, noise, outliers) = category;
        ModelCase {
            seed,
            kind,
            partial,
            noise,
            outliers,
            chosen: None,
            model_right: false,
            success: false,
            chamfer: f64::NAN,
            margin: f64::NAN,
            t_total_ms: f64::NAN,
            warned: false,
        }
    }
}

#[derive(Clone, Debug, Serialize)]
pub struct ModelReport {
    pub machine: super::Machine,
    pub model: Model,
    pub cases: Vec<ModelCase>,
}

/// Case i of the suite from `seed`: holed for even i, a superellipsoid for odd, the
/// category of i / 2.
pub fn run(
    cases: usize,
    seed: u64,
    backend: Backend,
    base: &FitOptions,
) -> Result<ModelReport, String> {
    if cases == 0 {
        return Err("--cases must be at least 1".into());
    }
    let mut evaluator = make_evaluator(backend, base.stage2_points).map_err(|e| e.to_string())?;
    let bar = super::progress(cases as u64, "model-choice suite");
    let mut out = Vec::with_capacity(cases);
    for i in 0..cases {
        let kind = if i % 2 == 0 {
            Kind::Holed
        } else {
            Kind::Superellipsoid
        };
        let (partial, noise, outliers) = category(i / 2);
        let case_seed = seed + i as u64;
        let case = make_case_of(kind, case_seed, partial, noise, outliers);
        let (points, viewpoint, back) = presented(&case, Presentation::Camera);
        let options = FitOptions {
            seed: case_seed,
            viewpoint,
            ..base.clone()
        };
        let refused = ModelCase::failed(case_seed, kind, (partial, noise, outliers));
        let fitted = fit(evaluator.as_mut(), &points, &options);
        out.push(judged(refused, &case, &back, fitted)?);
        bar.inc(1);
    }
    bar.finish_and_clear();
    Ok(ModelReport {
        machine: super::Machine::probe(),
        model: base.model,
        cases: out,
    })
}

/// A case judged from its fit (`back` takes the fit from the camera's frame to the
/// case's): `refused` (the case's description, failed) with the fit's model, rule and
/// time filled in. A true object refused by the object screen is that failed case, not a
/// stop; any other error stops the run.
fn judged(
    refused: ModelCase,
    case: &Case,
    back: &Pose,
    fitted: Result<FitReport, FitError>,
) -> Result<ModelCase, String> {
    let report = match fitted {
        Ok(report) => report,
        Err(FitError::NoObject(_)) => return Ok(refused),
        Err(e) => return Err(format!("case {}: {e}", refused.seed)),
    };
    let (shape, fitted) = report.fitted;
    let pose = back.compose(&fitted);
    let chosen = report.model.kind;
    let model_right = match refused.kind {
        Kind::Holed => chosen == Model::Supertoroid,
        Kind::Superellipsoid => chosen == Model::Superellipsoid,
    };
    let chamfer = relative_chamfer((&case.shape, &case.pose), (&shape, &pose));
    let within = match refused.kind {
        Kind::Holed => compare((&case.shape, &case.pose), (&shape, &pose)).success(),
        Kind::Superellipsoid => chamfer < CHAMFER_BOUND,
    };
    Ok(ModelCase {
        chosen: Some(chosen),
        model_right,
        success: model_right && within,
        chamfer,
        margin: report.model.bic.and_then(|b| b.margin).unwrap_or(f64::NAN),
        t_total_ms: report.timing_ms.total,
        warned: !report.warnings.is_empty(),
        ..refused
    })
}

impl Report for ModelReport {
    fn name(&self) -> &'static str {
        "models"
    }

    fn csv(&self) -> String {
        let mut s = String::from(
            "seed,kind,partial,noise,outliers,chosen,model_right,success,chamfer,margin,t_total_ms,warned\n",
        );
        for c in &self.cases {
            s += &format!(
                "{},{:?},{},{},{},{},{},{},{:.5},{:.2},{:.1},{}\n",
                c.seed,
                c.kind,
                c.partial,
                c.noise,
                c.outliers,
                c.chosen.map_or("none".to_owned(), |m| format!("{m:?}")),
                c.model_right,
                c.success,
                c.chamfer,
                c.margin,
                c.t_total_ms,
                c.warned
            );
        }
        s
    }

    fn markdown(&self) -> String {
        let mut md = format!(
            "# Model choice: supertoroids with a hole and superellipsoids\n\n{}\n\nModel `{:?}`; clouds as users post them (a view in its camera's frame, no options). Right: the true model chosen and the fit within its rule (holed: the suite's parameter rule; superellipsoid: surface chamfer under {:.0}% of the size).\n\n| cases | model right | right (model and fit) | 95% interval | median ms | p95 ms |\n|---|---|---|---|---|---|\n",
            self.machine.markdown(),
            self.model,
            100.0 * CHAMFER_BOUND
        );
        let rows: [(&str, Box<dyn Fn(&ModelCase) -> bool>); 5] = [
            ("all", Box::new(|_| true)),
            ("holed", Box::new(|c| c.kind == Kind::Holed)),
            (
                "superellipsoid",
                Box::new(|c| c.kind == Kind::Superellipsoid),
            ),
            ("full clouds", Box::new(|c| !c.partial)),
            ("single views", Box::new(|c| c.partial)),
        ];
        for (label, keep) in rows {
            let kept: Vec<&ModelCase> = self.cases.iter().filter(|c| keep(c)).collect();
            let n = kept.len();
            let model_right = kept.iter().filter(|c| c.model_right).count();
            let right = kept.iter().filter(|c| c.success).count();
            let [lo, hi] = wilson_interval(right, n);
            // (a refused cloud has no fit time)
            let times: Vec<f64> = kept
                .iter()
                .map(|c| c.t_total_ms)
                .filter(|t| t.is_finite())
                .collect();
            md += &format!(
                "| {label}: {n} | {model_right} ({:.1}%) | {right} ({:.1}%) | {:.1}-{:.1}% | {:.0} | {:.0} |\n",
                100.0 * model_right as f64 / n.max(1) as f64,
                100.0 * right as f64 / n.max(1) as f64,
                100.0 * lo,
                100.0 * hi,
                percentile(times.clone(), 0.5),
                percentile(times, 0.95),
            );
        }
        let (wrong, right): (Vec<&ModelCase>, Vec<&ModelCase>) =
            self.cases.iter().partition(|c| !c.success);
        let warned = |cases: &[&ModelCase]| cases.iter().filter(|c| c.warned).count();
        md += &format!(
            "\nWarnings: {} of the {} wrong fits carry one, {} of the {} right ones.\n",
            warned(&wrong),
            wrong.len(),
            warned(&right),
            right.len()
        );
        md
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_refused_cloud_is_a_failed_case_and_other_errors_stop_the_run() {
        let case = make_case_of(Kind::Superellipsoid, 7, true, 0.01, 0.0);
        let refused = ModelCase::failed(7, Kind::Superellipsoid, (true, 0.01, 0.0));
        let back = Pose::new(glam::DQuat::IDENTITY, glam::DVec3::ZERO);
        let judged_refusal = judged(
            refused.clone(),
            &case,
            &back,
            Err(FitError::NoObject("a bare plane".into())),
        )
        .expect("a refusal is a case");
        assert!(judged_refusal.chosen.is_none() && !judged_refusal.success);
        let report = ModelReport {
            machine: crate::bench::Machine::probe(),
            model: Model::Auto,
            cases: vec![judged_refusal],
        };
        assert!(
            report.csv().contains(",none,false,false,"),
            "{}",
            report.csv()
        );
        let stopped = judged(refused, &case, &back, Err(FitError::TooFewPoints(3)));
        assert!(stopped.is_err_and(|e| e.starts_with("case 7:")));
    }
}

//! `bench ablation`: what each optional stage of the fit ([`crate::fit::ablation::Stage`])
//! gains and costs. Every case of the ground-truth suite is fitted once with every stage
//! and once without each stage in turn, the variants interleaved case by case (the
//! machine's drift falls on all of them alike); the report gives each variant's successes
//! (full clouds, single views) and fit time (median, 90th percentile, mean), and which
//! cases each stage wins or loses.

use super::synthetic::{Presentation, category, presented};
use super::{Machine, Report, Stats};
use crate::eval::{Backend, make_evaluator};
use crate::fit::ablation::{self, Stage};
use crate::fit::{FitOptions, fit};
use crate::suite::ground_truth::{compare, make_case};
use clap::ValueEnum;
use serde::Serialize;

/// One variant: the stage it leaves out (None: every stage).
#[derive(Clone, Debug, Serialize)]
pub struct Variant {
    pub without: Option<String>,
    pub full_successes: usize,
    pub partial_successes: usize,
    pub time_ms: Stats,
    /// cases right with every stage and wrong without this one
    pub lost: Vec<u64>,
    /// cases wrong with every stage and right without this one
    pub gained: Vec<u64>,
}

#[derive(Clone, Debug, Serialize)]
pub struct AblationReport {
    pub machine: Machine,
    pub backend: String,
    pub presentation: Presentation,
    pub seeds: Vec<u64>,
    pub cases: usize,
    pub variants: Vec<Variant>,
}

/// Runs `cases` cases from each first seed with every stage and without each of
/// `stages` (all of them when empty).
pub fn run(
    cases: usize,
    seeds: &[u64],
    presentation: Presentation,
    stages: &[Stage],
    backend: Backend,
    base: &FitOptions,
) -> Result<AblationReport, String> {
    if cases == 0 || seeds.is_empty() {
        return Err("--cases must be at least 1 and --seed needs a seed".into());
    }
    let stages: Vec<Stage> = if stages.is_empty() {
        Stage::value_variants().to_vec()
    } else {
        stages.to_vec()
    };
    let variants: Vec<Option<Stage>> = std::iter::once(None)
        .chain(stages.iter().copied().map(Some))
        .collect();
    let mut evaluator = make_evaluator(backend, base.stage2_points).map_err(|e| e.to_string())?;
    let total = (cases * seeds.len()) as u64;
    let bar = super::progress(total, "ablation");
    // per variant: (seed, partial, success, time)
    let mut outcomes: Vec<Vec<(u64, bool, bool, f64)>> = vec![Vec::new(); variants.len()];
    for (k, (seed, i)) in seeds
        .iter()
        .flat_map(|&s| (0..cases).map(move |i| (s, i)))
        .enumerate()
    {
        let (partial, noise, outliers) = category(i);
        let case_seed = seed + i as u64;
        let case = make_case(case_seed, partial, noise, outliers);
        let (points, viewpoint, back) = presented(&case, presentation);
        // the order turns from case to case
        for j in 0..variants.len() {
            let v = (j + k) % variants.len();
            let options = FitOptions {
                seed: case_seed,
                viewpoint,
                skip: variants[v].into_iter().collect(),
                ..base.clone()
            };
            // (a cloud the object screen refuses is a failed case, as in `bench synthetic`)
            let report = match fit(evaluator.as_mut(), &points, &options) {
                Ok(report) => report,
                Err(crate::fit::FitError::NoObject(_)) => {
                    outcomes[v].push((case_seed, partial, false, 0.0));
                    continue;
                }
                Err(e) => return Err(format!("case {case_seed}: {e}")),
            };
            let pose = back.compose(&report.fitted.1);
            let success = compare((&case.shape, &case.pose), (&report.fitted.0, &pose)).success();
            outcomes[v].push((case_seed, partial, success, report.timing_ms.total));
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    let all = outcomes[0].clone();
    let variants = variants
        .iter()
        .zip(&outcomes)
        .map(|(stage, out)| {
            let times: Vec<f64> = out.iter().map(|o| o.3).collect();
            let differ = |now: bool| {
                out.iter()
                    .zip(&all)
                    .filter(|(o, a)| o.2 == now && a.2 != now)
                    .map(|(o, _)| o.0)
                    .collect()
            };
            Variant {
                without: stage.map(ablation::name),
                full_successes: out.iter().filter(|o| !o.1 && o.2).count(),
                partial_successes: out.iter().filter(|o| o.1 && o.2).count(),
                time_ms: Stats::of(&times),
                lost: differ(false),
                gained: differ(true),
            }
        })
        .collect();
    Ok(AblationReport {
        machine: Machine::probe(),
        backend: evaluator.device_name(),
        presentation,
        seeds: seeds.to_vec(),
        cases,
        variants,
    })
}

impl Report for AblationReport {
    fn name(&self) -> &'static str {
        "ablation"
    }

    fn csv(&self) -> String {
        let mut s = String::from(
            "without,full_successes,partial_successes,time_median_ms,time_p90_ms,time_mean_ms,lost,gained\n",
        );
        for v in &self.variants {
            s += &format!(
                "{},{},{},{:.2},{:.2},{:.2},{},{}\n",
                v.without.as_deref().unwrap_or("nothing"),
                v.full_successes,
                v.partial_successes,
                v.time_ms.median,
                v.time_ms.p90,
                v.time_ms.mean,
                v.lost.len(),
                v.gained.len()
            );
        }
        s
    }

    fn markdown(&self) -> String {
        let n = self.cases * self.seeds.len();
        let mut md = format!(
            "# Ablation of the fit's optional stages\n\n{}Evaluator: {}. {} cases of the ground-truth suite (first seeds {:?}, {:?}), each fitted with every stage and without each stage in turn, interleaved. Full clouds and single views out of {} each.\n\n| without | full | single views | time median / p90 / mean [ms] | lost | gained |\n|---|---:|---:|---|---|---|\n",
            self.machine.markdown(),
            self.backend,
            n,
            self.seeds,
            self.presentation,
            n / 2
        );
        for v in &self.variants {
            md += &format!(
                "| {} | {} | {} | {:.0} / {:.0} / {:.0} | {:?} | {:?} |\n",
                v.without.as_deref().unwrap_or("(nothing)"),
                v.full_successes,
                v.partial_successes,
                v.time_ms.median,
                v.time_ms.p90,
                v.time_ms.mean,
                v.lost,
                v.gained
            );
        }
        md
    }
}

//! Grasps planned on fits, checked on the truth: for each case of the ground-truth suite
//! the fit's best grasp is checked on the true surface (both contacts within
//! [`CONTACT_TOLERANCE`] of it, its normals there inside the friction cone of the closing
//! line). `supertoroid bench grasps`.

use super::Report;
use super::synthetic::{category, wilson_interval};
use crate::eval::{Backend, make_evaluator};
use crate::fit::{FitOptions, Viewpoint, fit};
use crate::grasp::{GraspRequest, Gripper, check_on_surface, plan::plan};
use crate::suite::ground_truth::{compare, make_case};
use serde::Serialize;

/// How far a contact may lie from the true surface, metres.
pub const CONTACT_TOLERANCE: f64 = 0.002;
/// A gripper sized to each case's true object: the suite's rings (6-50 cm across,
/// sections 2-24 cm) are mostly beyond any one parallel gripper, and what is measured
/// here is whether a grasp planned on the fit holds on the truth. The opening is 2.5,
/// the fingers 1.5, the pads 0.5 and the fingers' thickness 0.25 times the largest of
/// a1, a2, a3 (a Franka Hand against a 4 cm section).
pub fn gripper_for(shape: &crate::model::Shape) -> Gripper {
    let largest = shape.a1.max(shape.a2).max(shape.a3);
    Gripper {
        max_opening: 2.5 * largest,
        min_opening: 0.0,
        finger_depth: 1.5 * largest,
        finger_width: 0.5 * largest,
        finger_thickness: Some(0.25 * largest),
    }
}
pub const FRICTION: f64 = 0.5;

#[derive(Clone, Debug, Serialize)]
pub struct GraspCase {
    pub seed: u64,
    pub partial: bool,
    pub noise: f64,
    pub outliers: f64,
    pub fit_success: bool,
    /// the planner found a grasp on the fit
    pub grasped: bool,
    /// the best grasp holds on the true surface
    pub valid_on_truth: bool,
    /// the farther contact's distance from the true surface (NaN without a grasp)
    pub contact_distance: f64,
    pub antipodal_on_truth: bool,
    pub plan_ms: f64,
    /// why the planner dropped candidates
    pub rejected: crate::grasp::Rejections,
}

#[derive(Clone, Debug, Serialize)]
pub struct GraspReport {
    pub machine: super::Machine,
    pub contact_tolerance: f64,
    pub cases: Vec<GraspCase>,
}

pub fn run(cases: usize, seed: u64, backend: Backend) -> Result<GraspReport, String> {
    if cases == 0 {
        return Err("--cases must be at least 1".into());
    }
    let options = FitOptions::default();
    let mut evaluator =
        make_evaluator(backend, options.stage2_points).map_err(|e| e.to_string())?;
    let bar = super::progress(cases as u64, "grasps on the suite");
    let mut out = Vec::with_capacity(cases);
    for i in 0..cases {
        let (partial, noise, outliers) = category(i);
        let case_seed = seed + i as u64;
        let case = make_case(case_seed, partial, noise, outliers);
        let fit_options = FitOptions {
            seed: case_seed,
            viewpoint: case.viewpoint.into(),
            ..options.clone()
        };
        let report = match fit(evaluator.as_mut(), &case.points, &fit_options) {
            Ok(report) => report,
            // a true object refused by the object screen: no fit, no grasp
            Err(crate::fit::FitError::NoObject(_)) => {
                out.push(GraspCase {
                    seed: case_seed,
                    partial,
                    noise,
                    outliers,
                    fit_success: false,
                    grasped: false,
                    valid_on_truth: false,
                    contact_distance: f64::NAN,
                    antipodal_on_truth: false,
                    plan_ms: f64::NAN,
                    rejected: Default::default(),
                });
                bar.inc(1);
                continue;
            }
            Err(e) => return Err(format!("case {case_seed}: {e}")),
        };
        let (shape, pose) = report.fitted;
        let errors = compare((&case.shape, &case.pose), (&shape, &pose));
        let started = std::time::Instant::now();
        let planned = plan(&GraspRequest {
            shape,
            pose,
            gripper: gripper_for(&case.shape),
            friction: FRICTION,
            plane: None,
            viewpoint: match fit_options.viewpoint {
                Viewpoint::At(v, _) => Some(v),
                _ => None,
            },
            max_grasps: 1,
        })?;
        let plan_ms = started.elapsed().as_secs_f64() * 1e3;
        let best = planned.grasps.first();
        let check = best.map(|g| check_on_surface(&case.shape, &case.pose, g, FRICTION));
        let distance = check.map_or(f64::NAN, |c| c.distance[0].max(c.distance[1]));
        let antipodal = check.is_some_and(|c| c.antipodal);
        out.push(GraspCase {
            seed: case_seed,
            partial,
            noise,
            outliers,
            fit_success: errors.success(),
            grasped: best.is_some(),
            valid_on_truth: antipodal && distance <= CONTACT_TOLERANCE,
            contact_distance: distance,
            antipodal_on_truth: antipodal,
            plan_ms,
            rejected: planned.rejected,
        });
        bar.inc(1);
    }
    bar.finish_and_clear();
    Ok(GraspReport {
        machine: super::Machine::probe(),
        contact_tolerance: CONTACT_TOLERANCE,
        cases: out,
    })
}

impl GraspReport {
    /// (valid, grasped) among the fits within the success rule matching `keep`.
    pub fn valid_among_right_fits(&self, keep: impl Fn(&GraspCase) -> bool) -> (usize, usize) {
        let right: Vec<&GraspCase> = self
            .cases
            .iter()
            .filter(|c| c.fit_success && c.grasped && keep(c))
            .collect();
        (
            right.iter().filter(|c| c.valid_on_truth).count(),
            right.len(),
        )
    }
}

impl Report for GraspReport {
    fn name(&self) -> &'static str {
        "grasps"
    }

    fn csv(&self) -> String {
        let mut s = String::from(
            "seed,partial,noise,outliers,fit_success,grasped,valid_on_truth,contact_distance,antipodal_on_truth,plan_ms\n",
        );
        for c in &self.cases {
            s += &format!(
                "{},{},{},{},{},{},{},{},{},{:.3}\n",
                c.seed,
                c.partial,
                c.noise,
                c.outliers,
                c.fit_success,
                c.grasped,
                c.valid_on_truth,
                c.contact_distance,
                c.antipodal_on_truth,
                c.plan_ms
            );
        }
        s
    }

    fn markdown(&self) -> String {
        let mut md = format!(
            "# Grasps on fits, checked on the truth\n\n{}\n\nA gripper sized to each object (opening 2.5, finger depth 1.5, pad width 0.5, finger thickness 0.25 times the largest of a1, a2, a3); friction {FRICTION}; a grasp holds on the truth when both contacts lie within {} m of the true surface and its normals there are inside the friction cone.\n\n| cases | fits within the rule | with a grasp | best grasp holds on the truth | 95% interval |\n|---|---|---|---|---|\n",
            self.machine.markdown(),
            self.contact_tolerance
        );
        let rows: [(&str, Box<dyn Fn(&GraspCase) -> bool>); 5] = [
            ("all", Box::new(|_| true)),
            (
                "full, noise-free",
                Box::new(|c| !c.partial && c.noise == 0.0),
            ),
            ("full, noisy", Box::new(|c| !c.partial && c.noise > 0.0)),
            (
                "view, noise-free",
                Box::new(|c| c.partial && c.noise == 0.0),
            ),
            ("view, noisy", Box::new(|c| c.partial && c.noise > 0.0)),
        ];
        for (label, keep) in rows {
            let n = self.cases.iter().filter(|c| keep(c)).count();
            let right = self
                .cases
                .iter()
                .filter(|c| keep(c) && c.fit_success)
                .count();
            let (valid, grasped) = self.valid_among_right_fits(&keep);
            let [lo, hi] = wilson_interval(valid, grasped);
            md += &format!(
                "| {label}: {n} | {right} | {grasped} | {valid} ({:.1}%) | {:.1}-{:.1}% |\n",
                100.0 * valid as f64 / grasped.max(1) as f64,
                100.0 * lo,
                100.0 * hi
            );
        }
        let mut times: Vec<f64> = self
            .cases
            .iter()
            .map(|c| c.plan_ms)
            .filter(|t| t.is_finite())
            .collect();
        times.sort_by(f64::total_cmp);
        if !times.is_empty() {
            md += &format!(
                "\nPlanning time per object: median {:.2} ms, p95 {:.2} ms (`cargo bench --bench grasp` for the benchmark).\n",
                times[times.len() / 2],
                times[(times.len() * 95 / 100).min(times.len() - 1)]
            );
        }
        md
    }
}

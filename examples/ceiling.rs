//! How much of the ground-truth suite's failure is the estimator and how much the search:
//! for each case, the default fit, and a fit started at the true parameters and run to
//! convergence on all of the case's points (same Huber loss). A case that fails even from
//! the truth fails because the cost's minimum is away from the truth, not because the
//! starts missed it.
//!
//! `cargo run --release --example ceiling -- [CASES] [full|partial]`

use supertoroid::bench::synthetic::{DEFAULT_SEED, category};
use supertoroid::eval::{CpuEvaluator, Evaluator, Loss, Normalization};
use supertoroid::fit::{FitOptions, fit};
use supertoroid::solve::{SolverOptions, solve};
use supertoroid::suite::ground_truth::{compare, make_case};

fn main() {
    let cases: usize = std::env::args()
        .nth(1)
        .map(|s| s.parse().expect("CASES is a number"))
        .unwrap_or(180);
    let only = std::env::args().nth(2).map(|s| s == "partial");
    let options = FitOptions::default();
    let mut evaluator = CpuEvaluator::new();
    let (mut total, mut fitted_ok, mut truth_ok) = (0, 0, 0);
    for i in 0..cases {
        let (partial, noise, outliers) = category(i);
        if only.is_some_and(|p| p != partial) {
            continue;
        }
        // the seeds of `supertoroid bench synthetic` with its default --seed
        let seed = DEFAULT_SEED + i as u64;
        let case = make_case(seed, partial, noise, outliers);
        let report = fit(
            &mut evaluator,
            &case.points,
            &FitOptions {
                seed,
                ..options.clone()
            },
        )
        .expect("suite cases fit");
        let e_fit = compare(
            (&case.shape, &case.pose),
            (&report.fitted.0, &report.fitted.1),
        );

        let norm = Normalization::of(&case.points);
        evaluator.set_points(&norm.points(&case.points)).unwrap();
        let start = norm.candidate(&case.shape, &case.pose);
        let solver = SolverOptions {
            loss: Loss::Huber(options.huber),
            max_iterations: 60,
            ..Default::default()
        };
        let polished = solve(&mut evaluator, &[start], &options.bounds(), &solver).unwrap();
        let (shape, pose) = norm.to_world(&polished[0].candidate);
        let e_truth = compare((&case.shape, &case.pose), (&shape, &pose));

        total += 1;
        fitted_ok += e_fit.success() as usize;
        truth_ok += e_truth.success() as usize;
        if !e_fit.success() || !e_truth.success() {
            println!(
                "case {i} ({} noise {noise} outliers {outliers}): fit {} (sizes {:.3} a4 {:.3} eps {:.3} axis {:.1} deg), from the truth {} (sizes {:.3} a4 {:.3} eps {:.3})",
                if partial { "partial" } else { "full" },
                if e_fit.success() { "ok" } else { "fails" },
                e_fit.sizes,
                e_fit.a4,
                e_fit.eps,
                e_fit.axis_degrees,
                if e_truth.success() { "ok" } else { "fails" },
                e_truth.sizes,
                e_truth.a4,
                e_truth.eps,
            );
        }
    }
    println!(
        "{total} cases: the fit succeeds in {fitted_ok}, a fit started at the truth in {truth_ok}"
    );
}

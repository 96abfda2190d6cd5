//! The broadened single-view suite (`supertoroid::suite::broad`: tall rolls, thin washers,
//! oval rings and the suite's own shapes through a D435-like sensor), fitted as users post
//! the clouds: in the camera's frame, no options.
//!
//! Success by the suite's rule, per family and in all, with the fit's median and p95
//! time, and how many wrong and right fits carry a warning. For each miss it also says
//! whether the fit's own estimator started at the truth (`ground_truth::model_from_truth`)
//! misses too, and how much likelier the truth's basin is than the fit's under the fit's
//! own noise model (`ground_truth::basin_gap`): a miss in a less likely basin than the
//! truth's is the search's, one at least as likely as the truth's is the estimator's, and
//! one without a hole is unscored (the grid model needs one).
//!
//! `cargo run --release --example broad_views -- [CASES] [FIRST_SEED]`; with
//! `CASES_CSV=FILE` each case's verdict, warnings and the numbers they read go to FILE.

use supertoroid::eval::CpuEvaluator;
use supertoroid::fit::{FitOptions, fit, scatter};
use supertoroid::suite::broad::{FAMILIES, view};
use supertoroid::suite::ground_truth::{TruthPoints, basin_gap, compare, model_from_truth};

/// A gap in mean log-likelihood per point above which the truth's basin counts as the
/// likelier (the refinements stop at steps of 1e-4).
const BASIN_GAP: f64 = 1e-3;

fn main() {
    let mut args = std::env::args().skip(1);
    let cases: u64 = args.next().map_or(80, |a| a.parse().expect("CASES"));
    let first: u64 = args
        .next()
        .map_or(2_000_000, |a| a.parse().expect("FIRST_SEED"));
    let mut evaluator = CpuEvaluator::new();
    let mut right = [0usize; 4];
    let mut counts = [0usize; 4];
    let mut refused = 0;
    let mut beyond_estimator = 0;
    // misses in a basin less likely than the truth's, at least as likely, and unscored
    let mut by_basin = [0usize; 3];
    // [wrong, right] fits, and of them those with a warning
    let mut judged = [0usize; 2];
    let mut warned = [0usize; 2];
    // per family: [wrong, right] fits with a warning
    let mut warned_by_family = [[0usize; 2]; 4];
    let mut times = Vec::new();
    let mut rows = String::from(
        "seed,family,success,warned,uncertainty,median_over_size,median_over_scatter,warnings\n",
    );
    for seed in first..first + cases {
        let family = (seed % 4) as usize;
        let case = view(seed);
        counts[family] += 1;
        let options = FitOptions {
            seed,
            ..Default::default()
        };
        let report = match fit(&mut evaluator, &case.points, &options) {
            Ok(report) => report,
            Err(e) => {
                refused += 1;
                println!("  seed {seed} ({}): {e}", FAMILIES[family]);
                continue;
            }
        };
        times.push(report.timing_ms.total);
        let (shape, pose) = &report.fitted;
        let errors = compare((&case.shape, &case.pose), (shape, pose));
        let success = errors.success();
        judged[usize::from(success)] += 1;
        warned[usize::from(success)] += usize::from(!report.warnings.is_empty());
        warned_by_family[family][usize::from(success)] += usize::from(!report.warnings.is_empty());
        let median = report.quality.median_distance;
        rows += &format!(
            "{seed},{},{success},{},{},{},{},{}\n",
            FAMILIES[family],
            !report.warnings.is_empty(),
            report
                .quality
                .standard_errors
                .as_ref()
                .map_or(f64::NAN, |e| e.share_of_tolerance()),
            median / shape.size(),
            scatter::local_scatter(&case.points).map_or(f64::NAN, |s| median / s),
            report
                .warnings
                .iter()
                .map(|w| w.split(':').next().unwrap_or_default())
                .collect::<Vec<_>>()
                .join(";")
        );
        if success {
            right[family] += 1;
            continue;
        }
        let estimator_misses =
            !model_from_truth(&case, TruthPoints::All, true, &options).is_some_and(|e| e.success());
        beyond_estimator += usize::from(estimator_misses);
        let gap = basin_gap(&case, (shape, pose), report.quality.noise_sigma, &options);
        by_basin[match gap {
            Some(g) if g > BASIN_GAP => 0,
            Some(_) => 1,
            None => 2,
        }] += 1;
        println!(
            "  seed {seed} ({}) missed{}: truth {:.4?}, fit {:.4?}; {errors:.3?}; truth's basin likelier by {} nats a point; estimator {}; warnings {:?}",
            FAMILIES[family],
            if estimator_misses {
                " (so does the estimator from the truth)"
            } else {
                ""
            },
            case.shape.to_array(),
            shape.to_array(),
            gap.map_or("(unscored)".into(), |g| format!("{g:.4}")),
            report.search.as_ref().map_or("-", |s| s.estimator.as_str()),
            report.warnings
        );
    }
    if let Ok(path) = std::env::var("CASES_CSV") {
        std::fs::write(&path, rows).expect("CASES_CSV is writable");
    }
    times.sort_by(f64::total_cmp);
    println!(
        "{cases} views (seeds {first}..) through a D435-like sensor, no options, CPU evaluator:"
    );
    for (k, name) in FAMILIES.iter().enumerate() {
        let [wrong_warned, right_warned] = warned_by_family[k];
        println!(
            "  {name:13} {} of {} (warned: {wrong_warned} of the wrong fits, {right_warned} of the right)",
            right[k], counts[k]
        );
    }
    println!(
        "  all           {} of {cases} ({refused} refused as no object); fit median {:.0} ms, p95 {:.0} ms",
        right.iter().sum::<usize>(),
        times[times.len() / 2],
        times[(times.len() * 95 / 100).min(times.len() - 1)]
    );
    println!(
        "  of the misses, {beyond_estimator} are missed by the estimator started at the truth too"
    );
    println!(
        "  of the misses, {} lie in a basin less likely than the truth's (the search's), {} in one at least as likely (the estimator's), {} lost their hole (unscored: the grid model needs one)",
        by_basin[0], by_basin[1], by_basin[2]
    );
    println!(
        "  warned: {} of {} wrong fits, {} of {} right ones",
        warned[0], judged[0], warned[1], judged[1]
    );
}

//! The noise model's own ceiling on the ground-truth suite: each noisy case refined by
//! the model (`fit::likelihood::refine`) from its true parameters and true noise, on all
//! of its points or on the 1000-point sample the fit uses, and judged by the suite's
//! success rule. The noise-free cases count as recovered (the model never runs on them).
//! A case that fails here fails because the model's optimum near the truth is out of
//! tolerance, whatever the search.
//!
//! With `fine` it refines on the grid the fit's last polish uses
//! (`likelihood::refine_finely`, twice as fine along the section), so a case that fails
//! there fails the pipeline's own estimator whatever the search. SEED may be a
//! comma-separated list of first seeds (sets of 180 each).
//!
//! `cargo run --release --example model_ceiling -- [SEED[,SEED...]] [all|sample] [coarse|fine]`

use supertoroid::bench::synthetic::{DEFAULT_SEED, category};
use supertoroid::fit::FitOptions;
use supertoroid::suite::ground_truth::{TruthPoints, make_case, recovered_from_truth};

fn main() {
    let seeds: Vec<u64> = std::env::args()
        .nth(1)
        .map(|s| {
            s.split(',')
                .map(|x| x.parse().expect("SEED is a number"))
                .collect()
        })
        .unwrap_or(vec![DEFAULT_SEED]);
    let on_sample = std::env::args().nth(2).is_some_and(|s| s == "sample");
    let finely = std::env::args().nth(3).is_some_and(|s| s == "fine");
    let (mut all_recovered, mut all_cases) = (0, 0);
    for &seed in &seeds {
        let recovered = set_ceiling(seed, on_sample, finely);
        all_recovered += recovered;
        all_cases += 180;
    }
    if seeds.len() > 1 {
        println!("all sets: {all_recovered} of {all_cases}");
    }
}

/// The model's ceiling on one set of 180 cases from `seed`: prints and returns how many
/// it recovers.
fn set_ceiling(seed: u64, on_sample: bool, finely: bool) -> usize {
    let options = FitOptions::default();
    let (mut recovered, mut failed) = (0, Vec::new());
    for i in 0..180 {
        let case_seed = seed + i as u64;
        let (partial, noise, outliers) = category(i);
        let case = make_case(case_seed, partial, noise, outliers);
        let points = if on_sample {
            TruthPoints::Stage2Sample(case_seed)
        } else {
            TruthPoints::All
        };
        if recovered_from_truth(&case, points, finely, &options) {
            recovered += 1;
        } else {
            failed.push(case_seed);
        }
    }
    println!(
        "seeds {seed}..{}: the model from the truth on {} ({} grid) recovers {recovered} of 180; fails {failed:?}",
        seed + 179,
        if on_sample {
            "the stage-2 sample"
        } else {
            "all points"
        },
        if finely { "fine" } else { "coarse" },
    );
    recovered
}

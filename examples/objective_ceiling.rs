//! The two noise models' ceilings: each noisy suite case's stage-2 sample refined from the
//! true parameters by the grid model (`fit::likelihood`, the default pipeline's polish)
//! and by the objective of `method=search` (`fit::objective`); how many land within the
//! suite's tolerances, and their times. With PARTIAL set, single views only; with ALL set,
//! on all of each cloud's points rather than the stage-2 sample.
//!
//! `ALL=1 PARTIAL=1 cargo run --release --example objective_ceiling -- [FIRST_SEED] [CASES]`
use std::time::Instant;
use supertoroid::bench::synthetic::category;
use supertoroid::eval::Normalization;
use supertoroid::fit::{FitOptions, LIKELIHOOD_OUTLIER_WEIGHT, likelihood, objective};
use supertoroid::suite::ground_truth::{compare, make_case};
use supertoroid::synth;

fn main() {
    let seed: u64 = std::env::args()
        .nth(1)
        .map_or(300000, |s| s.parse().unwrap());
    let count: usize = std::env::args().nth(2).map_or(180, |s| s.parse().unwrap());
    let options = FitOptions::default();
    let (mut ok_old, mut ok_new, mut n) = (0, 0, 0);
    let (mut t_old, mut t_new) = (Vec::new(), Vec::new());
    let mut its: Vec<f64> = Vec::new();
    for i in 0..count {
        let case_seed = seed + i as u64;
        let (partial, noise, outliers) = category(i);
        if noise == 0.0 || (std::env::var("PARTIAL").is_ok() && !partial) {
            continue;
        }
        let case = make_case(case_seed, partial, noise, outliers);
        let norm = Normalization::of(&case.points);
        let all = norm.points(&case.points);
        let mut rng = synth::rng(case_seed);
        let _s1 = synth::subsample(&all, 150, &mut rng);
        let sample = if std::env::var("ALL").is_ok() {
            all.clone()
        } else {
            synth::subsample(&all, 1000, &mut rng)
        };
        let truth = norm.candidate(&case.shape, &case.pose);
        let sigma = case.noise * case.shape.size() / norm.scale;
        let viewpoint = case.viewpoint.map(|v| norm.point(v));
        let limits = likelihood::Limits {
            bounds: options.bounds(),
            fixed_shape: [false; 6],
            fixed_axis: false,
            deadline: None,
        };
        let t = Instant::now();
        let old = likelihood::refine(
            &sample,
            &truth,
            sigma,
            LIKELIHOOD_OUTLIER_WEIGHT,
            viewpoint.map(supertoroid::fit::Sight::at),
            &limits,
            60,
        );
        t_old.push(t.elapsed().as_secs_f64() * 1e3);
        let t = Instant::now();
        let sensor =
            viewpoint.map(|v| objective::Sensor::new(&sample, supertoroid::fit::Sight::at(v)));
        let volume = likelihood::outlier_volume(&sample, sigma);
        let data = objective::Data {
            points: &sample,
            outlier_weight: LIKELIHOOD_OUTLIER_WEIGHT,
            outlier_density: LIKELIHOOD_OUTLIER_WEIGHT / volume,
            sensor: sensor.as_ref(),
            device: None,
        };
        let olimits = objective::Limits {
            bounds: options.bounds(),
            fixed_shape: [false; 6],
            fixed_axis: false,
            deadline: None,
        };
        let new = objective::refine(&data, &truth, sigma, &olimits, 60);
        t_new.push(t.elapsed().as_secs_f64() * 1e3);
        n += 1;
        its.push(new.iterations as f64);
        let judge = |c: &supertoroid::eval::Candidate| {
            let (s, p) = norm.to_world(c);
            compare((&case.shape, &case.pose), (&s, &p))
        };
        let eo = old.map(|r| judge(&r.candidate));
        let en = judge(&new.candidate);
        let so = eo.is_some_and(|e| e.success());
        ok_old += so as usize;
        ok_new += en.success() as usize;
        if so != en.success() {
            println!(
                "{case_seed} partial {partial} noise {noise} out {outliers}: old {:?}\n   new {:?} it {} sigma {:.3}",
                eo.map(|e| (e.success(), e.sizes, e.a4, e.eps, e.axis_degrees)),
                (en.success(), en.sizes, en.a4, en.eps, en.axis_degrees),
                new.iterations,
                new.sigma / sigma
            );
        }
    }
    let med = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        (v[v.len() / 2], v[v.len() * 9 / 10])
    };
    println!("iterations median {:?}", med(&mut its));
    println!(
        "noisy cases {n}: grid model {ok_old} ({:?} ms), new objective {ok_new} ({:?} ms)",
        med(&mut t_old),
        med(&mut t_new)
    );
}

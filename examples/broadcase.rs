//! Development: fit views of the broadened suite (`bench broad`) as users post them and
//! print truth, fit, errors, timing and what the search kept; with SKIP=stage,... set,
//! without those optional stages.
use supertoroid::eval::{CpuEvaluator, Normalization};
use supertoroid::fit::{FitOptions, LIKELIHOOD_OUTLIER_WEIGHT, fit, likelihood, objective};
use supertoroid::suite::broad::view;
use supertoroid::suite::ground_truth::compare;
use supertoroid::synth;

fn main() {
    for seed in std::env::args().skip(1).map(|s| s.parse::<u64>().unwrap()) {
        let case = view(seed);
        // SKIP=stage,...: leave those optional stages out (as `bench broad --skip`)
        let skip = std::env::var("SKIP").map_or_else(
            |_| Vec::new(),
            |s| {
                use clap::ValueEnum;
                s.split(',')
                    .map(|n| supertoroid::fit::ablation::Stage::from_str(n, true).unwrap())
                    .collect()
            },
        );
        let options = FitOptions {
            seed,
            skip,
            ..Default::default()
        };
        let r = fit(&mut CpuEvaluator::new(), &case.points, &options).unwrap();
        let e = compare((&case.shape, &case.pose), (&r.fitted.0, &r.fitted.1));
        let axis = case.pose.rotation * glam::DVec3::Z;
        let sight = case.pose.translation.normalize();
        println!(
            "{seed} noise {:.3} points {}: success {} c {:.3} ax {:.2} sz {:.3} a4 {:.3} eps {:.3}; axis to sight {:.0} deg\n  truth {:.4?}\n  fit   {:.4?}\n  {:.0} ms {:?}\n  warnings {:?}\n  search {:?}",
            case.noise,
            case.points.len(),
            e.success(),
            e.centre,
            e.axis_degrees,
            e.sizes,
            e.a4,
            e.eps,
            axis.dot(sight).abs().acos().to_degrees(),
            case.shape.to_array(),
            r.fitted.0.to_array(),
            r.timing_ms.total,
            r.timing_ms.stages,
            r.warnings,
            r.search
        );

        if std::env::var("TRUTH").is_ok() {
            let norm = Normalization::of(&case.points);
            let all = norm.points(&case.points);
            let mut rng = synth::rng(seed);
            let sample = synth::subsample(&all, 1000, &mut rng);
            let v = norm.point(glam::DVec3::ZERO);
            let sensor = objective::Sensor::new(&sample, supertoroid::fit::Sight::at(v));
            let data = objective::Data {
                points: &sample,
                outlier_weight: LIKELIHOOD_OUTLIER_WEIGHT,
                outlier_density: LIKELIHOOD_OUTLIER_WEIGHT
                    / likelihood::outlier_volume(&sample, 2e-3),
                sensor: Some(&sensor),
            };
            let limits = objective::Limits {
                bounds: options.bounds(),
                fixed_shape: [false; 6],
                fixed_axis: false,
                deadline: None,
            };
            let sigma = (case.noise * case.shape.size() / norm.scale).max(2e-3);
            let truth = norm.candidate(&case.shape, &case.pose);
            let fitted = norm.candidate(&r.fitted.0, &r.fitted.1);
            let fs = (r.quality.noise_sigma / norm.scale).max(2e-3);
            let judge = |c: &supertoroid::eval::Candidate| {
                let (s, p) = norm.to_world(c);
                (
                    compare((&case.shape, &case.pose), (&s, &p)).success(),
                    s.to_array(),
                )
            };
            for (name, start, s0) in [("truth", truth, sigma), ("fit", fitted, fs)] {
                for its in [5usize, 30, 200] {
                    let t = objective::refine(&data, &start, s0, &limits, its);
                    let (ok, sh) = judge(&t.candidate);
                    println!(
                        "  quad from {name} {its}: obj {:.5} iters {} success {ok} shape {:.4?}",
                        t.objective, t.iterations, sh
                    );
                }
            }
        }
    }
}

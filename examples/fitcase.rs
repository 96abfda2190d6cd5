//! Development: fit suite cases as the bench presents them (camera frame, no options; or
//! with GIVEN set, the camera's position given) and print truth, fit, errors and timing;
//! with PAPER set, by `Method::Paper`; with TRUTH set, the likelihood of the fit against the truth refined;
//! with AXIS set, the true hole axis in the cloud's frame (to set beside the search's candidates).
//! with SKIP=stage,... set, without those optional stages (as `bench synthetic --skip`);
//! with BROAD set, the seeds are views of the broadened suite (`bench broad`); with GPU set,
//! fitted on the GPU evaluator.
use supertoroid::bench::synthetic::{Presentation, category, presented};
use supertoroid::eval::{
    AdapterChoice, CpuEvaluator, Evaluator, GpuContext, GpuEvaluator, Normalization,
};
use supertoroid::fit::{FitOptions, LIKELIHOOD_OUTLIER_WEIGHT, fit, likelihood, objective};
use supertoroid::model::Pose;
use supertoroid::suite::ground_truth::{compare, make_case};
use supertoroid::synth;

fn main() {
    let presentation = if std::env::var("GIVEN").is_ok() {
        Presentation::Viewpoint
    } else {
        Presentation::Camera
    };
    for seed in std::env::args().skip(1).map(|s| s.parse::<u64>().unwrap()) {
        // BROAD: a view of the broadened suite, already in its camera's frame
        let (case, (points, viewpoint, back)) = if std::env::var("BROAD").is_ok() {
            let case = supertoroid::suite::broad::view(seed);
            let points = case.points.clone();
            (case, (points, Default::default(), Pose::default()))
        } else {
            let (partial, noise, outliers) = category((seed % 1000) as usize % 180);
            let case = make_case(seed, partial, noise, outliers);
            let presented = presented(&case, presentation);
            (case, presented)
        };
        let (partial, noise, outliers) = (case.partial, case.noise, case.outlier_fraction);
        let method = if std::env::var("PAPER").is_ok() {
            supertoroid::fit::Method::Paper
        } else {
            Default::default()
        };
        // SKIP=stage,...: leave those optional stages out (as `bench synthetic --skip`)
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
            viewpoint,
            method,
            skip,
            ..Default::default()
        };
        // GPU=1: the GPU evaluator (its least squares and the search's likelihood on the
        // adapter) instead of the CPU's
        let mut evaluator: Box<dyn Evaluator> = if std::env::var("GPU").is_ok() {
            Box::new(GpuEvaluator::new(
                GpuContext::shared(&AdapterChoice::from_env()).expect("a GPU adapter"),
            ))
        } else {
            Box::new(CpuEvaluator::new())
        };
        let r = fit(evaluator.as_mut(), &points, &options).unwrap();
        let f = r.fitted.1;
        let pose = Pose::new(back.rotation * f.rotation, back.to_world(f.translation));
        let e = compare((&case.shape, &case.pose), (&r.fitted.0, &pose));
        println!(
            "{seed} {} noise {noise} out {outliers}: success {} c {:.3} ax {:.2} sz {:.3} a4 {:.3} eps {:.3}\n  truth {:.4?}\n  fit   {:.4?}\n  viewpoint {:?}; {:.0} ms {:?} warnings {}; points {:?}; search {:?}",
            if partial { "partial" } else { "full" },
            e.success(),
            e.centre,
            e.axis_degrees,
            e.sizes,
            e.a4,
            e.eps,
            case.shape.to_array(),
            r.fitted.0.to_array(),
            r.viewpoint.source,
            r.timing_ms.total,
            r.timing_ms,
            r.warnings.len(),
            r.points,
            r.search
        );
        if std::env::var("AXIS").is_ok() {
            println!(
                "  truth axis in the cloud's frame {:.2?}",
                back.rotation.inverse() * (case.pose.rotation * glam::DVec3::Z)
            );
        }
        if std::env::var("QUALITY").is_ok() {
            println!(
                "  median distance / size {:.2e}, noise sigma / size {:.2e}, scatter {:?}",
                r.quality.median_distance / r.fitted.0.size(),
                r.quality.noise_sigma / r.fitted.0.size(),
                supertoroid::fit::scatter::local_scatter(&points).map(|s| s / r.fitted.0.size())
            );
        }
        if std::env::var("TRUTH").is_ok() {
            // in the suite's frame
            let norm = Normalization::of(&case.points);
            let all = norm.points(&case.points);
            let mut rng = synth::rng(seed);
            let _ = synth::subsample(&all, 150, &mut rng);
            let sample = synth::subsample(&all, 1000, &mut rng);
            let v = if partial {
                case.viewpoint.map(|v| norm.point(v))
            } else {
                None
            };
            let sensor = v.map(|v| objective::Sensor::new(&sample, supertoroid::fit::Sight::at(v)));
            let data = objective::Data {
                points: &sample,
                outlier_weight: LIKELIHOOD_OUTLIER_WEIGHT,
                outlier_density: LIKELIHOOD_OUTLIER_WEIGHT
                    / likelihood::outlier_volume(&sample, 2e-3),
                sensor: sensor.as_ref(),
                device: None,
            };
            let limits = objective::Limits {
                bounds: options.bounds(),
                fixed_shape: [false; 6],
                fixed_axis: false,
                deadline: None,
            };
            let sigma = (case.noise * case.shape.size() / norm.scale).max(2e-3);
            let truth = norm.candidate(&case.shape, &case.pose);
            let t = objective::refine(&data, &truth, sigma, &limits, 60);
            let fitted = norm.candidate(&r.fitted.0, &pose);
            let fs = (r.quality.noise_sigma / norm.scale).max(2e-3);
            let fr = objective::refine(&data, &fitted, fs, &limits, 60);
            let (ts, tp) = norm.to_world(&t.candidate);
            let te = compare((&case.shape, &case.pose), (&ts, &tp));
            println!(
                "  truth-refined {:.4} (success {}) fit-refined {:.4} at fit {:.4}",
                t.objective,
                te.success(),
                fr.objective,
                objective::value(&data, &fitted, fs)
            );
            for vv in [v, None] {
                let sensor2 =
                    vv.map(|v| objective::Sensor::new(&sample, supertoroid::fit::Sight::at(v)));
                let d2 = objective::Data {
                    sensor: sensor2.as_ref(),
                    device: None,
                    ..data
                };
                println!(
                    "  at truth, sensor {}: new {:.4} old {:?}",
                    vv.is_some(),
                    objective::value(&d2, &truth, sigma),
                    likelihood::objective(
                        &sample,
                        &truth,
                        sigma,
                        LIKELIHOOD_OUTLIER_WEIGHT,
                        vv.map(supertoroid::fit::Sight::at)
                    )
                );
            }
            let ol = likelihood::Limits {
                bounds: options.bounds(),
                fixed_shape: [false; 6],
                fixed_axis: false,
                deadline: None,
            };
            let e = |c: &supertoroid::eval::Candidate| {
                let (s, p) = norm.to_world(c);
                compare((&case.shape, &case.pose), (&s, &p))
            };
            let fre = e(&fr.candidate);
            println!(
                "  new model from fit: success {} eps {:.3} sz {:.3}",
                fre.success(),
                fre.eps,
                fre.sizes
            );
            for (name, start, s0) in [("truth", truth, sigma), ("fit", fitted, fs)] {
                if let Some(o) = likelihood::refine_finely(
                    &sample,
                    &start,
                    s0,
                    LIKELIHOOD_OUTLIER_WEIGHT,
                    v.map(supertoroid::fit::Sight::at),
                    &ol,
                    60,
                ) {
                    let oe = e(&o.candidate);
                    println!(
                        "  old model from {name}: success {} eps {:.3} sz {:.3} obj {:.4}",
                        oe.success(),
                        oe.eps,
                        oe.sizes,
                        o.objective
                    );
                }
            }
        }
    }
}

//! Single views drawn otherwise than the ground-truth suite draws them, fitted as a user
//! posts them: a camera at the origin of the cloud's frame looking at the object, 1000-5000
//! points, isotropic noise of 1% of the size, and on every other cloud 5% outliers over the
//! axis-aligned box of the whole cloud (the suite spreads them over the object's own box).
//! Each cloud is fitted with no options (the viewpoint found), as a view from nowhere, and
//! with the camera's position given; successes by the suite's rule and median fit times.
//!
//! `cargo run --release --example independent_views -- [CASES] [FIRST_SEED] [METHOD]`
//! (METHOD: default or paper).

use clap::ValueEnum;
use glam::DVec3;
use rand::Rng;
use supertoroid::eval::CpuEvaluator;
use supertoroid::fit::{FitOptions, Method, Viewpoint, fit};
use supertoroid::model::{Pose, Shape};
use supertoroid::suite::ground_truth::compare;
use supertoroid::synth::{self, Intrinsics};

/// One view in its camera's frame, with the truth in that frame.
fn view(seed: u64) -> (Vec<DVec3>, Shape, Pose) {
    let mut rng = synth::rng(seed);
    // the suite's shapes, drawn otherwise
    let (shape, axis) = supertoroid::suite::ground_truth::random_shape(&mut rng);
    let intrinsics = Intrinsics::REALSENSE_640X480;
    // far enough for the object to fill about half the image's height
    let distance = intrinsics.fy * 2.0 * shape.size() / (0.5 * intrinsics.height as f64);
    let (pose, camera) =
        supertoroid::suite::broad::in_front_of_camera(&mut rng, axis, distance, intrinsics);
    let rendered = synth::render_view(&shape, &pose, &camera, 0.0001).expect("a valid view");
    let count = rng.random_range(1000..=5000);
    let mut points: Vec<DVec3> = synth::subsample(&rendered.points, count, &mut rng)
        .into_iter()
        .map(|p| camera.pose.to_canonical(p))
        .collect();
    synth::add_noise(&mut points, 0.01 * shape.size(), &mut rng);
    if seed % 2 == 1 {
        let (lo, hi) = points.iter().fold(
            (DVec3::splat(f64::MAX), DVec3::splat(f64::MIN)),
            |(lo, hi), p| (lo.min(*p), hi.max(*p)),
        );
        let extra = points.len() * 5 / 95;
        for _ in 0..extra {
            points.push(DVec3::new(
                rng.random_range(lo.x..=hi.x),
                rng.random_range(lo.y..=hi.y),
                rng.random_range(lo.z..=hi.z),
            ));
        }
    }
    let in_camera = Pose::new(
        camera.pose.rotation.inverse() * pose.rotation,
        camera.pose.to_canonical(pose.translation),
    );
    (points, shape, in_camera)
}

fn main() {
    let mut args = std::env::args().skip(1);
    let cases: u64 = args.next().map_or(40, |a| a.parse().expect("CASES"));
    let first: u64 = args
        .next()
        .map_or(900_000, |a| a.parse().expect("FIRST_SEED"));
    let method = args.next().map_or(Method::Default, |a| {
        Method::from_str(&a, true).expect("METHOD: default or paper")
    });
    let mut evaluator = CpuEvaluator::new();
    let variants = [
        ("no options", Viewpoint::Auto),
        ("viewpoint none", Viewpoint::None),
        ("camera given", Viewpoint::given(DVec3::ZERO)),
    ];
    let mut right = [0usize; 3];
    let mut times: [Vec<f64>; 3] = Default::default();
    for seed in first..first + cases {
        let (points, shape, pose) = view(seed);
        for (k, (_, viewpoint)) in variants.iter().enumerate() {
            let options = FitOptions {
                seed,
                viewpoint: *viewpoint,
                method,
                ..Default::default()
            };
            let report = fit(&mut evaluator, &points, &options).expect("a fit");
            let success = compare((&shape, &pose), (&report.fitted.0, &report.fitted.1)).success();
            if !success && k != 1 {
                println!(
                    "  seed {seed}: {} missed: truth {:.4?}, fit {:.4?}",
                    variants[k].0,
                    shape.to_array(),
                    report.fitted.0.to_array()
                );
            }
            right[k] += success as usize;
            times[k].push(report.timing_ms.total);
        }
    }
    println!("{cases} independent single views (seeds {first}..), {method:?}, CPU evaluator:");
    for (k, (name, _)) in variants.iter().enumerate() {
        let t = &mut times[k];
        t.sort_by(f64::total_cmp);
        println!(
            "  {name:15} {:3} of {cases} within tolerance, fit median {:.0} ms, p95 {:.0} ms",
            right[k],
            t[t.len() / 2],
            t[(t.len() * 95 / 100).min(t.len() - 1)]
        );
    }
}

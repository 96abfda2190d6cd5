//! The broadened single-view suite: shapes users have beyond the ground-truth suite's
//! ranges, seen through a D435-like sensor, fitted as users post them (the cloud in its
//! camera's frame, no options).
//!
//! - Shape families, by seed mod 4: the suite's ranges; tall rolls and tubes (a3 from
//!   one to three times a1·a4, the hole along the longest extent); thin washers (a3
//!   4-12 mm); oval rings (a1/a2 from 1.3 to 2).
//! - The sensor (`synth::with_sensor_noise`): depth noise along the ray of 1 mm at 0.5 m
//!   growing with the range squared, 1 mm quantisation, flying pixels at 30% of the
//!   silhouette edges; the object 0.4-0.9 m from the camera (farther where it would not
//!   fit in the image).
//! - 1000-5000 of the view's points; on every other cloud 5% outliers over the scene's
//!   box (twice the object's extent about it, towards the camera as well).
//!
//! Success by the suite's rule (`suite::ground_truth::compare`); per family and in all,
//! with the median fit time.
//!
//! `cargo run --release --example broad_views -- [CASES] [FIRST_SEED]`

#[path = "shared/placement.rs"]
mod placement;

use glam::DVec3;
use rand::Rng;
use supertoroid::eval::CpuEvaluator;
use supertoroid::fit::{FitOptions, fit};
use supertoroid::model::{Pose, Shape};
use supertoroid::suite::ground_truth::{compare, random_shape};
use supertoroid::synth::scene::with_sensor_noise;
use supertoroid::synth::{self, Intrinsics, SeededRng};

const FAMILIES: [&str; 4] = ["suite ranges", "tall rolls", "thin washers", "oval rings"];

/// A shape of family `family` and a random rotation axis.
fn shape_of(family: usize, rng: &mut SeededRng) -> (Shape, DVec3) {
    let (suite, axis) = random_shape(rng);
    let shape = match family {
        1 => {
            let a1 = rng.random_range(0.02..0.05);
            let a4 = rng.random_range(1.2..2.0);
            Shape::new(
                a1,
                a1 * rng.random_range(0.9..1.1),
                a1 * a4 * rng.random_range(1.0..3.0),
                a4,
                rng.random_range(0.2..1.0),
                rng.random_range(0.8..1.2),
            )
        }
        2 => Shape::new(
            rng.random_range(0.03..0.10),
            rng.random_range(0.03..0.10),
            rng.random_range(0.004..0.012),
            rng.random_range(1.5..3.0),
            rng.random_range(0.3..1.5),
            rng.random_range(0.3..1.5),
        ),
        3 => {
            let a1 = rng.random_range(0.05..0.12);
            Shape::new(
                a1,
                a1 / rng.random_range(1.3..2.0),
                rng.random_range(0.01..0.05),
                rng.random_range(1.2..3.0),
                rng.random_range(0.3..1.8),
                rng.random_range(0.3..1.8),
            )
        }
        _ => suite,
    };
    (shape, axis)
}

/// One view in its camera's frame through the sensor, with the truth in that frame.
fn view(seed: u64) -> (Vec<DVec3>, Shape, Pose) {
    let mut rng = synth::rng(seed);
    let (shape, axis) = shape_of((seed % 4) as usize, &mut rng);
    let intrinsics = Intrinsics::REALSENSE_640X480;
    // a table-top robot's range, and far enough for the object to fit in the image
    let distance = rng
        .random_range(0.4f64..0.9)
        .max(intrinsics.fy * shape.size() / (0.8 * intrinsics.height as f64));
    let (pose, camera) = placement::in_front_of_camera(&mut rng, axis, distance, intrinsics);
    let rendered = synth::render_view(&shape, &pose, &camera, 0.001).expect("a valid view");
    let depth = with_sensor_noise(&rendered.depth, 0.001, 0.3, seed);
    let seen = depth.back_project(&intrinsics);
    let count = rng.random_range(1000..=5000);
    let mut points = synth::subsample(&seen, count, &mut rng);
    let in_camera = Pose::new(
        camera.pose.rotation.inverse() * pose.rotation,
        camera.pose.to_canonical(pose.translation),
    );
    if seed % 2 == 1 {
        let half = shape.half_extents().max_element() * 2.0;
        let extra = points.len() * 5 / 95;
        for _ in 0..extra {
            let offset = DVec3::new(
                rng.random_range(-half..half),
                rng.random_range(-half..half),
                rng.random_range(-half..half),
            );
            points.push(in_camera.translation + offset);
        }
    }
    (points, shape, in_camera)
}

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
    let mut times = Vec::new();
    for seed in first..first + cases {
        let family = (seed % 4) as usize;
        let (points, shape, pose) = view(seed);
        counts[family] += 1;
        let options = FitOptions {
            seed,
            ..Default::default()
        };
        let report = match fit(&mut evaluator, &points, &options) {
            Ok(report) => report,
            Err(e) => {
                refused += 1;
                println!("  seed {seed} ({}): {e}", FAMILIES[family]);
                continue;
            }
        };
        let errors = compare((&shape, &pose), (&report.fitted.0, &report.fitted.1));
        if errors.success() {
            right[family] += 1;
        } else {
            println!(
                "  seed {seed} ({}) missed: truth {:.4?}, fit {:.4?}",
                FAMILIES[family],
                shape.to_array(),
                report.fitted.0.to_array()
            );
        }
        times.push(report.timing_ms.total);
    }
    times.sort_by(f64::total_cmp);
    println!(
        "{cases} views (seeds {first}..) through a D435-like sensor, no options, CPU evaluator:"
    );
    for (k, name) in FAMILIES.iter().enumerate() {
        println!("  {name:13} {} of {}", right[k], counts[k]);
    }
    println!(
        "  all           {} of {cases} ({refused} refused as no object); fit median {:.0} ms, p95 {:.0} ms",
        right.iter().sum::<usize>(),
        times[times.len() / 2],
        times[(times.len() * 95 / 100).min(times.len() - 1)]
    );
}

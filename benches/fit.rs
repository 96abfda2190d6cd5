//! One whole fit (both stages, default options) of each paper cloud, on the CPU and GPU
//! evaluators; and the four clouds as one lockstep batch (`fit_batch`, what
//! `/v1/fit/batch` runs) against the four fitted one after another; and a single-view
//! cloud of the ground-truth suite with and without its camera's position (the
//! free-space points a viewpoint adds); and a noisy full cloud with and without the noise
//! model; and setting stray points aside on clouds the size of a single view and of a
//! depth frame's mask.
//! `cargo bench --bench fit` (lavapipe is the GPU on a machine without one).

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use std::time::Duration;
use supertoroid::eval::*;
use supertoroid::fit::{FitOptions, fit, fit_batch};

/// A group of 20 samples after half a second of warm-up, over `seconds`: whole fits take
/// milliseconds, and the 2-core machine should get through `cargo bench` in minutes.
fn timed_group<'a>(
    c: &'a mut Criterion,
    name: &str,
    seconds: u64,
) -> criterion::BenchmarkGroup<'a, criterion::measurement::WallTime> {
    let mut group = c.benchmark_group(name);
    group
        .sample_size(20)
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(seconds));
    group
}

/// The CPU evaluator, and the GPU one when wgpu finds an adapter.
fn evaluators() -> Vec<Box<dyn Evaluator>> {
    let mut evaluators: Vec<Box<dyn Evaluator>> = vec![Box::new(CpuEvaluator::new())];
    match GpuContext::shared(&AdapterChoice::from_env()) {
        Ok(ctx) => evaluators.push(Box::new(GpuEvaluator::new(ctx))),
        Err(e) => eprintln!("no GPU adapter, CPU only: {e}"),
    }
    evaluators
}

fn bench_fit(c: &mut Criterion) {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/clouds/paper");
    let clouds: Vec<(String, Vec<glam::DVec3>)> =
        ["gearclean", "pot2clean", "perfectnoisedisplaced", "roll"]
            .iter()
            .map(|n| {
                let points = supertoroid::io::read_cloud(&dir.join(format!("{n}.pcd")), None)
                    .expect("the paper's clouds in ../shared/clouds/paper");
                (n.to_string(), points)
            })
            .collect();
    let mut evaluators = evaluators();
    let mut group = timed_group(c, "fit", 3);
    for evaluator in &mut evaluators {
        let kind = evaluator.kind();
        for (name, points) in &clouds {
            group.bench_function(BenchmarkId::new(kind, name), |b| {
                b.iter(|| fit(evaluator.as_mut(), points, &FitOptions::default()).unwrap())
            });
        }
    }
    group.finish();

    let mut group = timed_group(c, "batch of the four clouds", 4);
    let options = FitOptions::default();
    let batch: Vec<(&[glam::DVec3], &FitOptions)> = clouds
        .iter()
        .map(|(_, p)| (p.as_slice(), &options))
        .collect();
    for evaluator in &mut evaluators {
        let kind = evaluator.kind();
        group.bench_function(BenchmarkId::new(kind, "one after another"), |b| {
            b.iter(|| {
                for (_, points) in &clouds {
                    fit(evaluator.as_mut(), points, &options).unwrap();
                }
            })
        });
        group.bench_function(BenchmarkId::new(kind, "lockstep batch"), |b| {
            b.iter(|| fit_batch(evaluator.as_mut(), &batch).unwrap())
        });
    }
    group.finish();
}

/// Each named variant of the fit options on `points`, on every evaluator.
fn bench_variants(
    group: &mut criterion::BenchmarkGroup<'_, criterion::measurement::WallTime>,
    evaluators: &mut [Box<dyn Evaluator>],
    points: &[glam::DVec3],
    variants: &[(&str, FitOptions)],
) {
    for evaluator in evaluators {
        let kind = evaluator.kind();
        for (name, options) in variants {
            group.bench_function(BenchmarkId::new(kind, name), |b| {
                b.iter(|| fit(evaluator.as_mut(), points, options).unwrap())
            });
        }
    }
}

fn bench_single_view(c: &mut Criterion) {
    let mut evaluators = evaluators();
    let mut group = timed_group(c, "single view", 3);
    // the suite's case 10: single view, noise 1% of the size, no outliers
    let case = supertoroid::suite::ground_truth::make_case(10_010, true, 0.01, 0.0);
    let options = |viewpoint: Option<_>| FitOptions {
        seed: 10_010,
        viewpoint: viewpoint.into(),
        ..Default::default()
    };
    bench_variants(
        &mut group,
        &mut evaluators,
        &case.points,
        &[
            ("no viewpoint", options(None)),
            ("viewpoint", options(case.viewpoint)),
        ],
    );
    // the suite's case 17: a noisy single view with outliers, with and without the last
    // polish of the noise model on more points
    let noisy = supertoroid::suite::ground_truth::make_case(10_017, true, 0.02, 0.1);
    let options = |polish_points| FitOptions {
        seed: 10_017,
        viewpoint: noisy.viewpoint.into(),
        polish_points,
        ..Default::default()
    };
    bench_variants(
        &mut group,
        &mut evaluators,
        &noisy.points,
        &[
            ("noisy view, no polish", options(0)),
            (
                "noisy view, polished",
                options(FitOptions::default().polish_points),
            ),
        ],
    );
    group.finish();
}

/// The noise model's cost: the suite's case 5 (full cloud, noise 2% of the size, 0.45 of
/// a3, 5% outliers), and a single view with 1% noise seen by its camera.
fn bench_noise_model(c: &mut Criterion) {
    let mut evaluators = evaluators();
    let mut group = timed_group(c, "noise model", 3);
    let case = supertoroid::suite::ground_truth::make_case(10_005, false, 0.02, 0.05);
    let options = |noise_model| FitOptions {
        seed: 10_005,
        noise_model,
        ..Default::default()
    };
    bench_variants(
        &mut group,
        &mut evaluators,
        &case.points,
        &[
            ("noisy full, plain", options(false)),
            ("noisy full, modelled", options(true)),
        ],
    );
    // case 10 of seed set 20000: a single view (noise 1% of the size, 0.12 of the
    // thinnest half-axis)
    let grown = supertoroid::suite::ground_truth::make_case(20_010, true, 0.01, 0.0);
    let options = |noise_model| FitOptions {
        seed: 20_010,
        viewpoint: grown.viewpoint.into(),
        noise_model,
        ..Default::default()
    };
    bench_variants(
        &mut group,
        &mut evaluators,
        &grown.points,
        &[
            ("noisy single view, plain", options(false)),
            ("noisy single view, modelled", options(true)),
        ],
    );
    group.finish();
}

/// Setting isolated points aside (`fit::isolated`, the fit's first stage, on the CPU
/// whatever the evaluator): a noisy ring of 5,000, 20,000 and 60,000 points (a single
/// view; a depth frame's mask) with 5% strays over a box four times its extent.
fn bench_isolated(c: &mut Criterion) {
    use glam::{DQuat, DVec3};
    use rand::Rng;
    use supertoroid::model::{Pose, Shape};
    let mut group = timed_group(c, "set aside isolated points", 3);
    let shape = Shape::new(0.06, 0.05, 0.02, 2.0, 0.8, 1.0);
    let pose = Pose::new(DQuat::IDENTITY, DVec3::new(0.0, 0.0, 0.6));
    for count in [5_000, 20_000, 60_000] {
        let mut rng = supertoroid::synth::rng(7);
        let mut points = supertoroid::synth::sample_surface(&shape, &pose, count, &mut rng);
        supertoroid::synth::add_noise(&mut points, 0.001, &mut rng);
        for _ in 0..count / 20 {
            let offset = DVec3::new(
                rng.random_range(-0.5..0.5),
                rng.random_range(-0.5..0.5),
                rng.random_range(-0.5..0.5),
            );
            points.push(pose.translation + offset);
        }
        group.bench_function(BenchmarkId::new("cpu", count), |b| {
            b.iter(|| supertoroid::fit::isolated::without_isolated(&points))
        });
    }
    group.finish();
}

criterion_group!(
    benches,
    bench_fit,
    bench_single_view,
    bench_noise_model,
    bench_isolated
);
criterion_main!(benches);

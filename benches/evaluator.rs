//! Point-Jacobian evaluations per second (residual + 12-column gradient + reduction to
//! normal equations) for N points x K candidates, GPU (whatever adapter wgpu finds:
//! lavapipe on a machine without a GPU) against the f64 CPU evaluator. The N = 1000,
//! K = 1 GPU case is the round-trip latency of one solver iteration. Beside them, one
//! evaluation of the fit's objective with its gradient and BHHH Hessian (`objective`):
//! the f64 loop against the kernel, a noisy view of N points seen from its sensor; at
//! N = 8 the points cost nothing and what is left is the host's part of an evaluation
//! (the quadrature built at the candidate, and on the GPU the round trip).
//!
//! `cargo bench --bench evaluator`; `SUPERTOROID_BENCH_QUICK=1` keeps N <= 1e5.

use criterion::{
    BenchmarkId, Criterion, SamplingMode, Throughput, criterion_group, criterion_main,
};
use glam::{DQuat, DVec3};
use std::time::Duration;
use supertoroid::eval::*;
use supertoroid::model::{Pose, Shape};
use supertoroid::synth;

fn evaluators() -> Vec<Box<dyn Evaluator>> {
    let mut out: Vec<Box<dyn Evaluator>> = vec![Box::new(CpuEvaluator::new())];
    match GpuContext::shared(&AdapterChoice::from_env()) {
        Ok(ctx) => {
            eprintln!("GPU adapter: {}", ctx.adapter_name());
            out.push(Box::new(GpuEvaluator::new(ctx)));
        }
        Err(e) => eprintln!("no GPU adapter, CPU only: {e}"),
    }
    out
}

fn bench_normal_equations(c: &mut Criterion) {
    let shape = Shape::new(0.05, 0.04, 0.02, 2.0, 0.8, 1.2);
    let pose = Pose::new(DQuat::from_rotation_x(0.3), DVec3::new(0.1, 0.2, 0.5));
    let quick = std::env::var("SUPERTOROID_BENCH_QUICK").is_ok();
    let sizes: &[usize] = if quick {
        &[1_000, 10_000, 100_000]
    } else {
        &[1_000, 10_000, 100_000, 1_000_000]
    };
    let mut rng = synth::rng(1);
    let mut group = c.benchmark_group("normal_equations");
    group
        .sample_size(10)
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(2));
    for mut evaluator in evaluators() {
        for &n in sizes {
            let mut world = synth::sample_surface(&shape, &pose, n, &mut rng);
            synth::add_noise(&mut world, 0.01 * shape.size(), &mut rng);
            let norm = Normalization::of(&world);
            evaluator.set_points(&norm.points(&world)).unwrap();
            let truth = norm.candidate(&shape, &pose);
            for k in [1usize, 8, 64] {
                let batch: Vec<Candidate> = (0..k)
                    .map(|i| {
                        let mut c = truth;
                        c.shape.a1 *= 1.0 + 0.01 * i as f64;
                        c
                    })
                    .collect();
                if n * k >= 10_000_000 {
                    group.sampling_mode(SamplingMode::Flat);
                } else {
                    group.sampling_mode(SamplingMode::Auto);
                }
                group.throughput(Throughput::Elements((n * k) as u64));
                group.bench_with_input(
                    BenchmarkId::new(format!("{}/K={k}", evaluator.kind()), n),
                    &batch,
                    |b, batch| b.iter(|| evaluator.normal_equations(batch, Loss::Squared).unwrap()),
                );
            }
        }
    }
    group.finish();
}

fn bench_objective(c: &mut Criterion) {
    use supertoroid::fit::Sight;
    use supertoroid::fit::objective::{Data, Objective, Sensor, parameters};
    let shape = Shape::new(0.3, 0.2, 0.12, 2.0, 0.7, 1.3);
    let pose = Pose::new(DQuat::from_rotation_x(0.3), DVec3::new(0.05, -0.02, 0.1));
    let candidate = Candidate { shape, pose };
    let sigma = 0.02;
    let device = GpuContext::shared(&AdapterChoice::from_env())
        .and_then(|ctx| GpuObjective::shared(&ctx))
        .map_err(|e| eprintln!("no GPU adapter, the objective on the CPU only: {e}"))
        .ok();
    let mut group = c.benchmark_group("objective");
    group
        .sample_size(10)
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(2));
    let mut rng = synth::rng(2);
    for n in [8usize, 1_000, 4_000, 16_000] {
        let mut points = synth::sample_surface(&shape, &pose, n, &mut rng);
        synth::add_noise(&mut points, sigma, &mut rng);
        let sensor = Sensor::new(&points, Sight::at(DVec3::new(0.9, -1.4, 1.1)));
        let x = parameters(&candidate, sigma);
        for (kind, on) in [("cpu", None), ("gpu", device.as_deref())] {
            if kind == "gpu" && on.is_none() {
                continue;
            }
            let data = Data {
                points: &points,
                outlier_weight: 0.05,
                outlier_density: 0.05 / 8.0,
                sensor: Some(&sensor),
                device: on,
            };
            let mut objective = Objective::new(&data, &candidate, sigma);
            objective.hold(&x);
            group.throughput(Throughput::Elements(n as u64));
            group.bench_function(BenchmarkId::new(kind, n), |b| {
                b.iter(|| objective.evaluate(&x, true))
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bench_normal_equations, bench_objective);
criterion_main!(benches);

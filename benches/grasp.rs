//! Grasps for one object and surface queries of 10,000 points (paper §IV), on the CPU
//! (they run nowhere else): `cargo bench --bench grasp`.

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use glam::{DQuat, DVec3};
use std::time::Duration;
use supertoroid::grasp::{GraspRequest, Gripper, plan::plan, surface};
use supertoroid::model::{Plane, Pose, Shape};

fn objects() -> Vec<(&'static str, Shape)> {
    vec![
        ("ring", Shape::new(0.015, 0.015, 0.008, 2.5, 1.0, 1.0)),
        ("oval_ring", Shape::new(0.03, 0.02, 0.01, 3.0, 0.3, 0.6)),
        ("tube", Shape::new(0.012, 0.012, 0.05, 2.0, 0.2, 1.0)),
        ("box", Shape::new(0.03, 0.02, 0.03, 0.0, 0.5, 0.2)),
    ]
}

fn bench_grasps(c: &mut Criterion) {
    let mut group = c.benchmark_group("grasps");
    group
        .sample_size(30)
        .warm_up_time(Duration::from_millis(300))
        .measurement_time(Duration::from_secs(3));
    for (name, shape) in objects() {
        let request = GraspRequest {
            shape,
            pose: Pose::new(
                DQuat::from_rotation_x(0.3),
                DVec3::new(0.0, 0.0, shape.a3 + 0.6),
            ),
            gripper: Gripper::FRANKA_LIKE,
            friction: 0.5,
            plane: Some(Plane::through(DVec3::new(0.0, 0.0, 0.6), DVec3::Z)),
            viewpoint: Some(DVec3::new(0.0, -0.4, 1.1)),
            max_grasps: 10,
        };
        group.bench_with_input(BenchmarkId::new("plan", name), &request, |b, r| {
            b.iter(|| plan(r).unwrap())
        });
    }
    group.finish();
}

fn bench_surface(c: &mut Criterion) {
    let mut group = c.benchmark_group("surface_10k");
    group
        .sample_size(30)
        .warm_up_time(Duration::from_millis(300))
        .measurement_time(Duration::from_secs(3));
    let pose = Pose::new(DQuat::from_rotation_y(0.4), DVec3::new(0.1, 0.0, 0.5));
    for (name, shape) in objects() {
        group.bench_with_input(BenchmarkId::new("grid", name), &shape, |b, s| {
            b.iter(|| surface::grid(s, &pose, 100, 100))
        });
    }
    group.finish();
}

criterion_group!(benches, bench_grasps, bench_surface);
criterion_main!(benches);

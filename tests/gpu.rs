//! The WGSL evaluator against the f64 reference. Runs on whatever adapter wgpu finds
//! (lavapipe in CI, with WGPU_BACKEND=vulkan); a missing adapter fails these tests, it
//! never skips them.

use glam::{DQuat, DVec3};
use rand::Rng;
use std::sync::Arc;
use supertoroid::eval::*;
use supertoroid::model::{Pose, Shape, meridian_distance};
use supertoroid::synth;

fn context() -> Arc<GpuContext> {
    match GpuContext::shared(&AdapterChoice::from_env()) {
        Ok(ctx) => {
            eprintln!("GPU adapter: {}", ctx.adapter_name());
            ctx
        }
        Err(e) => panic!(
            "no GPU adapter ({e}); install mesa-vulkan-drivers (lavapipe) and run with WGPU_BACKEND=vulkan (CI={:?})",
            std::env::var("CI").ok()
        ),
    }
}

/// Costs of the GPU against the reference, candidate by candidate: the same point counts,
/// costs within 2e-3 relative to the reference's (or to `floor`, where it is ~0).
fn compare_costs(gpu: &[Cost], cpu: &[Cost], floor: f64) {
    assert_eq!(gpu.len(), cpu.len());
    for (k, (a, b)) in gpu.iter().zip(cpu).enumerate() {
        assert_eq!(a.count, b.count, "candidate {k}");
        assert!(
            (a.cost - b.cost).abs() <= 2e-3 * b.cost.max(floor),
            "candidate {k}: {} vs {}",
            a.cost,
            b.cost
        );
    }
}

fn random_shape(rng: &mut impl Rng) -> Shape {
    let eps = |rng: &mut synth::SeededRng| match rng.random_range(0..4) {
        0 => rng.random_range(0.1..0.15),
        1 => rng.random_range(1.9..2.0),
        _ => rng.random_range(0.1..2.0),
    };
    let mut r = synth::rng(rng.random());
    Shape::new(
        rng.random_range(0.3..1.5),
        rng.random_range(0.3..1.5),
        rng.random_range(0.2..1.0),
        if rng.random_bool(0.2) {
            0.0
        } else {
            rng.random_range(0.0..3.0)
        },
        eps(&mut r),
        eps(&mut r),
    )
}

fn random_pose(rng: &mut impl Rng) -> Pose {
    let axis = DVec3::new(
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
    )
    .normalize_or(DVec3::Z);
    Pose::new(
        DQuat::from_axis_angle(axis, rng.random_range(-3.0..3.0)),
        DVec3::new(
            rng.random_range(-0.5..0.5),
            rng.random_range(-0.5..0.5),
            rng.random_range(-0.5..0.5),
        ),
    )
}

/// Points around the object, including the axis and the mean superellipse (section centres).
fn points_around(shape: &Shape, pose: &Pose, n: usize, rng: &mut impl Rng) -> Vec<DVec3> {
    let h = shape.half_extents() * 1.5;
    (0..n)
        .map(|i| {
            let c = match i % 5 {
                // 0.5-1% of the size from the z axis: the distance jumps across the axis
                // when a1 != a2 (the meridian plane turns with the point), so closer in the
                // f32 rounding of the input alone moves it by more than 1e-4 of the size
                0 => {
                    let w: f64 = rng.random_range(-3.1..3.1);
                    let rho = rng.random_range(0.005..0.01) * shape.size();
                    DVec3::new(rho * w.cos(), rho * w.sin(), rng.random_range(-h.z..h.z))
                }
                1 => {
                    let w: f64 = rng.random_range(-3.1..3.1);
                    let [x, y] = supertoroid::model::mean_superellipse_point(shape, w);
                    // 1% of the size from the section centre: closer, the distance's jump
                    // across the centre (it is direction-dependent there) amplifies f32
                    // rounding of G - a4 beyond 1e-4 of the size
                    let offset = DVec3::new(
                        rng.random_range(-1.0..1.0),
                        rng.random_range(-1.0..1.0),
                        rng.random_range(-1.0..1.0),
                    );
                    DVec3::new(x, y, 0.0) + offset.normalize_or(DVec3::Z) * 0.01 * shape.size()
                }
                _ => DVec3::new(
                    rng.random_range(-h.x..h.x),
                    rng.random_range(-h.y..h.y),
                    rng.random_range(-h.z..h.z),
                ),
            };
            pose.to_world(c)
        })
        .collect()
}

#[test]
fn every_shader_validates_with_naga() {
    let mut count = 0;
    for entry in std::fs::read_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/shaders")).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "wgsl") {
            let source = std::fs::read_to_string(&path).unwrap();
            let module = naga::front::wgsl::parse_str(&source)
                .unwrap_or_else(|e| panic!("{}: {}", path.display(), e.emit_to_string(&source)));
            naga::valid::Validator::new(
                naga::valid::ValidationFlags::all(),
                naga::valid::Capabilities::empty(),
            )
            .validate(&module)
            .unwrap_or_else(|e| panic!("{}: {e:?}", path.display()));
            count += 1;
        }
    }
    assert!(count >= 1);
}

#[test]
fn gpu_residuals_match_the_f64_evaluator() {
    let mut gpu = GpuEvaluator::new(context());
    let mut rng = synth::rng(21);
    let mut worst: f64 = 0.0;
    for _ in 0..40 {
        let shape = random_shape(&mut rng);
        let pose = random_pose(&mut rng);
        let world = points_around(&shape, &pose, 500, &mut rng);
        let norm = Normalization::of(&world);
        gpu.set_points(&norm.points(&world)).unwrap();
        let r = gpu.residuals(&[norm.candidate(&shape, &pose)]).unwrap();
        for (p, r_gpu) in world.iter().zip(&r) {
            let exact = meridian_distance(&shape, pose.to_canonical(*p)).signed;
            let err = (r_gpu * norm.scale - exact).abs() / shape.size();
            worst = worst.max(err);
            assert!(
                err <= 1e-4,
                "gpu {} vs f64 {exact} ({shape:?}, canonical {})",
                r_gpu * norm.scale,
                pose.to_canonical(*p)
            );
        }
    }
    eprintln!("worst residual error / size = {worst:e}");
}

/// The f64 residual of a point under a candidate perturbed in parameter `k` by `h`
/// (rotation increments applied on the right, as the kernels' Jacobian assumes).
fn perturbed_residual(c: &Candidate, p: DVec3, k: usize, h: f64) -> f64 {
    let mut shape = c.shape.to_array();
    let mut pose = c.pose;
    match k {
        0..=5 => shape[k] += h,
        6..=8 => pose.translation[k - 6] += h,
        _ => {
            let mut d = DVec3::ZERO;
            d[k - 9] = h;
            pose.rotation = pose.rotation * DQuat::from_scaled_axis(d);
        }
    }
    meridian_distance(&Shape::from_array(shape), pose.to_canonical(p)).signed
}

#[test]
fn gpu_jacobian_matches_central_differences() {
    let mut gpu = GpuEvaluator::new(context());
    let mut rng = synth::rng(22);
    let mut checked = 0;
    while checked < 150 {
        let shape = random_shape(&mut rng);
        if shape.eps1 < 0.3 || shape.eps2 < 0.3 {
            continue; // f32 rounding of x^(2/eps) dominates the finite differences there
        }
        let c = Candidate {
            shape,
            pose: random_pose(&mut rng),
        };
        let h3 = shape.half_extents() * 1.5;
        let q = DVec3::new(
            rng.random_range(-h3.x..h3.x),
            rng.random_range(-h3.y..h3.y),
            rng.random_range(-h3.z..h3.z),
        );
        let m = meridian_distance(&shape, q);
        // differentiable region: off the axis, off the section centre, residual not ~0
        if q.x.hypot(q.y) < 0.05 || m.beta1 > 10.0 || m.signed.abs() < 0.02 {
            continue;
        }
        let p = c.pose.to_world(q);
        gpu.set_points(&[p]).unwrap();
        let ne = gpu.normal_equations(&[c], Loss::Squared).unwrap().remove(0);
        assert_eq!(ne.count, 1);
        let r = m.signed;
        let jac: Vec<f64> = ne.jtr.iter().map(|v| v / r).collect();
        let h = 1e-6;
        let fd: Vec<f64> = (0..NUM_PARAMS)
            .map(|k| {
                (perturbed_residual(&c, p, k, h) - perturbed_residual(&c, p, k, -h)) / (2.0 * h)
            })
            .collect();
        let scale = fd.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        for k in 0..NUM_PARAMS {
            let tol = 1e-2 * fd[k].abs().max(1e-2 * scale);
            assert!(
                (jac[k] - fd[k]).abs() <= tol,
                "column {k}: gpu {} vs fd {} ({shape:?}, q = {q})",
                jac[k],
                fd[k]
            );
        }
        checked += 1;
    }
}

fn compare_normal_equations(a: &NormalEquations, b: &NormalEquations, tol: f64) {
    assert_eq!(a.count, b.count);
    assert!(
        (a.cost - b.cost).abs() <= tol * b.cost.abs().max(1e-12),
        "cost {} vs {}",
        a.cost,
        b.cost
    );
    for i in 0..NUM_PARAMS {
        for j in 0..NUM_PARAMS {
            let s = (b.jtj[i][i] * b.jtj[j][j]).sqrt().max(1e-12);
            assert!(
                (a.jtj[i][j] - b.jtj[i][j]).abs() <= tol * s,
                "JtJ[{i}][{j}] {} vs {}",
                a.jtj[i][j],
                b.jtj[i][j]
            );
        }
        let s = (b.jtj[i][i] * 2.0 * b.cost).sqrt().max(1e-12);
        assert!(
            (a.jtr[i] - b.jtr[i]).abs() <= tol * s,
            "Jtr[{i}] {} vs {}",
            a.jtr[i],
            b.jtr[i]
        );
    }
}

#[test]
fn normal_equations_and_costs_match_the_cpu_for_1e3_and_1e6_points() {
    let mut gpu = GpuEvaluator::new(context());
    let mut cpu = CpuEvaluator::new();
    let mut rng = synth::rng(23);
    let shape = Shape::new(0.05, 0.04, 0.02, 2.0, 0.8, 1.2);
    let pose = random_pose(&mut rng);
    for n in [1_000usize, 1_000_000] {
        let mut world = synth::sample_surface(&shape, &pose, n, &mut rng);
        synth::add_noise(&mut world, 0.01 * shape.size(), &mut rng);
        let norm = Normalization::of(&world);
        let pts = norm.points(&world);
        gpu.set_points(&pts).unwrap();
        cpu.set_points(&pts).unwrap();
        // the truth and a perturbed candidate, with each loss
        let truth = norm.candidate(&shape, &pose);
        let mut off = truth;
        off.shape.a1 *= 1.1;
        off.shape.eps1 = 0.6;
        off.pose.translation += DVec3::new(0.05, -0.02, 0.03);
        for loss in [Loss::Squared, Loss::Huber(0.01), Loss::Cauchy(0.02)] {
            let g = gpu.normal_equations(&[truth, off], loss).unwrap();
            let c = cpu.normal_equations(&[truth, off], loss).unwrap();
            for (a, b) in g.iter().zip(&c) {
                compare_normal_equations(a, b, 2e-3);
            }
            let gc = gpu.costs(&[truth, off], loss).unwrap();
            for (a, b) in gc.iter().zip(&c) {
                assert_eq!(a.count, b.count);
                assert!(
                    (a.cost - b.cost).abs() <= 2e-3 * b.cost,
                    "cost-only kernel {} vs {}",
                    a.cost,
                    b.cost
                );
            }
        }
    }
}

#[test]
fn a_batch_of_candidates_equals_single_evaluations_and_is_reproducible() {
    let mut gpu = GpuEvaluator::new(context());
    let mut rng = synth::rng(24);
    let shape = Shape::new(0.8, 0.6, 0.4, 1.8, 0.7, 1.1);
    let pose = random_pose(&mut rng);
    let pts = synth::sample_surface(&shape, &pose, 5000, &mut rng);
    gpu.set_points(&pts).unwrap();
    let batch: Vec<Candidate> = (0..8)
        .map(|_| Candidate {
            shape: random_shape(&mut rng),
            pose: random_pose(&mut rng),
        })
        .collect();
    let together = gpu.normal_equations(&batch, Loss::Huber(0.05)).unwrap();
    assert_eq!(
        together,
        gpu.normal_equations(&batch, Loss::Huber(0.05)).unwrap(),
        "not reproducible"
    );
    for (c, b) in batch.iter().zip(&together) {
        let single = gpu
            .normal_equations(std::slice::from_ref(c), Loss::Huber(0.05))
            .unwrap()
            .remove(0);
        compare_normal_equations(&single, b, 1e-5);
    }
    let costs = gpu.costs(&batch, Loss::Squared).unwrap();
    for (c, b) in batch.iter().zip(&costs) {
        let single = gpu.costs(std::slice::from_ref(c), Loss::Squared).unwrap()[0];
        assert_eq!(single.count, b.count);
        assert!((single.cost - b.cost).abs() <= 1e-5 * b.cost);
    }
}

#[test]
fn padding_and_non_finite_points_are_not_counted() {
    let mut gpu = GpuEvaluator::new(context());
    let shape = Shape::new(1.0, 1.0, 0.5, 2.0, 1.0, 1.0);
    let mut pts = synth::sample_surface(&shape, &Pose::IDENTITY, 100, &mut synth::rng(1));
    pts.push(DVec3::new(f64::NAN, 0.0, 0.0));
    gpu.set_points(&pts).unwrap();
    let c = Candidate {
        shape,
        pose: Pose::IDENTITY,
    };
    let ne = gpu.normal_equations(&[c], Loss::Squared).unwrap().remove(0);
    assert_eq!(ne.count, 100);
    assert!(ne.cost < 1e-8);
    let mut empty = GpuEvaluator::new(context());
    assert!(matches!(
        empty.costs(&[c], Loss::Squared),
        Err(EvalError::NoPoints)
    ));
}

/// Several point sets in one upload, each candidate on its own: what a batch of clouds
/// needs. The normal equations, costs and residuals of each candidate equal the f64
/// reference on its set, and a set that was not uploaded is an error.
#[test]
fn candidates_on_different_point_sets_match_the_reference() {
    let mut gpu = GpuEvaluator::new(context());
    let mut cpu = CpuEvaluator::new();
    let mut rng = synth::rng(31);
    let shapes = [
        Shape::new(0.8, 0.6, 0.4, 1.8, 0.7, 1.1),
        Shape::new(0.5, 0.5, 0.2, 2.5, 1.2, 0.6),
        Shape::new(0.9, 0.7, 0.5, 0.0, 1.0, 1.0),
    ];
    let poses: Vec<Pose> = shapes.iter().map(|_| random_pose(&mut rng)).collect();
    let clouds: Vec<Vec<DVec3>> = [3000, 150, 1000]
        .iter()
        .zip(shapes.iter().zip(&poses))
        .map(|(&n, (s, p))| synth::sample_surface(s, p, n, &mut rng))
        .collect();
    let sets: Vec<&[DVec3]> = clouds.iter().map(|c| c.as_slice()).collect();
    gpu.set_point_sets(&sets).unwrap();
    cpu.set_point_sets(&sets).unwrap();
    // per set: the truth and a perturbed start; interleaved so no set is contiguous
    let mut batch = Vec::new();
    let mut which = Vec::new();
    for round in 0..2 {
        for (k, (s, p)) in shapes.iter().zip(&poses).enumerate() {
            let shape = if round == 0 {
                *s
            } else {
                Shape {
                    a1: s.a1 * 1.1,
                    eps1: s.eps1 * 0.9,
                    ..*s
                }
            };
            batch.push(Candidate { shape, pose: *p });
            which.push(k);
        }
    }
    let loss = Loss::Huber(0.05);
    let g = gpu.normal_equations_on(&batch, &which, loss).unwrap();
    let c = cpu.normal_equations_on(&batch, &which, loss).unwrap();
    for (k, (a, b)) in g.iter().zip(&c).enumerate() {
        assert_eq!(b.count as usize, clouds[which[k]].len(), "candidate {k}");
        if k >= 3 {
            // the truth has cost ~0, where f32 and f64 differ in relative terms
            compare_normal_equations(a, b, 2e-3);
        } else {
            assert_eq!(a.count, b.count);
        }
    }
    let gc = gpu.costs_on(&batch, &which, loss).unwrap();
    let cc = cpu.costs_on(&batch, &which, loss).unwrap();
    compare_costs(&gc, &cc, 1e-6);
    let gr = gpu.residuals_on(&batch, &which).unwrap();
    let cr = cpu.residuals_on(&batch, &which).unwrap();
    let expected: usize = which.iter().map(|&k| clouds[k].len()).sum();
    assert_eq!(gr.len(), expected);
    assert_eq!(cr.len(), expected);
    let far = gr
        .iter()
        .zip(&cr)
        .filter(|(a, b)| (*a - *b).abs() > 1e-3)
        .count();
    assert!(far * 100 < expected, "{far} of {expected} residuals differ");
    assert!(matches!(
        gpu.costs_on(&batch[..1], &[3], loss),
        Err(EvalError::BadSet(_))
    ));
    assert!(matches!(
        cpu.costs_on(&batch[..1], &[3], loss),
        Err(EvalError::BadSet(_))
    ));
}

/// `auto` sends small fits to the CPU even where a hardware GPU is found (a whole fit is
/// many small dispatches; measured on an H100, 1000-point stage-2 fits took 31 ms on it
/// against 12 ms on the host's CPU), and large ones to a hardware GPU when there is one.
#[test]
fn auto_fits_small_samples_on_the_cpu() {
    assert!(!auto_prefers_gpu(1000));
    assert!(!auto_prefers_gpu(AUTO_GPU_POINTS_PER_THREAD - 1));
    assert!(auto_prefers_gpu(
        AUTO_GPU_POINTS_PER_THREAD * rayon::current_num_threads()
    ));
    let evaluator = make_evaluator(Backend::Auto, 1000).unwrap();
    assert_eq!(evaluator.kind(), "cpu");
    // lavapipe is never taken by auto, however large the work
    let evaluator = make_evaluator(Backend::Auto, 100_000_000).unwrap();
    if let Ok(ctx) = GpuContext::shared(&AdapterChoice::from_env())
        && ctx.is_software()
    {
        assert_eq!(evaluator.kind(), "cpu");
    }
}

/// Free-space points (`PointSet::free_space`): outside the candidate they add nothing,
/// inside they add rho(r) of their (negative) meridian distance, never to the count, and
/// they have no residual entries; the WGSL kernels agree with the f64 reference.
#[test]
fn free_space_points_count_only_inside_the_candidate() {
    let mut rng = synth::rng(41);
    let shape = Shape::new(0.8, 0.6, 0.4, 1.8, 0.7, 1.1);
    let pose = random_pose(&mut rng);
    let surface = synth::sample_surface(&shape, &pose, 700, &mut rng);
    // points around the object, split by the truth's inside-outside function
    let around: Vec<DVec3> = (0..600)
        .map(|_| {
            let half = shape.half_extents() * 1.2;
            pose.to_world(DVec3::new(
                rng.random_range(-half.x..half.x),
                rng.random_range(-half.y..half.y),
                rng.random_range(-half.z..half.z),
            ))
        })
        .collect();
    let inside_outside = |p: &DVec3| shape.inside_outside(pose.to_canonical(*p));
    let outside: Vec<DVec3> = around
        .iter()
        .copied()
        .filter(|p| inside_outside(p) > 1.0)
        .collect();
    let inside: Vec<DVec3> = around
        .iter()
        .copied()
        .filter(|p| inside_outside(p) < 1.0)
        .collect();
    assert!(
        outside.len() > 100 && inside.len() > 50,
        "{} / {}",
        outside.len(),
        inside.len()
    );

    let truth = Candidate { shape, pose };
    let loss = Loss::Huber(0.05);
    let mut cpu = CpuEvaluator::new();
    cpu.set_points(&surface).unwrap();
    let alone = cpu.normal_equations(&[truth], loss).unwrap().remove(0);

    // outside: exactly nothing added
    cpu.set_point_sets_with_free_space(&[PointSet {
        surface: &surface,
        free_space: &outside,
    }])
    .unwrap();
    let with_outside = cpu.normal_equations(&[truth], loss).unwrap().remove(0);
    assert_eq!(with_outside.jtj, alone.jtj);
    assert_eq!(with_outside.jtr, alone.jtr);
    assert_eq!(
        (with_outside.cost, with_outside.count),
        (alone.cost, alone.count)
    );

    // inside: each adds rho of its meridian distance, none adds to the count
    cpu.set_point_sets_with_free_space(&[PointSet {
        surface: &surface,
        free_space: &inside,
    }])
    .unwrap();
    let with_inside = cpu.normal_equations(&[truth], loss).unwrap().remove(0);
    let expected: f64 = inside
        .iter()
        .map(|p| {
            loss.eval(meridian_distance(&shape, pose.to_canonical(*p)).signed)
                .0
        })
        .sum();
    assert!(expected > 0.0);
    assert!(
        (with_inside.cost - alone.cost - expected).abs() <= 1e-9 * expected,
        "{} vs {}",
        with_inside.cost - alone.cost,
        expected
    );
    assert_eq!(with_inside.count, surface.len() as u64);
    assert_eq!(cpu.residuals(&[truth]).unwrap().len(), surface.len());

    // the GPU kernels, on a mixed set and a start away from the truth
    let mut gpu = GpuEvaluator::new(context());
    let sets = [
        PointSet {
            surface: &surface,
            free_space: &around,
        },
        PointSet::surface(&surface[..150]),
    ];
    gpu.set_point_sets_with_free_space(&sets).unwrap();
    cpu.set_point_sets_with_free_space(&sets).unwrap();
    let start = Candidate {
        shape: Shape {
            a1: shape.a1 * 1.15,
            a3: shape.a3 * 1.2,
            ..shape
        },
        pose,
    };
    let batch = [start, truth, start];
    let which = [0, 0, 1];
    let g = gpu.normal_equations_on(&batch, &which, loss).unwrap();
    let c = cpu.normal_equations_on(&batch, &which, loss).unwrap();
    assert_eq!(c[0].count, surface.len() as u64);
    compare_normal_equations(&g[0], &c[0], 2e-3);
    compare_normal_equations(&g[2], &c[2], 2e-3);
    assert_eq!(g[1].count, c[1].count);
    let gc = gpu.costs_on(&batch, &which, loss).unwrap();
    let cc = cpu.costs_on(&batch, &which, loss).unwrap();
    compare_costs(&gc, &cc, 1e-3);
    let gr = gpu.residuals_on(&batch, &which).unwrap();
    assert_eq!(gr.len(), 2 * surface.len() + 150);
    assert_eq!(cpu.residuals_on(&batch, &which).unwrap().len(), gr.len());
}

/// The objective's kernel (`shaders/objective.wgsl`) against its f64 loop: value,
/// gradient and BHHH Hessian of a noisy cloud with outliers, with and without a sensor,
/// on a ring, an open superellipsoid and a thin square-sectioned tube.
#[test]
fn the_objective_on_the_gpu_matches_the_f64_loop() {
    use supertoroid::fit::Sight;
    use supertoroid::fit::objective::{Data, Objective, Sensor, parameters};
    let device = GpuObjective::shared(&context()).expect("the objective's kernel compiles");
    let shapes = [
        Shape::new(0.3, 0.2, 0.12, 2.0, 0.7, 1.3),
        Shape::new(0.3, 0.25, 0.2, 0.0, 0.6, 1.4),
        Shape::new(0.3, 0.15, 0.06, 2.3, 1.5, 0.3),
    ];
    for (s, shape) in shapes.into_iter().enumerate() {
        let pose = Pose::new(
            DQuat::from_scaled_axis(DVec3::new(0.3, -0.2, 0.5)),
            DVec3::new(0.05, -0.02, 0.1),
        );
        let mut rng = synth::rng(40 + s as u64);
        let mut points = synth::sample_surface(&shape, &pose, 800, &mut rng);
        synth::add_noise(&mut points, 0.02, &mut rng);
        points.extend((0..40).map(|_| {
            DVec3::new(
                rng.random_range(-0.6..0.6),
                rng.random_range(-0.6..0.6),
                rng.random_range(-0.6..0.6),
            )
        }));
        let sensor = Sensor::new(&points, Sight::at(DVec3::new(0.9, -1.4, 1.1)));
        let start = Candidate {
            shape: Shape::new(
                shape.a1 * 1.03,
                shape.a2 * 0.98,
                shape.a3 * 1.05,
                shape.a4,
                shape.eps1 + 0.05,
                shape.eps2 - 0.05,
            ),
            pose: Pose::new(pose.rotation, DVec3::new(0.06, -0.03, 0.1)),
        };
        for seen in [false, true] {
            let cpu_data = Data {
                points: &points,
                outlier_weight: 0.05,
                outlier_density: 0.05 / 8.0,
                sensor: seen.then_some(&sensor),
                device: None,
            };
            let gpu_data = Data {
                device: Some(&device),
                ..cpu_data
            };
            let x = parameters(&start, 0.025);
            let mut cpu = Objective::new(&cpu_data, &start, 0.025);
            let mut gpu = Objective::new(&gpu_data, &start, 0.025);
            cpu.hold(&x);
            gpu.hold(&x);
            let (value, gradient, hessian) = cpu.evaluate(&x, true);
            let (g_value, g_gradient, g_hessian) = gpu.evaluate(&x, true);
            let case = format!("{shape:?}, seen {seen}");
            // (f32 sums never equal the f64 loop's to the bit: the kernel ran, no fallback)
            assert_ne!(value, g_value, "{case}: the device's value is the loop's");
            assert!(
                (value - g_value).abs() < 1e-5 * value.abs().max(1.0),
                "{case}: {value} vs {g_value}"
            );
            let scale = gradient.amax().max(1e-3);
            assert!(
                (gradient - g_gradient).amax() < 1e-4 * scale,
                "{case}: {gradient} vs {g_gradient}"
            );
            let scale = hessian.amax();
            assert!(
                (hessian - g_hessian).amax() < 1e-4 * scale,
                "{case}: Hessians differ"
            );
            let (value_only, _, _) = gpu.evaluate(&x, false);
            assert!(
                (value_only - g_value).abs() < 1e-6 * value.abs().max(1.0),
                "{case}"
            );
        }
    }
}

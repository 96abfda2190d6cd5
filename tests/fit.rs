//! The two-stage fit against ground truth, and its handling of bad clouds.

use glam::DVec3;
use supertoroid::bench::paper::{Grade, grade_runs};
use supertoroid::eval::*;
use supertoroid::fit::{FitError, FitOptions, FitReport, fit};
use supertoroid::suite::ground_truth::{Case, compare, make_case};

/// Full clouds, noise 0-2% of the size, 0-10% outliers: a seeded CI subset of the suite.
/// (`bench synthetic` measures the whole suite; this is the quick check.)
#[test]
fn full_clouds_are_recovered_within_the_ground_truth_bounds() {
    let mut evaluator = CpuEvaluator::new();
    let mut successes = 0;
    let cases = 12;
    for i in 0..cases {
        let seed = 2 * i as u64;
        let noise = [0.0, 0.01, 0.02][i % 3];
        let outliers = [0.0, 0.05, 0.1][(i / 3) % 3];
        let case = make_case(seed, false, noise, outliers);
        let report = fit(
            &mut evaluator,
            &case.points,
            &FitOptions {
                seed,
                ..Default::default()
            },
        )
        .unwrap();
        let e = compare(
            (&case.shape, &case.pose),
            (&report.fitted.0, &report.fitted.1),
        );
        eprintln!(
            "case {seed}: noise {noise} outliers {outliers}: {e:?} -> {}",
            e.success()
        );
        if e.success() {
            successes += 1;
        }
    }
    assert!(
        successes >= 10,
        "only {successes} of {cases} full clouds recovered"
    );
}

/// A CI subset held to 90%: every full cloud with noise of at most 1% of the size (0, 5
/// and 10% outliers) among the 180 cases of `bench synthetic` (default seeds), 60 cases.
/// A floor for what works, beside the suite's own figures (README: Results).
#[test]
fn ninety_percent_of_full_clouds_with_up_to_one_percent_noise() {
    use supertoroid::bench::synthetic::{DEFAULT_SEED, category};
    let mut evaluator = CpuEvaluator::new();
    let (mut cases, mut successes) = (0, 0);
    for i in 0..180 {
        let (partial, noise, outliers) = category(i);
        if partial || noise > 0.011 {
            continue;
        }
        let seed = DEFAULT_SEED + i as u64;
        let case = make_case(seed, partial, noise, outliers);
        let options = FitOptions {
            seed,
            ..Default::default()
        };
        let report = fit(&mut evaluator, &case.points, &options).unwrap();
        let e = compare(
            (&case.shape, &case.pose),
            (&report.fitted.0, &report.fitted.1),
        );
        if !e.success() {
            eprintln!("case {seed}: noise {noise} outliers {outliers}: {e:?}");
        }
        cases += 1;
        successes += e.success() as usize;
    }
    assert_eq!(cases, 60);
    assert!(
        successes * 10 >= cases * 9,
        "{successes} of {cases} full clouds with noise <= 1% recovered (90% asked)"
    );
}

/// Successes on the single-view partial cases (odd seeds 1..23; noise 0/1/2% and
/// outliers 0/5/10% by seed) with a method.
fn partial_successes(method: supertoroid::fit::Method) -> usize {
    let mut evaluator = CpuEvaluator::new();
    let mut successes = 0;
    for seed in (1..24u64).step_by(2) {
        let noise = [0.0, 0.01, 0.02][(seed / 2 % 3) as usize];
        let outliers = [0.0, 0.05, 0.1][(seed / 6 % 3) as usize];
        let case = make_case(seed, true, noise, outliers);
        let report = fit(
            &mut evaluator,
            &case.points,
            &FitOptions {
                seed,
                method,
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(report.method, method);
        let e = compare(
            (&case.shape, &case.pose),
            (&report.fitted.0, &report.fitted.1),
        );
        eprintln!(
            "{method:?} partial case {seed}: noise {noise} outliers {outliers}: {e:?} -> {}",
            e.success()
        );
        successes += e.success() as usize;
    }
    successes
}

/// Twelve partial clouds with outliers, no viewpoint given: at least 5 recovered (without
/// a viewpoint the hidden side is unknown), and never fewer than the paper's procedure.
#[test]
fn partial_clouds_regression_floor() {
    let successes = partial_successes(supertoroid::fit::Method::Default);
    let paper = partial_successes(supertoroid::fit::Method::Paper);
    eprintln!("partial clouds recovered: {successes} of 12; paper method: {paper} of 12");
    assert!(
        successes >= 5,
        "only {successes} of 12 partial clouds recovered"
    );
    assert!(successes >= paper, "default {successes} < paper {paper}");
}

#[test]
fn gpu_and_cpu_fits_agree_on_a_clean_cloud() {
    let ctx =
        GpuContext::shared(&AdapterChoice::from_env()).expect("a GPU adapter (lavapipe in CI)");
    let case = make_case(100, false, 0.005, 0.0);
    let cpu = fit(
        &mut CpuEvaluator::new(),
        &case.points,
        &FitOptions::default(),
    )
    .unwrap();
    let gpu = fit(
        &mut GpuEvaluator::new(ctx),
        &case.points,
        &FitOptions::default(),
    )
    .unwrap();
    let e_cpu = compare((&case.shape, &case.pose), (&cpu.fitted.0, &cpu.fitted.1));
    let e_gpu = compare((&case.shape, &case.pose), (&gpu.fitted.0, &gpu.fitted.1));
    assert!(e_cpu.success(), "{e_cpu:?}");
    assert!(e_gpu.success(), "{e_gpu:?}");
    assert_eq!(gpu.backend.kind, "gpu");
    assert!(
        (cpu.quality.rms_distance - gpu.quality.rms_distance).abs()
            < 0.2 * cpu.quality.rms_distance
    );
}

/// A noisy full cloud fitted on the GPU evaluator: its search's likelihood runs on the
/// objective's kernel (the device counts its evaluations), and the fit is right as the
/// CPU's is.
#[test]
fn a_noisy_fit_on_the_gpu_ranks_by_the_objectives_kernel() {
    let ctx =
        GpuContext::shared(&AdapterChoice::from_env()).expect("a GPU adapter (lavapipe in CI)");
    let device = GpuObjective::shared(&ctx).expect("the objective's kernel compiles");
    let case = make_case(131, false, 0.02, 0.0);
    let before = device.evaluations();
    let gpu = fit(
        &mut GpuEvaluator::new(ctx),
        &case.points,
        &FitOptions::default(),
    )
    .unwrap();
    let on_device = device.evaluations() - before;
    assert!(on_device >= 10, "{on_device} evaluations on the device");
    let cpu = fit(
        &mut CpuEvaluator::new(),
        &case.points,
        &FitOptions::default(),
    )
    .unwrap();
    let e_gpu = compare((&case.shape, &case.pose), (&gpu.fitted.0, &gpu.fitted.1));
    let e_cpu = compare((&case.shape, &case.pose), (&cpu.fitted.0, &cpu.fitted.1));
    assert!(e_cpu.success() && e_gpu.success(), "{e_cpu:?} / {e_gpu:?}");
}

/// A dense cloud (a depth mask's tens of thousands of points) is fitted on an even
/// stride of at most `MAX_FIT_POINTS`, its strays set aside among those, and the fit is
/// the ring's; the report says what it read.
#[test]
fn a_dense_cloud_is_fitted_on_a_stride_of_it() {
    use glam::DQuat;
    use rand::Rng;
    use supertoroid::fit::MAX_FIT_POINTS;
    use supertoroid::model::{Pose, Shape};
    use supertoroid::synth;
    let shape = Shape::new(0.05, 0.04, 0.02, 2.0, 0.6, 1.0);
    let pose = Pose::new(DQuat::from_rotation_x(0.5), DVec3::new(0.02, -0.01, 0.6));
    let mut rng = synth::rng(11);
    let mut points = synth::sample_surface(&shape, &pose, 40_000, &mut rng);
    synth::add_noise(&mut points, 0.0003, &mut rng);
    for _ in 0..200 {
        let offset = DVec3::new(
            rng.random_range(-0.4..0.4),
            rng.random_range(-0.4..0.4),
            rng.random_range(-0.4..0.4),
        );
        points.push(pose.translation + offset);
    }
    let report = fit(
        &mut CpuEvaluator::new(),
        &points,
        &FitOptions {
            viewpoint: supertoroid::fit::Viewpoint::None,
            model: supertoroid::fit::Model::Supertoroid,
            ..Default::default()
        },
    )
    .unwrap();
    let read = report.points.thinned_to.expect("thinned");
    assert!(
        (MAX_FIT_POINTS / 2..=MAX_FIT_POINTS).contains(&read),
        "{:?}",
        report.points
    );
    assert_eq!(report.points.input, points.len());
    // (a stride of the strays is among the points read)
    assert!(
        (20..=read / 100).contains(&report.points.isolated),
        "{:?}",
        report.points
    );
    let e = compare((&shape, &pose), (&report.fitted.0, &report.fitted.1));
    assert!(e.success(), "{e:?}");
}

#[test]
fn bad_clouds_are_rejected_with_a_reason() {
    let mut ev = CpuEvaluator::new();
    let o = FitOptions::default();
    let few: Vec<DVec3> = (0..5).map(|i| DVec3::new(i as f64, 1.0, 2.0)).collect();
    assert_eq!(
        fit(&mut ev, &few, &o).unwrap_err(),
        FitError::TooFewPoints(5)
    );
    let mut nan = make_case(1, false, 0.0, 0.0).points;
    nan[17].y = f64::NAN;
    assert_eq!(fit(&mut ev, &nan, &o).unwrap_err(), FitError::NonFinite(17));
    let planar: Vec<DVec3> = (0..500)
        .map(|i| DVec3::new((i % 25) as f64, (i / 25) as f64, 3.0))
        .collect();
    assert_eq!(
        fit(&mut ev, &planar, &o).unwrap_err(),
        FitError::Degenerate("planar")
    );
    let line: Vec<DVec3> = (0..500)
        .map(|i| DVec3::new(i as f64, 2.0 * i as f64, -(i as f64)))
        .collect();
    assert_eq!(
        fit(&mut ev, &line, &o).unwrap_err(),
        FitError::Degenerate("collinear")
    );
    let same = vec![DVec3::ONE; 100];
    assert!(matches!(
        fit(&mut ev, &same, &o).unwrap_err(),
        FitError::Degenerate(_)
    ));
    let good = make_case(1, false, 0.0, 0.0).points;
    for refine_scale in [-1.0, f64::NAN, f64::INFINITY] {
        let bad = FitOptions {
            refine_scale,
            ..Default::default()
        };
        assert!(matches!(
            fit(&mut ev, &good, &bad).unwrap_err(),
            FitError::InvalidOption(m) if m.contains("refine scale")
        ));
    }
    let nowhere = FitOptions {
        viewpoint: supertoroid::fit::Viewpoint::given(DVec3::new(0.0, f64::INFINITY, 0.0)),
        ..Default::default()
    };
    assert!(matches!(
        fit(&mut ev, &good, &nowhere).unwrap_err(),
        FitError::InvalidOption(m) if m.contains("viewpoint")
    ));
}

/// Points that fill a volume (a solid ball of random points half a metre from the
/// camera, as a wrongly read file or a cloud of spray could give) lie on no surface: the
/// fit through them is not a confident answer. Their scatter grows with their misfit, so
/// it is the misfit against the size (`fit::MISFIT_OF_SIZE`) that warns.
#[test]
fn a_volume_of_points_is_not_fitted_as_a_confident_surface() {
    use rand::Rng;
    let mut rng = supertoroid::synth::rng(3);
    let mut ball = Vec::new();
    while ball.len() < 3000 {
        let p = DVec3::new(
            rng.random_range(-0.05..0.05),
            rng.random_range(-0.05..0.05),
            rng.random_range(-0.05..0.05),
        );
        if p.length() < 0.05 {
            ball.push(p + DVec3::new(0.0, 0.0, 0.5));
        }
    }
    let report = fit(&mut CpuEvaluator::new(), &ball, &FitOptions::default()).unwrap();
    assert!(warned_off_its_points(&report), "{:?}", report.warnings);
}

#[test]
fn cli_fit_prints_every_documented_field() {
    let dir = std::env::temp_dir().join(format!("supertoroid-fit-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("mug.xyz");
    let case = make_case(4, false, 0.005, 0.0);
    let text: String = case
        .points
        .iter()
        .map(|p| format!("{} {} {}\n", p.x, p.y, p.z))
        .collect();
    std::fs::write(&file, text).unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_supertoroid"))
        .args(["fit", "--backend", "cpu", "--seed", "3"])
        .arg(&file)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for path in [
        "/shape/a1",
        "/shape/a2",
        "/shape/a3",
        "/shape/a4",
        "/shape/eps1",
        "/shape/eps2",
        "/pose/translation/2",
        "/pose/rotation/2/2",
        "/pose/quaternion_wxyz/3",
        "/quality/rms_distance",
        "/quality/median_distance",
        "/quality/relative_rms",
        "/quality/inlier_fraction",
        "/quality/noise_sigma",
        "/timing_ms/stage1",
        "/timing_ms/stage2",
        "/timing_ms/noise_model",
        "/timing_ms/total",
        "/iterations/stage1",
        "/iterations/stage2",
        "/backend/kind",
        "/backend/adapter",
        "/points/input",
        "/points/stage1",
        "/points/stage2",
        "/search/starts",
        "/search/kept",
        "/search/refined",
        "/search/estimator",
        "/search/finalists",
    ] {
        assert!(json.pointer(path).is_some(), "missing {path} in {json}");
    }
    assert_eq!(json.pointer("/points/input").unwrap().as_u64(), Some(2000));
    let t = json
        .pointer("/pose/translation")
        .unwrap()
        .as_array()
        .unwrap();
    let centre = DVec3::new(
        t[0].as_f64().unwrap(),
        t[1].as_f64().unwrap(),
        t[2].as_f64().unwrap(),
    );
    assert!((centre - case.pose.translation).length() < 0.05 * case.shape.size());
    // a planar cloud: exit code 2 and one line naming the problem
    let flat = dir.join("flat.xyz");
    std::fs::write(
        &flat,
        (0..100)
            .map(|i| format!("{} {} 0\n", i % 10, i / 10))
            .collect::<String>(),
    )
    .unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_supertoroid"))
        .args(["fit", "--backend", "cpu"])
        .arg(&flat)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("planar"));
    // the sensor's position: accepted as x,y,z, named when malformed
    for (viewpoint, ok) in [("0,-1,0.5", true), ("0,1", false), ("0,nan,1", false)] {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_supertoroid"))
            .args(["fit", "--backend", "cpu", "--viewpoint", viewpoint])
            .arg(&file)
            .output()
            .unwrap();
        assert_eq!(out.status.success(), ok, "--viewpoint {viewpoint}");
        if !ok {
            assert_eq!(out.status.code(), Some(2));
            assert!(String::from_utf8_lossy(&out.stderr).contains("viewpoint"));
        }
    }
}

/// A flat washer seen from below (seed 1019), with no viewpoint (its cloud is in the
/// world's frame, whose origin is no camera): the view cannot tell its thickness, and the
/// unconstrained fit grows it into the unseen side, sizes far off. Given a3 (a product
/// dimension), the pose is recovered: centre within 5% of the size, axis within 5 degrees
/// (the shape still misses the suite's eps bound: the section curve is seen from one side
/// only).
#[test]
fn a_known_a3_resolves_a_one_sided_view() {
    let case = make_case(1019, true, 0.01, 0.0);
    let mut ev = CpuEvaluator::new();
    let free = fit(
        &mut ev,
        &case.points,
        &FitOptions {
            seed: 19,
            viewpoint: supertoroid::fit::Viewpoint::None,
            ..Default::default()
        },
    )
    .unwrap();
    let e_free = compare((&case.shape, &case.pose), (&free.fitted.0, &free.fitted.1));
    let known = fit(
        &mut ev,
        &case.points,
        &FitOptions {
            seed: 19,
            viewpoint: supertoroid::fit::Viewpoint::None,
            known_shape: [None, None, Some(case.shape.a3), None, None, None],
            ..Default::default()
        },
    )
    .unwrap();
    let e_known = compare(
        (&case.shape, &case.pose),
        (&known.fitted.0, &known.fitted.1),
    );
    eprintln!("free: {e_free:?}\nknown a3: {e_known:?}");
    assert!(
        e_free.sizes > 0.3,
        "the free fit was expected to miss here: {e_free:?}"
    );
    assert!(
        e_known.centre < 0.05 && e_known.axis_degrees < 5.0,
        "{e_known:?}"
    );
    assert!(e_known.sizes < e_free.sizes / 5.0, "{e_known:?}");
    let held = (known.fitted.0.a3 - case.shape.a3).abs() / case.shape.a3;
    assert!(held < 1e-6, "a3 moved by {held} (relative)");
    // nonsense is refused
    let bad = fit(
        &mut ev,
        &case.points,
        &FitOptions {
            known_shape: [None, None, Some(-1.0), None, None, None],
            ..Default::default()
        },
    );
    assert!(matches!(bad, Err(FitError::InvalidOption(_))));
}

/// A batch of clouds, fitted in lockstep: each cloud gets exactly the fit it gets alone
/// (CPU evaluator, bit for bit), a bad cloud gets its own error without stopping the
/// others, and clouds with other solver settings (the paper's method) still fit.
#[test]
fn a_batch_of_clouds_gives_each_cloud_its_own_fit() {
    use supertoroid::fit::{Method, fit_batch};
    let full = make_case(3, false, 0.01, 0.05).points;
    let partial = make_case(4, true, 0.0, 0.0).points;
    let outliers = make_case(5, false, 0.0, 0.1).points;
    let few: Vec<DVec3> = (0..5).map(|i| DVec3::new(i as f64, 1.0, 2.0)).collect();
    let a = FitOptions {
        seed: 7,
        ..Default::default()
    };
    let b = FitOptions {
        seed: 8,
        method: Method::Paper,
        ..Default::default()
    };
    let c = FitOptions {
        seed: 9,
        ..Default::default()
    };
    let clouds: Vec<(&[DVec3], &FitOptions)> = vec![
        (&full, &a),
        (&few, &a),
        (&partial, &b),
        (&outliers, &c),
        (&partial, &c),
    ];
    let batch = fit_batch(&mut CpuEvaluator::new(), &clouds).unwrap();
    assert_eq!(batch.len(), clouds.len());
    assert_eq!(batch[1].as_ref().unwrap_err(), &FitError::TooFewPoints(5));
    for (i, (points, options)) in clouds.iter().enumerate() {
        if i == 1 {
            continue;
        }
        let alone = fit(&mut CpuEvaluator::new(), points, options).unwrap();
        let together = batch[i].as_ref().unwrap();
        assert_eq!(together.fitted, alone.fitted, "cloud {i}");
        assert_eq!(together.method, options.method, "cloud {i}");
        assert_eq!(
            together.iterations.stage2, alone.iterations.stage2,
            "cloud {i}"
        );
        assert_eq!(together.quality.rms_distance, alone.quality.rms_distance);
    }
}

/// The same batch on the GPU evaluator (lavapipe in CI): one dispatch per solver
/// iteration for all clouds, each fit as good as the CPU's.
#[test]
fn a_batch_of_clouds_fits_on_the_gpu() {
    use supertoroid::fit::fit_batch;
    let ctx =
        GpuContext::shared(&AdapterChoice::from_env()).expect("a GPU adapter (lavapipe in CI)");
    let cases: Vec<_> = (0..3)
        .map(|i| make_case(100 + i, false, 0.005, 0.0))
        .collect();
    let o = FitOptions::default();
    let clouds: Vec<(&[DVec3], &FitOptions)> =
        cases.iter().map(|c| (c.points.as_slice(), &o)).collect();
    let gpu = fit_batch(&mut GpuEvaluator::new(ctx), &clouds).unwrap();
    let cpu = fit_batch(&mut CpuEvaluator::new(), &clouds).unwrap();
    for (i, case) in cases.iter().enumerate() {
        let g = gpu[i].as_ref().unwrap();
        let c = cpu[i].as_ref().unwrap();
        assert_eq!(g.backend.kind, "gpu");
        let e_gpu = compare((&case.shape, &case.pose), (&g.fitted.0, &g.fitted.1));
        let e_cpu = compare((&case.shape, &case.pose), (&c.fitted.0, &c.fitted.1));
        assert_eq!(
            e_gpu.success(),
            e_cpu.success(),
            "cloud {i}: {e_gpu:?} vs {e_cpu:?}"
        );
        assert!(
            (g.quality.rms_distance - c.quality.rms_distance).abs() < 0.2 * c.quality.rms_distance,
            "cloud {i}"
        );
    }
}

/// One of the paper's clouds, read from `../shared/clouds/paper` (never copied in).
fn paper_cloud(name: &str) -> Vec<DVec3> {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join(format!("../shared/clouds/paper/{name}.pcd"));
    supertoroid::io::read_cloud(&path, None)
        .expect("the paper's clouds live in ../shared/clouds/paper")
}

/// The paper's pot: a wall seen from one side, which least squares also fits with a
/// body stretched over empty space (a cylinder ten times taller than the pot, or one
/// lying on its side) at a lower cost than the ring the paper fits. Sizes are kept to the
/// cloud's extent (`fit::overreach`) on every seed, and at least 9 of 10 seeds agree on
/// the hole axis (the search puts one of ten in another basin). Fitted as the paper
/// fitted it, without a viewpoint (seen from its frame's origin the fit is worse:
/// `docs/fit.md`).
#[test]
fn the_pot_is_not_stretched_over_empty_space() {
    let points = paper_cloud("pot2clean");
    let mut evaluator = CpuEvaluator::new();
    let fits: Vec<_> = (0..10)
        .map(|seed| {
            let o = FitOptions {
                seed,
                viewpoint: supertoroid::fit::Viewpoint::None,
                ..FitOptions::default()
            };
            fit(&mut evaluator, &points, &o).unwrap().fitted
        })
        .collect();
    for (seed, (shape, pose)) in fits.iter().enumerate() {
        let reach = supertoroid::fit::overreach(
            &Candidate {
                shape: *shape,
                pose: *pose,
            },
            &points,
        );
        assert!(
            reach <= supertoroid::fit::MAX_OVERREACH,
            "seed {seed}: overreach {reach:.2}, {shape:?}"
        );
    }
    let agreeing = |axis: DVec3| {
        fits.iter()
            .filter(|(_, p)| axis.dot(p.axis()).abs() > 5f64.to_radians().cos())
            .count()
    };
    let most = fits.iter().map(|(_, p)| agreeing(p.axis())).max().unwrap();
    assert!(most >= 9, "only {most} of 10 seeds share a hole axis");
}

/// The paper's pot read as a view from its frame's origin (how its PCD header and `auto`
/// read it). Its open top is not in the model; a thin-walled tube (a4 at its bound of 8)
/// explains that misfit as blur at four times the cloud's own scatter, and the view
/// likelihood preferred it on 8 seeds of 10 once it refined the pot's thin-walled
/// candidates. Held to twice the noise the cloud shows (`fit::MAX_SIGMA_GROWTH`), the
/// pot is refined as a precise cloud: a thick ring close to most of its points.
#[test]
fn the_pot_read_as_a_view_is_not_taken_for_a_thin_walled_tube() {
    let points = paper_cloud("pot2clean");
    let mut evaluator = CpuEvaluator::new();
    for seed in [0, 2, 3] {
        let o = FitOptions {
            seed,
            viewpoint: supertoroid::fit::Viewpoint::Auto,
            ..FitOptions::default()
        };
        let r = fit(&mut evaluator, &points, &o).unwrap();
        assert!(
            r.fitted.0.a4 < 4.0 && r.quality.inlier_fraction > 0.6,
            "seed {seed}: {:?}, {:.2} of the points within 2% of the size",
            r.fitted.0,
            r.quality.inlier_fraction
        );
    }
}

/// The paper's pot fitted ten times on the CPU (f64) and on the GPU evaluator (f32): every
/// run grades the same on both. Its starts have round top views, whose turn about the
/// hole axis the points do not see; the GPU's rounding once turned them at random and
/// sent 5 of 30 runs to other basins than the CPU's.
#[test]
fn the_pots_runs_grade_alike_on_both_backends() {
    let ctx =
        GpuContext::shared(&AdapterChoice::from_env()).expect("a GPU adapter (lavapipe in CI)");
    let points = paper_cloud("pot2clean");
    let runs = |evaluator: &mut dyn Evaluator| -> Vec<FitReport> {
        (0..10)
            .map(|seed| {
                let o = FitOptions {
                    seed,
                    viewpoint: supertoroid::fit::Viewpoint::None,
                    ..FitOptions::default()
                };
                fit(evaluator, &points, &o).unwrap()
            })
            .collect()
    };
    let cpu = runs(&mut CpuEvaluator::new());
    let gpu = runs(&mut GpuEvaluator::new(ctx));
    let grades = |fits: &[FitReport]| -> Vec<Grade> {
        let fits: Vec<&FitReport> = fits.iter().collect();
        grade_runs(&points, &fits).iter().map(|g| g.grade).collect()
    };
    assert_eq!(
        grades(&cpu),
        grades(&gpu),
        "CPU and GPU grades of seeds 0-9"
    );
}

#[test]
fn true_shapes_are_supported_by_their_clouds_and_stretched_ones_are_not() {
    for seed in 0..20u64 {
        let case = make_case(20_000 + seed, seed % 2 == 1, 0.02, 0.0);
        let truth = Candidate {
            shape: case.shape,
            pose: case.pose,
        };
        let reach = supertoroid::fit::overreach(&truth, &case.points);
        assert!(reach < 1.0, "seed {seed}: the truth reaches {reach:.2}");
        let mut stretched = truth;
        stretched.shape.a3 *= 3.0 * supertoroid::fit::MAX_OVERREACH;
        let reach = supertoroid::fit::overreach(&stretched, &case.points);
        assert!(
            reach > supertoroid::fit::MAX_OVERREACH,
            "seed {seed}: a3 stretched reaches only {reach:.2}"
        );
    }
}

/// The suite's cases (default seeds of `bench synthetic`) whose category
/// `keep(partial, noise, outliers)` accepts, with their seeds.
fn suite_cases(keep: impl Fn(bool, f64, f64) -> bool) -> Vec<(u64, Case)> {
    suite_cases_from(supertoroid::bench::synthetic::DEFAULT_SEED, keep)
}

/// The same from another first seed (`bench synthetic --seed`).
fn suite_cases_from(first_seed: u64, keep: impl Fn(bool, f64, f64) -> bool) -> Vec<(u64, Case)> {
    use supertoroid::bench::synthetic::category;
    (0..180)
        .filter_map(|i| {
            let (partial, noise, outliers) = category(i);
            let seed = first_seed + i as u64;
            keep(partial, noise, outliers).then(|| (seed, suite_case(first_seed, seed)))
        })
        .collect()
}

/// The suite's case `seed` of the seed set that starts at `first_seed` (its category
/// follows from its place in the set).
fn suite_case(first_seed: u64, seed: u64) -> Case {
    let (partial, noise, outliers) =
        supertoroid::bench::synthetic::category((seed - first_seed) as usize);
    make_case(seed, partial, noise, outliers)
}

/// The default options for a suite case seen from its camera, the noise model on or off.
fn view_options(seed: u64, case: &Case, noise_model: bool) -> FitOptions {
    FitOptions {
        seed,
        viewpoint: case.viewpoint.into(),
        noise_model,
        ..Default::default()
    }
}

/// Fits the suite's case `seed` (of the set from `first_seed`) with the default options
/// seen from its camera and asserts that it is recovered; the case and the fit.
fn assert_recovered(evaluator: &mut CpuEvaluator, first_seed: u64, seed: u64) -> (Case, FitReport) {
    let case = suite_case(first_seed, seed);
    let (ok, report) = recovers(evaluator, &case, &view_options(seed, &case, true));
    assert!(
        ok,
        "case {seed}: {:?} against {:?}",
        report.fitted.0, case.shape
    );
    (case, report)
}

/// Whether the fit with `options` recovers the case (the suite's rule), and the fit.
fn recovers(evaluator: &mut CpuEvaluator, case: &Case, options: &FitOptions) -> (bool, FitReport) {
    let report = fit(evaluator, &case.points, options).unwrap();
    let e = compare(
        (&case.shape, &case.pose),
        (&report.fitted.0, &report.fitted.1),
    );
    (e.success(), report)
}

/// A suite case as users post it (in its camera's frame, no option but the seed): its
/// points, the fit, and the fit's pose in the case's world.
fn fitted_as_posted(
    evaluator: &mut CpuEvaluator,
    case: &Case,
    seed: u64,
) -> (Vec<DVec3>, FitReport, supertoroid::model::Pose) {
    use supertoroid::bench::synthetic::{Presentation, presented};
    let (points, viewpoint, back) = presented(case, Presentation::Camera);
    let options = FitOptions {
        seed,
        viewpoint,
        ..Default::default()
    };
    let report = fit(evaluator, &points, &options).unwrap();
    let pose = back.compose(&report.fitted.1);
    (points, report, pose)
}

/// The robust refinement at the end of stage 2 (a Cauchy loss scaled by the cloud's own
/// residual spread): on the suite's 20 noise-free single-view clouds with 5-10%
/// outliers, the fit with it must recover clearly more shapes than without it (measured
/// when written: 16 of 20 with it, 11 without). Both without the last polish of a
/// precise misfit (`FitOptions::polish_points`), which solves at small Cauchy scales too
/// and recovers most of them either way (19 and 18 with
/// it; 19 and 12 with it off in both arms).
#[test]
fn the_robust_refinement_shakes_off_outliers_on_one_sided_views() {
    let mut evaluator = CpuEvaluator::new();
    let cases = suite_cases(|partial, noise, outliers| partial && noise == 0.0 && outliers > 0.0);
    let (mut with, mut without) = (0, 0);
    for (seed, case) in &cases {
        let options = |refine_scale| FitOptions {
            seed: *seed,
            refine_scale,
            polish_points: 0,
            ..Default::default()
        };
        let default_scale = FitOptions::default().refine_scale;
        with += recovers(&mut evaluator, case, &options(default_scale)).0 as usize;
        without += recovers(&mut evaluator, case, &options(0.0)).0 as usize;
    }
    eprintln!("{with} of 20 recovered with the refinement, {without} without");
    assert_eq!(cases.len(), 20);
    assert!(
        with >= 15,
        "only {with} of 20 recovered with the refinement"
    );
    assert!(with >= without + 3, "refinement {with} vs none {without}");
}

/// A noise-free single view with outliers is fitted to rounding, not to a few per cent:
/// the Cauchy refinement shrinks its scale with the fit's residuals. On the suite's 20
/// such clouds (seen from their cameras), the sizes must come out within 1e-3 of the
/// truth on at least 16 (with one refinement at one scale: 4; the other four end within
/// the suite's tolerance, not at rounding).
#[test]
fn noise_free_views_with_outliers_are_fitted_to_rounding() {
    let mut evaluator = CpuEvaluator::new();
    let cases = suite_cases(|partial, noise, outliers| partial && noise == 0.0 && outliers > 0.0);
    let mut exact = Vec::new();
    for (seed, case) in &cases {
        let report = fit(
            &mut evaluator,
            &case.points,
            &view_options(*seed, case, true),
        )
        .unwrap();
        let e = compare(
            (&case.shape, &case.pose),
            (&report.fitted.0, &report.fitted.1),
        );
        if e.sizes < 1e-3 {
            exact.push(*seed);
            assert!(
                !warned_off_precise(&report),
                "case {seed}: a fit to rounding warned {:?}",
                report.warnings
            );
        }
    }
    eprintln!("sizes within 1e-3 on {} of 20: {exact:?}", exact.len());
    assert_eq!(cases.len(), 20);
    assert!(
        exact.len() >= 16,
        "only {} of 20 fitted to rounding",
        exact.len()
    );
}

/// The paper's real clouds are not what the model describes exactly (the gear's teeth,
/// the pot's wall and rim), so their fits leave more than their scatter: the pot 5.5
/// times it, the roll 2.7, the gear 2.0 (measured when written). The bound of
/// `fit::MISFIT_OVER_SCATTER` keeps clear of them by half again at least, so they are
/// neither retried nor warned. Fitted as the paper fitted them, without a viewpoint.
#[test]
fn the_paper_clouds_fit_within_the_bound_on_their_scatter() {
    let mut evaluator = CpuEvaluator::new();
    for name in ["gearclean", "perfectnoisedisplaced", "pot2clean", "roll"] {
        let points = paper_cloud(name);
        let scatter = supertoroid::fit::scatter::local_scatter(&points).unwrap();
        let options = FitOptions {
            viewpoint: supertoroid::fit::Viewpoint::None,
            ..Default::default()
        };
        let report = fit(&mut evaluator, &points, &options).unwrap();
        let ratio = report.quality.median_distance / scatter;
        assert!(
            ratio < supertoroid::fit::MISFIT_OVER_SCATTER / 1.5,
            "{name}: median distance {ratio:.1} times the scatter"
        );
        assert!(report.warnings.is_empty(), "{name}: {:?}", report.warnings);
    }
}

/// The noise model's refinement goes on through one step of little progress: on 20175
/// (a single view, 1% noise, 5% outliers) the first such step stopped it in a flat
/// valley with a3 13% short of the truth; the second step in a row ends it now.
#[test]
fn the_noise_model_does_not_stop_at_one_small_step() {
    let mut evaluator = CpuEvaluator::new();
    assert_recovered(&mut evaluator, 20000, 20175);
}

fn warned_off_precise(report: &FitReport) -> bool {
    report
        .warnings
        .iter()
        .any(|w| w.starts_with("off a precise"))
}

fn warned_off_its_points(report: &FitReport) -> bool {
    report
        .warnings
        .iter()
        .any(|w| w.starts_with(supertoroid::fit::OFF_ITS_POINTS_WARNING))
}

/// A depth sensor saw through the space in front of its points: told where the camera
/// was, the fit keeps solid out of it. On the suite's 60 single-view clouds with noise
/// <= 1% the fit with the viewpoint must recover more shapes than without it.
#[test]
fn the_camera_position_helps_single_views() {
    let mut evaluator = CpuEvaluator::new();
    let cases = suite_cases(|partial, noise, _| partial && noise <= 0.011);
    let (mut with, mut without) = (0, 0);
    for (seed, case) in &cases {
        let options = |viewpoint: Option<DVec3>| FitOptions {
            seed: *seed,
            viewpoint: viewpoint.into(),
            ..Default::default()
        };
        assert!(case.viewpoint.is_some());
        let (recovered, report) = recovers(&mut evaluator, case, &options(case.viewpoint));
        // the camera's own position is never taken for a wrong one
        assert!(
            viewpoint_warnings(&report).is_empty(),
            "case {seed}: {:?}",
            report.warnings
        );
        with += recovered as usize;
        without += recovers(&mut evaluator, case, &options(None)).0 as usize;
    }
    eprintln!("{with} of 60 recovered with the viewpoint, {without} without");
    assert_eq!(cases.len(), 60);
    assert!(with >= without + 4, "viewpoint {with} vs none {without}");
}

/// A viewpoint on the wrong side (opposite the camera, as a cloud in another frame than
/// its viewpoint would give) would push the fit off the points. The search may find a
/// body the wrong viewpoint does not contradict (behind the points, seen from there);
/// where its fit does put solid where the sensor saw through, the cloud is fitted again
/// without the viewpoint and the report says so. Either way the caller is told: the fit
/// with the wrong viewpoint carries a warning, the one with the camera's none of the
/// viewpoint's.
#[test]
fn a_viewpoint_the_fit_contradicts_is_ignored_with_a_warning() {
    let mut evaluator = CpuEvaluator::new();
    // the suite's case 10010: single view, noise 1%, no outliers
    let seed = 10_010;
    let case = make_case(seed, true, 0.01, 0.0);
    let camera = case.viewpoint.unwrap();
    let opposite = case.pose.translation - (camera - case.pose.translation);
    let options = |viewpoint: Option<DVec3>| FitOptions {
        seed,
        viewpoint: viewpoint.into(),
        ..Default::default()
    };
    let wrong = fit(&mut evaluator, &case.points, &options(Some(opposite))).unwrap();
    let none = fit(&mut evaluator, &case.points, &options(None)).unwrap();
    let right = fit(&mut evaluator, &case.points, &options(Some(camera))).unwrap();
    assert!(!wrong.warnings.is_empty(), "{:?}", wrong.warnings);
    if !viewpoint_warnings(&wrong).is_empty() {
        assert_eq!(
            wrong.fitted, none.fitted,
            "the refit is the fit without a viewpoint"
        );
        assert!(wrong.viewpoint.position.is_none());
    }
    assert!(viewpoint_warnings(&none).is_empty() && viewpoint_warnings(&right).is_empty());
}

/// The robust refinement's later rounds (clouds that lie on their surface) run up to 60
/// iterations, not 15: the held-out noise-free view 40138 (5% outliers) stopped at 15
/// with its points 4e-5 of the size off and a4 14% long, and is recovered at 60.
#[test]
fn the_robust_refinement_finishes_a_slow_valley_on_a_precise_view() {
    let mut evaluator = CpuEvaluator::new();
    let (case, report) = assert_recovered(&mut evaluator, 40_000, 40_138);
    assert_eq!(case.noise, 0.0);
    assert!(report.warnings.is_empty(), "{:?}", report.warnings);
}

/// The search starts single views from hole axes across the line of sight too
/// (`fit::starts::across_line_of_sight`): a ring seen edge-on shows a band whose normal
/// lines meet the tube's tangent about as well as the hole axis. The noise-free view
/// 60171, seen 75 degrees off its hole axis, is recovered to rounding.
#[test]
fn an_edge_on_ring_is_fitted_from_axes_across_the_line_of_sight() {
    let mut evaluator = CpuEvaluator::new();
    for (first_seed, seed) in [(60_000, 60_171)] {
        let (case, report) = assert_recovered(&mut evaluator, first_seed, seed);
        assert_eq!(case.noise, 0.0);
        let camera = (case.viewpoint.unwrap() - case.pose.translation).normalize();
        assert!(
            camera.dot(case.pose.axis()).abs() < 0.3,
            "case {seed} is seen edge-on"
        );
        assert!(report.fitted.0.a4 > 1.0, "{:?}", report.fitted.0);
        assert!(
            report.quality.median_distance < 1e-6 * case.shape.size(),
            "{:?}",
            report.quality
        );
    }
}

/// The search also starts behind the skin the sensor saw (`fit::starts::behind_the_skin`):
/// the view 60175 (a thin ring seen 10 degrees off edge-on, 1% noise, 5% outliers),
/// whose starts on the skin end as a closed body 8 times its size, is recovered.
#[test]
fn a_ring_seen_from_the_side_is_fitted_from_behind_its_skin() {
    let mut evaluator = CpuEvaluator::new();
    let (case, report) = assert_recovered(&mut evaluator, 60_000, 60_175);
    let camera = (case.viewpoint.unwrap() - case.pose.translation).normalize();
    assert!(
        camera.dot(case.pose.axis()).abs() < 0.2,
        "seen from the side"
    );
    assert!(
        report.quality.visible_coverage.unwrap() >= 0.75,
        "{:?}",
        report.quality
    );
}

/// A ring seen near edge-on, whose view a closed slab lying across the hole also covers,
/// converges beside that slab however far behind it round 2 leaves the ring
/// (`fit::search::rounds::ring_beside_closed`): the views 120085, 120089 and 140013
/// (1-2% noise, 5-10% outliers), fitted as closed slabs with the hole axis 60-90 degrees
/// off when only round 2's close finalists converged, are recovered with their hole.
#[test]
fn a_ring_behind_a_closed_slab_converges_beside_it() {
    let mut evaluator = CpuEvaluator::new();
    for (first_seed, seed) in [(120_000, 120_085), (120_000, 120_089), (140_000, 140_013)] {
        let (case, report) = assert_recovered(&mut evaluator, first_seed, seed);
        let camera = (case.viewpoint.unwrap() - case.pose.translation).normalize();
        assert!(
            camera.dot(case.pose.axis()).abs() < 0.5,
            "case {seed} is seen within 30 degrees of edge-on"
        );
        assert!(
            report.fitted.0.a4 > 1.0,
            "case {seed}: {:?}",
            report.fitted.0
        );
    }
}

fn viewpoint_warnings(report: &FitReport) -> Vec<&String> {
    report
        .warnings
        .iter()
        .filter(|w| w.starts_with("viewpoint ignored"))
        .collect()
}

/// The fit says when its points pin the shape down too loosely to trust its sizes and
/// eps (`fit::uncertainty`): the fits it does not warn about are the ones to trust. On
/// the suite's 90 full clouds (default seeds) the unwarned fits must be within the
/// suite's tolerances in 95% of cases at least, a noise-free cloud is never warned, and
/// the warned ones (where there are any) do worse.
#[test]
fn fits_without_an_uncertainty_warning_are_within_tolerance() {
    let mut evaluator = CpuEvaluator::new();
    let (mut unwarned, mut unwarned_ok, mut warned, mut warned_ok) = (0, 0, 0, 0);
    for (seed, case) in suite_cases(|partial, _, _| !partial) {
        let options = FitOptions {
            seed,
            ..Default::default()
        };
        let (ok, report) = recovers(&mut evaluator, &case, &options);
        let uncertain = report.warnings.iter().any(|w| w.starts_with("uncertain"));
        assert!(
            !(uncertain && case.noise == 0.0),
            "case {seed}: {:?}",
            report.warnings
        );
        if uncertain {
            (warned, warned_ok) = (warned + 1, warned_ok + ok as usize);
        } else {
            (unwarned, unwarned_ok) = (unwarned + 1, unwarned_ok + ok as usize);
            if !ok {
                eprintln!("case {seed}: unwarned and off: {:?}", report.shape);
            }
        }
    }
    eprintln!(
        "unwarned {unwarned_ok} of {unwarned} within tolerance, warned {warned_ok} of {warned}"
    );
    assert!(unwarned >= 80, "only {unwarned} of 90 fits unwarned");
    assert!(
        unwarned_ok * 100 >= unwarned * 95,
        "{unwarned_ok} of {unwarned} unwarned fits within tolerance (95% asked)"
    );
    assert!(warned == 0 || warned_ok * unwarned < unwarned_ok * warned);
}

/// A thin ring (a3 = 1 cm): with 2000 points its noise estimate is within 20% of the true
/// sigma (measured when written: 0.97 and 5.9 mm at 1 and 6 mm), and at 1 mm its
/// standard errors stay under half the tolerances. Under 6 mm of noise, 0.6 of the
/// section's half-thickness, they do not: with 2000 points the likelihood leaves eps
/// loose by 0.08 (eps1 came out 0.11 off), with 300 points looser still (0.34 off), and
/// the `uncertain shape` warning reaches the JSON.
#[test]
fn a_thin_ring_with_few_noisy_points_is_flagged_uncertain() {
    use supertoroid::model::{Pose, Shape};
    let shape = Shape::new(0.05, 0.05, 0.01, 2.0, 1.0, 1.0);
    let pose = Pose::default();
    let mut evaluator = CpuEvaluator::new();
    for (count, sigma, flagged, (low, high)) in [
        (2000, 0.0, false, (0.0, 1e-4)),
        (2000, 0.001, false, (0.8, 1.25)),
        (2000, 0.006, true, (0.8, 1.25)),
        (300, 0.006, true, (0.6, 1.5)),
    ] {
        let mut rng = supertoroid::synth::rng(5);
        let mut points = supertoroid::synth::sample_surface(&shape, &pose, count, &mut rng);
        supertoroid::synth::add_noise(&mut points, sigma, &mut rng);
        let report = fit(&mut evaluator, &points, &FitOptions::default()).unwrap();
        let json = serde_json::to_value(&report).unwrap();
        let noise = json["quality"]["noise_sigma"].as_f64().unwrap();
        let ratio = if sigma > 0.0 { noise / sigma } else { noise };
        eprintln!("{count} points, sigma {sigma}: estimated {noise}");
        assert!(
            (low..=high).contains(&ratio),
            "sigma {sigma}: estimated {noise}"
        );
        assert!(
            json["quality"]["standard_errors"]["eps"].is_number(),
            "{json}"
        );
        let says = json
            .get("warnings")
            .and_then(|w| w.as_array())
            .is_some_and(|w| {
                w.iter()
                    .any(|w| w.as_str().unwrap().starts_with("uncertain shape"))
            });
        assert_eq!(
            says, flagged,
            "{count} points, sigma {sigma}: {:?}",
            report.warnings
        );
    }
}

/// A free fit (`model: supertoroid`, a4 not held) that comes out a superellipsoid has
/// a4 on its bound at 0: its sizes' and exponents' errors are taken with a4 held there,
/// and a4's own error is measured against 1, the least a4 with a hole (against the
/// rounding the solver keeps above 0 it read as billions of percent and warned every
/// such fit). A whole box leaves no doubt that it has no hole; a tall roll seen from the
/// side and fitted without its hole (`suite::broad`'s view 2000029, the search's hollow
/// reading left out: with it the fit keeps the hole) does.
#[test]
fn a_free_fit_that_comes_out_a_superellipsoid_is_warned_only_where_a_hole_could_be() {
    use supertoroid::model::{Pose, Shape};
    let shape = Shape::new(0.04, 0.03, 0.05, 0.0, 0.3, 0.3);
    let mut rng = supertoroid::synth::rng(11);
    let mut points = supertoroid::synth::sample_surface(&shape, &Pose::default(), 2000, &mut rng);
    supertoroid::synth::add_noise(&mut points, 0.0005, &mut rng);
    let mut evaluator = CpuEvaluator::new();
    let report = fit(&mut evaluator, &points, &FitOptions::default()).unwrap();
    assert!(report.shape.a4 < 0.01, "{:?}", report.shape);
    let errors = report.quality.standard_errors.as_ref().unwrap();
    assert!(errors.a4 < 0.05 && errors.sizes < 0.01, "{errors:?}");
    assert!(
        !report.warnings.iter().any(|w| w.starts_with("uncertain")),
        "{:?}",
        report.warnings
    );
    // with `model: auto` the choice weighs the hole: the free fit standing for the
    // superellipsoid carries no a4 error, as the superellipsoid fit does not
    let auto = FitOptions {
        model: supertoroid::fit::Model::Auto,
        ..Default::default()
    };
    let report = fit(&mut evaluator, &points, &auto).unwrap();
    assert_eq!(report.quality.standard_errors.as_ref().unwrap().a4, 0.0);
    let seed = 2_000_029;
    let roll = supertoroid::suite::broad::view(seed);
    let options = FitOptions {
        seed,
        skip: vec![supertoroid::fit::ablation::Stage::HollowedReading],
        ..Default::default()
    };
    let report = fit(&mut evaluator, &roll.points, &options).unwrap();
    assert!(
        roll.shape.a4 > 1.0 && report.shape.a4 < 0.01,
        "{:?}",
        report.shape
    );
    let errors = report.quality.standard_errors.as_ref().unwrap();
    assert!(errors.a4 >= 0.05 && errors.a4 < 1.0, "{errors:?}");
    assert!(
        report.warnings.iter().any(|w| w.starts_with("uncertain")),
        "{:?}",
        report.warnings
    );
}

/// Told where the sensor was, a fit can be drawn from there (`fit::coverage`): the true
/// shape of a single view shows the sensor surface that the points cover, a body grown
/// into the side the sensor did not see shows it surface without points.
#[test]
fn the_visible_surface_of_the_true_shape_is_covered_and_a_grown_ones_is_not() {
    use supertoroid::fit::Sight;
    use supertoroid::fit::coverage::{MIN_VISIBLE_COVERAGE, visible_coverage};
    // the suite's case 10010: single view, noise 1%
    let case = make_case(10_010, true, 0.01, 0.0);
    let norm = Normalization::of(&case.points);
    let points = norm.points(&case.points);
    let viewpoint = norm.point(case.viewpoint.unwrap());
    let truth = norm.candidate(&case.shape, &case.pose);
    let covered = visible_coverage(&truth, &points, Sight::at(viewpoint));
    // grown: twice as thick and wide, moved away from the sensor so that its front
    // stays about where the points are
    let mut grown = truth;
    grown.shape.a1 *= 2.0;
    grown.shape.a2 *= 2.0;
    grown.shape.a3 *= 2.0;
    let away = (truth.pose.translation - viewpoint).normalize();
    grown.pose.translation += away * truth.shape.a3;
    let uncovered = visible_coverage(&grown, &points, Sight::at(viewpoint));
    eprintln!("coverage: truth {covered:.2}, grown {uncovered:.2}");
    assert!(covered >= 0.9, "truth covered {covered}");
    assert!(
        uncovered < MIN_VISIBLE_COVERAGE,
        "grown body covered {uncovered}"
    );
}

/// The suite's cases where the sensor noise is small against the object: sigma under 10%
/// of the true shape's thinnest half-axis (min of a1, a2, a3). Full and single-view
/// clouds, every outlier level, noise 0-2% of the size wherever the shape is thick enough
/// for it, held to 90%. Single views are given
/// the camera's position, as a depth frame gives it.
#[test]
fn ninety_percent_where_the_noise_is_under_a_tenth_of_the_thinnest_half_axis() {
    let mut evaluator = CpuEvaluator::new();
    let cases: Vec<(u64, Case)> = suite_cases(|_, _, _| true)
        .into_iter()
        .filter(|(_, c)| c.noise * c.shape.size() < 0.1 * c.shape.thinnest_half_axis())
        .collect();
    let (mut successes, mut partial, mut noisy) = (0, 0, 0);
    for (seed, case) in &cases {
        let options = FitOptions {
            seed: *seed,
            viewpoint: case.viewpoint.into(),
            ..Default::default()
        };
        let (ok, _) = recovers(&mut evaluator, case, &options);
        if !ok {
            eprintln!("case {seed}: partial {} noise {}", case.partial, case.noise);
        }
        successes += ok as usize;
        partial += case.partial as usize;
        noisy += (case.noise > 0.0) as usize;
    }
    eprintln!(
        "{successes} of {} recovered ({partial} single views, {noisy} noisy)",
        cases.len()
    );
    // the subset spans the suite: both cloud kinds, noisy clouds among them
    assert!(cases.len() >= 80 && partial >= 30 && noisy >= 20);
    assert!(
        successes * 10 >= cases.len() * 9,
        "{successes} of {} recovered (90% asked)",
        cases.len()
    );
}

/// The fit's estimator started at the answer (`ground_truth::model_from_truth`, the
/// ceiling `bench synthetic --from-truth` reports): on the suite's 2%-noise full cloud
/// 10002 it refines away from the truth (the noise moves its optimum) and stays within
/// the tolerances, on all points and on the fit's stage-2 sample, whose optimum differs;
/// a noise-free case has none (the model never runs on one, and its truth is an exact
/// least-squares optimum).
#[test]
fn the_estimator_from_the_truth_moves_off_it_and_stays_within_tolerance() {
    use supertoroid::suite::ground_truth::{TruthPoints, model_from_truth};
    let options = FitOptions::default();
    let seed = 10_002;
    let case = suite_case(10_000, seed);
    assert_eq!((case.partial, case.noise), (false, 0.02));
    let on_all = model_from_truth(&case, TruthPoints::All, true, &options).unwrap();
    let on_sample =
        model_from_truth(&case, TruthPoints::Stage2Sample(seed), true, &options).unwrap();
    for errors in [on_all, on_sample] {
        assert!(errors.success(), "{errors:?}");
        assert!(errors.sizes > 1e-4 && errors.eps > 1e-4, "{errors:?}");
    }
    assert_ne!(on_all.eps, on_sample.eps);
    let coarse = model_from_truth(&case, TruthPoints::All, false, &options).unwrap();
    assert_ne!(
        coarse.eps, on_all.eps,
        "the two grids have different optima"
    );
    let noise_free = suite_case(10_000, 10_000);
    assert_eq!(noise_free.noise, 0.0);
    assert!(model_from_truth(&noise_free, TruthPoints::All, true, &options).is_none());
}

/// A fit in the wrong basin is told from one the estimator itself settles in by
/// `ground_truth::basin_gap`: broadened view 3700024 (a squarish ring, eps2 0.43, through
/// the D435-like sensor) read the other way, its top view a diamond (the truth's turned
/// dual, eps2 1.57), is plainly less likely than the truth's basin (measured when written:
/// 0.55 nats a point); the truth itself is no gap at all, and a start the noise model does
/// not cover (no hole) is unscored.
#[test]
fn the_truths_basin_is_likelier_than_the_other_reading_of_a_top_view() {
    use supertoroid::eval::Normalization;
    use supertoroid::fit::starts::turned_dual;
    use supertoroid::suite::ground_truth::basin_gap;
    let case = supertoroid::suite::broad::view(3_700_024);
    let options = FitOptions::default();
    let sigma = case.noise * case.shape.size();
    let truth = (&case.shape, &case.pose);
    assert_eq!(basin_gap(&case, truth, sigma, &options), Some(0.0));
    let norm = Normalization::of(&case.points);
    let (shape, pose) = norm.to_world(&turned_dual(&norm.candidate(&case.shape, &case.pose)));
    assert!((shape.eps2 - (2.0 - case.shape.eps2)).abs() < 1e-12);
    let gap = basin_gap(&case, (&shape, &pose), sigma, &options).expect("both have a hole");
    assert!(gap > 0.1, "the other reading's gap {gap}");
    let solid = supertoroid::model::Shape {
        a4: 0.5,
        ..case.shape
    };
    assert_eq!(
        basin_gap(&case, (&solid, &case.pose), sigma, &options),
        None
    );
}

/// A tall roll seen from the side (a broadened view through the D435-like sensor, its hole
/// axis 83 degrees from the line of sight, no point on its inside) shows only its outside,
/// which least squares fits as well by a closed body: the search's hollow reading, weighed
/// by the likelihood, keeps the hole and the outer radius; without it the fit closes.
/// The wall's thickness is not pinned from there, so a4 itself is not asserted.
#[test]
fn a_tall_roll_seen_from_the_side_keeps_its_hole() {
    use supertoroid::fit::ablation::Stage;
    let case = supertoroid::suite::broad::view(4_100_069);
    let axis = case.pose.rotation * glam::DVec3::Z;
    let across = axis.dot(case.pose.translation.normalize()).abs().acos();
    assert!(across.to_degrees() > 75.0, "{}", across.to_degrees());
    let outer = |s: &supertoroid::model::Shape| s.a1.max(s.a2) * (1.0 + s.a4);
    let fitted = |skip: Vec<Stage>| fit_broad_view(&case, 4_100_069, skip).fitted.0;
    let shape = fitted(Vec::new());
    assert!(shape.a4 > 1.0, "{shape:?}");
    assert!(
        (outer(&shape) / outer(&case.shape) - 1.0).abs() < 0.1,
        "{shape:?} against {:?}",
        case.shape
    );
    let closed = fitted(vec![Stage::HollowedReading]);
    assert!(closed.a4 < 1.0, "{closed:?}");
}

/// Broadened view `case` (`suite::broad::view(seed)`) fitted as `bench broad` fits it,
/// with no option but its seed, leaving out the stages `skip`.
fn fit_broad_view(
    case: &Case,
    seed: u64,
    skip: Vec<supertoroid::fit::ablation::Stage>,
) -> FitReport {
    let options = FitOptions {
        seed,
        skip,
        ..Default::default()
    };
    fit(&mut CpuEvaluator::new(), &case.points, &options).unwrap()
}

/// A tall roll seen from the side through the D435-like sensor (broadened view 4660005,
/// 2.8% noise, its axis 88 degrees from the line of sight) that the search fits closed
/// (a4 0.71: without the hollow reading that fit stands): its hollow reading, started at
/// a4 = 2 and converged, then once more around a hole half as wide
/// (`search::NARROWER_HOLE`), brings the fit within the suite's rule, a4 included (the
/// hollow reading alone left it wrong).
#[test]
fn a_tall_roll_seen_from_the_side_gets_its_wall() {
    use supertoroid::fit::ablation::Stage;
    let seed = 4_660_005;
    let case = supertoroid::suite::broad::view(seed);
    let fitted = |skip: Vec<Stage>| fit_broad_view(&case, seed, skip).fitted;
    let (shape, pose) = fitted(Vec::new());
    let errors = compare((&case.shape, &case.pose), (&shape, &pose));
    assert!(
        errors.success(),
        "{shape:?} against {:?}: {errors:?}",
        case.shape
    );
    let (closed, _) = fitted(vec![Stage::HollowedReading]);
    assert!(closed.a4 < 1.0, "{closed:?}");
}

/// A view through the D435-like sensor (broadened view 4720016: a ring of the suite's
/// ranges, noise along the rays 0.4% of its size, its depth in 1 mm steps) whose search
/// rounds end on a least-squares fit, its sizes 40% off. Converged by the likelihood from
/// there (a view whose points show noise, `Stage::ViewLikelihood`), it stands within the
/// suite's rule; left out, the least-squares fit stands.
#[test]
fn a_sensor_view_refined_by_least_squares_ends_on_the_likelihood() {
    use supertoroid::fit::ablation::Stage;
    let seed = 4_720_016;
    let case = supertoroid::suite::broad::view(seed);
    let fitted = |skip: Vec<Stage>| {
        let report = fit_broad_view(&case, seed, skip);
        let (shape, pose) = report.fitted;
        let errors = compare((&case.shape, &case.pose), (&shape, &pose));
        let search = report.search.expect("the search's report");
        (errors, search)
    };
    let (errors, search) = fitted(Vec::new());
    assert!(errors.success(), "{errors:?}");
    assert!(search.finalists >= 1, "{search:?}");
    let (errors, search) = fitted(vec![Stage::ViewLikelihood]);
    assert!(!errors.success(), "{errors:?}");
    assert_eq!(search.finalists, 0, "{search:?}");
}

/// A view of a pinched ring (suite case 2460174: noise-free, 5% outliers, in its camera's
/// frame, no options) that least squares fits as well by a closed slab lying across its
/// hole: without the rings a closed fit may lie across, the fit is that slab, its hole
/// axis about 90 degrees off; with them the ring, the likelier, stands.
#[test]
fn a_ring_fitted_as_a_slab_across_its_hole_is_read_as_the_ring() {
    use supertoroid::bench::synthetic::{Presentation, category, presented};
    use supertoroid::fit::ablation::Stage;
    let seed = 2_460_174;
    let (partial, noise, outliers) = category((seed % 1000) as usize % 180);
    let case = make_case(seed, partial, noise, outliers);
    let (points, viewpoint, back) = presented(&case, Presentation::Camera);
    let errors = |skip: Vec<Stage>| {
        let options = FitOptions {
            seed,
            viewpoint,
            skip,
            ..Default::default()
        };
        let (shape, pose) = fit(&mut CpuEvaluator::new(), &points, &options)
            .unwrap()
            .fitted;
        let pose = supertoroid::model::Pose::new(
            back.rotation * pose.rotation,
            back.to_world(pose.translation),
        );
        compare((&case.shape, &case.pose), (&shape, &pose))
    };
    let slab = errors(vec![Stage::RingsAcross]);
    assert!(slab.axis_degrees > 60.0, "{slab:?}");
    let ring = errors(Vec::new());
    assert!(ring.success(), "{ring:?}");
}

/// A hole kept from the side (a tall roll's broadened view, 2000029, its hole axis across
/// the line of sight): the outer radius is measured but the wall is not, and the fit's
/// a4 comes out far off (2.5 against 1.85). Least squares' covariance reads a4 as pinned;
/// the likelihood's information, which weighs where the sensor would have seen into the
/// hole, leaves it loose, and the fit is warned `uncertain shape`.
#[test]
fn a_hole_kept_from_the_side_is_warned_as_loose_as_the_likelihood_leaves_it() {
    let seed = 2_000_029;
    let roll = supertoroid::suite::broad::view(seed);
    let options = FitOptions {
        seed,
        ..Default::default()
    };
    let report = fit(&mut CpuEvaluator::new(), &roll.points, &options).unwrap();
    let shape = report.shape;
    assert!(shape.a4 > 1.0, "{shape:?}");
    let (by_least_squares, errors) = warned_as_loose_as_the_likelihood(&report, &roll.points);
    assert!(errors.a4 > by_least_squares.a4, "{errors:?}");
}

/// The fit's standard errors from least squares alone (the meridian distances' covariance)
/// and as reported: least squares' under the warning's share, the report's over it, and
/// the fit warned `uncertain shape`.
fn warned_as_loose_as_the_likelihood(
    report: &FitReport,
    points: &[DVec3],
) -> (
    supertoroid::fit::uncertainty::StandardErrors,
    supertoroid::fit::uncertainty::StandardErrors,
) {
    let by_least_squares = supertoroid::fit::uncertainty::standard_errors(
        &report.fitted.0,
        &report.fitted.1,
        points,
        &[false; 6],
    )
    .unwrap();
    let share = supertoroid::fit::uncertainty::WARNING_SHARE;
    let errors = *report.quality.standard_errors.as_ref().unwrap();
    assert!(
        by_least_squares.share_of_tolerance() < share && errors.share_of_tolerance() >= share,
        "{by_least_squares:?} {errors:?}"
    );
    assert!(
        report
            .warnings
            .iter()
            .any(|w| w.starts_with("uncertain shape")),
        "{:?}",
        report.warnings
    );
    (by_least_squares, errors)
}

/// A noisy view the likelihood fitted (the suite's 100014: 2% noise, 5% outliers, as a
/// user posts it): least squares' covariance of the meridian distances reads the shape as
/// pinned within half the tolerances, the likelihood's information, whose maximum the fit
/// is, leaves it looser, and the fit is warned `uncertain shape` (its sizes came out 10.6%
/// off when this was written).
#[test]
fn a_noisy_view_is_as_uncertain_as_the_likelihood_leaves_it() {
    use supertoroid::bench::synthetic::category;
    let seed = 100_014;
    let (partial, noise, outliers) = category((seed % 1000) as usize % 180);
    let case = make_case(seed, partial, noise, outliers);
    let (points, report, _) = fitted_as_posted(&mut CpuEvaluator::new(), &case, seed);
    // (the polish takes on only a fit the noise model refined)
    assert!(report.points.polish.is_some(), "{:?}", report.search);
    warned_as_loose_as_the_likelihood(&report, &points);
}

/// The suite's CI subset: the first 72 cases of the ground-truth suite's default seeds,
/// four of each of its 18 categories (full and single-view clouds, noise 0, 1 and 2% of
/// the size, outliers 0, 5 and 10%), fitted as `bench synthetic` fits them (single views
/// given the camera's position). At least 90% must be within tolerance (measured when
/// written: 68 of 72; 67 and 68 on the first 72 of seeds 20000, 30000).
#[test]
fn ninety_percent_of_the_suite_ci_subset() {
    use supertoroid::bench::synthetic::{DEFAULT_SEED, category};
    let mut evaluator = CpuEvaluator::new();
    let mut successes = 0;
    let subset = 72;
    for i in 0..subset {
        let (partial, noise, outliers) = category(i);
        let seed = DEFAULT_SEED + i as u64;
        let case = make_case(seed, partial, noise, outliers);
        let (ok, _) = recovers(&mut evaluator, &case, &view_options(seed, &case, true));
        if !ok {
            eprintln!("case {seed}: partial {partial} noise {noise} outliers {outliers}");
        }
        successes += ok as usize;
    }
    eprintln!("{successes} of {subset} within tolerance");
    assert!(
        successes * 10 >= subset * 9,
        "{successes} of {subset} within tolerance (90% asked)"
    );
}

/// The noise model's polish on all of a cloud's points (`FitOptions::polish_points`):
/// eight views of seed set 810000 (as users post them: in the camera's frame, no options)
/// where `bench ablation` found the polish decides (noisy views whose search ends with eps
/// or sizes just off). At least six are recovered with it, and at least two more than
/// without it (the search's own refinement gets four of them right).
#[test]
fn the_polish_on_all_points_recovers_noisy_fits() {
    use supertoroid::bench::synthetic::{Presentation, category, presented};
    let mut evaluator = CpuEvaluator::new();
    let (mut polished_right, mut sample_right) = (0, 0);
    for seed in [
        810_028u64, 810_041, 810_047, 810_083, 810_095, 810_122, 810_157, 810_179,
    ] {
        let (partial, noise, outliers) = category((seed - 810_000) as usize);
        let case = make_case(seed, partial, noise, outliers);
        let (points, viewpoint, back) = presented(&case, Presentation::Camera);
        let right = |r: &FitReport| {
            let pose = back.compose(&r.fitted.1);
            compare((&case.shape, &case.pose), (&r.fitted.0, &pose)).success()
        };
        let options = |polish_points| FitOptions {
            seed,
            viewpoint,
            polish_points,
            ..Default::default()
        };
        let polished = fit(&mut evaluator, &points, &options(4000)).unwrap();
        let sample = fit(&mut evaluator, &points, &options(0)).unwrap();
        assert_eq!(sample.points.polish, None);
        polished_right += right(&polished) as usize;
        sample_right += right(&sample) as usize;
    }
    eprintln!("polished {polished_right} of 8 right, unpolished {sample_right}");
    assert!(
        polished_right >= 6 && polished_right >= sample_right + 2,
        "polished {polished_right}, unpolished {sample_right}"
    );
    // a polish on fewer points than a stage may have is refused
    let case = suite_case(20_000, 20_176);
    let err = fit(
        &mut evaluator,
        &case.points,
        &FitOptions {
            polish_points: 10,
            ..view_options(20_176, &case, true)
        },
    )
    .unwrap_err();
    assert!(err.to_string().contains("polish points"), "{err}");
}

/// The other reading of the top view ([`starts::turned_dual`]): the suite's cases 20016
/// (1% noise, 10% outliers; the rescue of an uncovered view) and 20053 (2% noise, 10%
/// outliers; the noise model's polish) fitted a square-ish top view (eps2 0.3 and 0.7)
/// to diamond-ish objects (eps2 1.55 and 1.45), sizes 17% and 10% off, until the model
/// also tried the reading turned 45 degrees; now both are within tolerance (on the
/// suite: 508 -> 510 of 540, none lost).
///
/// [`starts::turned_dual`]: supertoroid::fit::starts::turned_dual
#[test]
fn the_other_reading_of_the_top_view_is_tried() {
    let mut evaluator = CpuEvaluator::new();
    for seed in [20_016u64, 20_053] {
        assert_recovered(&mut evaluator, 20_000, seed);
    }
}

/// On a full cloud the likelier reading of the top view wins outright
/// (`fit::COVERED_DUAL_READING_MARGIN` 0, against the margin single views need): 90091
/// (1% noise) and 80113 (2% noise, 5% outliers), diamond-ish tops (eps2 1.72 and 1.55),
/// were fitted square-ish (eps2 0.36 and 0.43) with the right reading less than the
/// single views' margin more likely; both are recovered now.
#[test]
fn a_full_cloud_takes_the_likelier_reading_of_its_top_view() {
    let mut evaluator = CpuEvaluator::new();
    for (first_seed, seed) in [(90_000u64, 90_091u64), (80_000, 80_113)] {
        let (case, report) = assert_recovered(&mut evaluator, first_seed, seed);
        assert!(!case.partial && case.noise > 0.0, "case {seed}");
        assert!(report.shape.eps2 > 1.25, "{:?}", report.shape);
    }
}

/// A nearly round top view is read the other way too (`fit::DUAL_MIN_ROUNDNESS_GAP`
/// 0.07, where the readings' eps2 differ by more than the tolerance of 0.15): the full
/// cloud 90004 (1% noise, 5% outliers, a1 = a2 within 3%, eps2 1.11) was fitted in the
/// other reading (eps2 0.88) and left there while only top views 0.25 from round were
/// read both ways.
#[test]
fn a_nearly_round_top_view_is_read_both_ways() {
    let mut evaluator = CpuEvaluator::new();
    let (case, report) = assert_recovered(&mut evaluator, 90_000, 90_004);
    assert!(!case.partial && case.noise > 0.0);
    assert!(report.shape.eps2 > 1.0, "{:?}", report.shape);
}

/// The noise model's last polish refines on a grid twice as fine along the section
/// (`likelihood::refine_finely`): on sections a few sigmas thick the usual grid bends
/// the model's optimum. Refined from the true parameters on 16,000 points (three
/// samples each of the shapes of 40008, 50098 and 100044, full clouds at 2% noise and
/// no outliers), the usual grid leaves eps1 high on average (measured when written:
/// +0.044), the fine one not (+0.002).
#[test]
fn the_fine_grid_takes_the_section_bias_out_of_the_noise_model() {
    use supertoroid::fit::{LIKELIHOOD_OUTLIER_WEIGHT, likelihood};
    let options = FitOptions::default();
    let limits = likelihood::Limits {
        bounds: options.bounds(),
        fixed_shape: [false; 6],
        fixed_axis: false,
        deadline: None,
    };
    let (mut usual, mut fine) = (Vec::new(), Vec::new());
    for (first_seed, seed) in [(40000, 40008), (50000, 50098), (100000, 100044)] {
        let case = suite_case(first_seed, seed);
        for sample in 0..3 {
            let mut rng = supertoroid::synth::rng(seed * 7 + sample);
            let mut points =
                supertoroid::synth::sample_surface(&case.shape, &case.pose, 16_000, &mut rng);
            supertoroid::synth::add_noise(&mut points, case.noise * case.shape.size(), &mut rng);
            let norm = Normalization::of(&points);
            let points = norm.points(&points);
            let truth = norm.candidate(&case.shape, &case.pose);
            let sigma = case.noise * case.shape.size() / norm.scale;
            for (refine, errors) in [
                (likelihood::refine as likelihood::Refine, &mut usual),
                (likelihood::refine_finely, &mut fine),
            ] {
                let refined = refine(
                    &points,
                    &truth,
                    sigma,
                    LIKELIHOOD_OUTLIER_WEIGHT,
                    None,
                    &limits,
                    60,
                )
                .expect("the suite's shapes have a hole");
                errors.push(norm.to_world(&refined.candidate).0.eps1 - case.shape.eps1);
            }
        }
    }
    let mean = |e: &[f64]| e.iter().sum::<f64>() / e.len() as f64;
    eprintln!("eps1 errors, usual grid {usual:.3?}, fine {fine:.3?}");
    assert!(
        mean(&usual) > 0.025,
        "usual grid: mean eps1 error {:.3}",
        mean(&usual)
    );
    assert!(
        mean(&fine).abs() < 0.02,
        "fine grid: mean eps1 error {:.3}",
        mean(&fine)
    );
}

/// The noise model's grid fine enough for 1% noise (`likelihood::MAX_CELLS` 24,000): single
/// views of the suite with 1% noise and 0-10% outliers (10154, 20139) whose model, capped
/// at 12,000 cells, ended 10-20% off in a size or a4 (cells wider than the 2 sigmas that
/// make the kernel sum match its integral). With the finer grid they are within tolerance
/// (on the suite: 512 -> 515 of 540, none lost; a third, 10070, is lost to the view
/// model's mesh occlusion: a4 14% off, 517 of 540).
#[test]
fn the_noise_model_grid_is_fine_enough_for_one_percent_noise() {
    let mut evaluator = CpuEvaluator::new();
    for (first_seed, seed) in [(10_000u64, 10_154u64), (20_000, 20_139)] {
        let (case, _) = assert_recovered(&mut evaluator, first_seed, seed);
        assert_eq!(case.noise, 0.01, "case {seed} has 1% noise");
        assert!(case.partial, "case {seed} is a single view");
    }
}

/// A product's dimensions as a prior (`FitOptions::known_shape`): on the suite's 60
/// single views with noise <= 1%, given a1, a2, a3 and a4 the fit must find the pose
/// (centre and hole axis within the suite's bounds) in at least 54 and recover every
/// parameter in at least 50 (measured when written: 57 and 54; without the prior 47 and
/// 41; since the noise model 56 and 55, without the prior 56 and 50; since the rescue of
/// uncovered single views the free fit finds one pose more, 57, and since the retries
/// follow the least-squares fit's coverage 57 and 56 with the prior, 57 and 51 without;
/// since the noise model's finer grid 57 and 57 with it, 60 and 58 without; since the
/// polish on all points 57 and 57 with it, 60 and 59 without), and recover no fewer than
/// two short of the free fit (one until the polish, which the free fit gained one by). The
/// known values are held exactly. (The prior's pose misses, cases 10100, 10136 and 10171,
/// are fits in a wrong basin whose free space the known sizes contradict, refitted
/// without the viewpoint, which the polish does not touch.)
#[test]
fn known_dimensions_pin_down_single_views() {
    use supertoroid::suite::ground_truth::{AXIS_BOUND_DEGREES, CENTRE_BOUND};
    let mut evaluator = CpuEvaluator::new();
    let cases = suite_cases(|partial, noise, _| partial && noise <= 0.011);
    let (mut pose, mut all, mut pose_free, mut all_free) = (0, 0, 0, 0);
    for (seed, case) in &cases {
        let s = case.shape;
        let options = |known_shape| FitOptions {
            seed: *seed,
            viewpoint: case.viewpoint.into(),
            known_shape,
            ..Default::default()
        };
        let known = [Some(s.a1), Some(s.a2), Some(s.a3), Some(s.a4), None, None];
        for (shape, pose_count, all_count) in [
            (known, &mut pose, &mut all),
            ([None; 6], &mut pose_free, &mut all_free),
        ] {
            let report = fit(&mut evaluator, &case.points, &options(shape)).unwrap();
            let e = compare(
                (&case.shape, &case.pose),
                (&report.fitted.0, &report.fitted.1),
            );
            *pose_count +=
                (e.centre < CENTRE_BOUND && e.axis_degrees < AXIS_BOUND_DEGREES) as usize;
            *all_count += e.success() as usize;
            if shape[0].is_some() {
                let f = report.fitted.0;
                for (got, want) in [(f.a1, s.a1), (f.a2, s.a2), (f.a3, s.a3), (f.a4, s.a4)] {
                    assert!(
                        (got - want).abs() <= 1e-9 * want.max(1.0),
                        "{got} vs {want}"
                    );
                }
            }
        }
    }
    eprintln!("known dimensions: pose {pose}, all {all}; free: pose {pose_free}, all {all_free}");
    assert_eq!(cases.len(), 60);
    assert!(pose >= 54 && all >= 50, "pose {pose}, all {all} of 60");
    assert!(
        all + 2 >= all_free,
        "all {all} with the prior, {all_free} without"
    );
}

/// The text form of known shape parameters, and what it refuses.
#[test]
fn known_shape_parameters_parse_and_bad_ones_are_named() {
    use supertoroid::fit::{known_with_a3, parse_known_shape};
    let known = parse_known_shape("a1=0.05, a4:2.1,eps2=1").unwrap();
    assert_eq!(known, [Some(0.05), None, None, Some(2.1), None, Some(1.0)]);
    assert_eq!(parse_known_shape("").unwrap(), [None; 6]);
    for (bad, names) in [
        ("a5=1", "a5"),
        ("a1", "a1"),
        ("a1=x", "x"),
        ("a1=1,a1=2", "twice"),
    ] {
        let e = parse_known_shape(bad).unwrap_err();
        assert!(e.contains(names), "{bad}: {e}");
    }
    assert_eq!(known_with_a3([None; 6], Some(0.02)).unwrap()[2], Some(0.02));
    assert!(known_with_a3([None, None, Some(0.02), None, None, None], Some(0.02)).is_err());
    // implausible values are refused by the fit, naming the parameter
    let case = make_case(1019, true, 0.01, 0.0);
    let mut evaluator = CpuEvaluator::new();
    for known in [
        [None, None, None, Some(9.0), None, None],
        [None, None, None, None, Some(0.01), None],
        [Some(f64::NAN), None, None, None, None, None],
    ] {
        let bad = fit(
            &mut evaluator,
            &case.points,
            &FitOptions {
                known_shape: known,
                ..Default::default()
            },
        );
        assert!(matches!(bad, Err(FitError::InvalidOption(_))), "{known:?}");
    }
}

/// The noise model (`fit::likelihood`): on the suite's 30 full clouds with 2% noise (up to
/// 0.7 of the thinnest half-axis), least squares leaves sizes and eps biased; the model's
/// maximum-likelihood polish must recover clearly more of them (measured when written:
/// 27 of 30 with it, 17 without), and its sigma must be within 20% of the truth on
/// each recovered one.
#[test]
fn the_noise_model_recovers_noisy_full_clouds() {
    let mut evaluator = CpuEvaluator::new();
    let cases = suite_cases(|partial, noise, _| !partial && noise == 0.02);
    let (mut with, mut without) = (0, 0);
    for (seed, case) in &cases {
        let options = |noise_model| FitOptions {
            seed: *seed,
            noise_model,
            ..Default::default()
        };
        let (ok, report) = recovers(&mut evaluator, case, &options(true));
        let truth = case.noise * case.shape.size();
        let ratio = report.quality.noise_sigma / truth;
        eprintln!("case {seed}: {ok}, sigma {ratio:.2} of the truth");
        if ok {
            assert!(
                (0.8..1.2).contains(&ratio),
                "case {seed}: sigma {ratio} of the truth"
            );
        }
        with += ok as usize;
        without += recovers(&mut evaluator, case, &options(false)).0 as usize;
    }
    eprintln!(
        "{with} of {} with the noise model, {without} without",
        cases.len()
    );
    assert!(with >= 26, "{with} of {} with the noise model", cases.len());
    assert!(
        with >= without + 8,
        "{with} with the noise model, {without} without"
    );
}

/// With the camera's position the noise model also weighs what the sensor saw
/// (cos(incidence) / range² on the visible surface): on the suite's 60 noisy single views
/// (noise 1% and 2%) it must recover more shapes than the fit without it (measured when
/// written: 36 of 60 with it, 19 without; with the view model's
/// back faces culled and grazing faces kept, 50 with it; it needs a margin of 25).
#[test]
fn the_noise_model_helps_noisy_single_views() {
    let mut evaluator = CpuEvaluator::new();
    let cases = suite_cases(|partial, noise, _| partial && noise > 0.0);
    let (mut with, mut without) = (0, 0);
    for (seed, case) in &cases {
        let options = |noise_model| view_options(*seed, case, noise_model);
        with += recovers(&mut evaluator, case, &options(true)).0 as usize;
        without += recovers(&mut evaluator, case, &options(false)).0 as usize;
    }
    eprintln!(
        "{with} of {} with the noise model, {without} without",
        cases.len()
    );
    assert!(
        with >= without + 25,
        "{with} with the noise model, {without} without"
    );
}

/// As a user posts a cloud, with no options: single views in their camera's optical
/// frame are found to be views from the origin and fitted as views; full clouds in the
/// suite's frame (the origin outside them) are fitted as views from nowhere. On a dozen
/// of the suite's cases with noise up to 1%, at least 11 are within tolerance (measured
/// when written: 12).
#[test]
fn clouds_posted_as_sensors_write_them_are_fitted_without_options() {
    let recovered = recovered_as_posted(supertoroid::fit::Method::Default);
    assert!(recovered >= 11, "only {recovered} of 12 recovered");
}

/// Twelve suite cases with up to 1% noise and 5% outliers as a sensor writes them (a
/// single view in its camera's frame, a full cloud as drawn), fitted by `method` with no
/// other option: the viewpoint each is given is checked, and the recovered are counted.
fn recovered_as_posted(method: supertoroid::fit::Method) -> usize {
    use supertoroid::fit::ViewpointSource;
    let mut evaluator = CpuEvaluator::new();
    let cases: Vec<(u64, Case)> =
        suite_cases(|_, noise, outliers| noise <= 0.011 && outliers <= 0.05)
            .into_iter()
            .step_by(3)
            .take(12)
            .collect();
    let mut recovered = 0;
    for (seed, case) in &cases {
        let (points, camera) = match case.in_camera_frame() {
            Some(view) => view,
            None => (
                case.points.clone(),
                supertoroid::model::Pose::new(glam::DQuat::IDENTITY, DVec3::ZERO),
            ),
        };
        let options = FitOptions {
            seed: *seed,
            method,
            ..Default::default()
        };
        let report = fit(&mut evaluator, &points, &options).unwrap();
        assert_eq!(report.method, method);
        let expected = if case.partial {
            ViewpointSource::FrameOrigin
        } else {
            ViewpointSource::None
        };
        assert_eq!(
            report.viewpoint.source, expected,
            "case {seed}: {}",
            report.viewpoint.reason
        );
        assert!(
            viewpoint_warnings(&report).is_empty(),
            "case {seed}: {:?}",
            report.warnings
        );
        let in_world = camera.compose(&report.fitted.1);
        let success = compare((&case.shape, &case.pose), (&report.fitted.0, &in_world)).success();
        eprintln!("{method:?} case {seed}: recovered {success}");
        recovered += success as usize;
    }
    assert_eq!(cases.len(), 12);
    assert!(cases.iter().any(|(_, c)| c.partial) && cases.iter().any(|(_, c)| !c.partial));
    recovered
}

/// A batch that mixes the search with the default pipeline gives each cloud the fit its
/// own method gives it alone, in the order the clouds came.
#[test]
fn a_batch_mixing_methods_gives_each_cloud_its_own_fit() {
    use supertoroid::fit::{Method, fit_batch};
    let mut evaluator = CpuEvaluator::new();
    let clouds: Vec<(Vec<DVec3>, FitOptions)> = [
        (10_004, Method::Default),
        (10_006, Method::Paper),
        (10_010, Method::Default),
    ]
    .into_iter()
    .map(|(seed, method)| {
        let case = make_case(seed, false, 0.01, 0.05);
        (
            case.points,
            FitOptions {
                seed,
                method,
                ..Default::default()
            },
        )
    })
    .collect();
    let refs: Vec<(&[DVec3], &FitOptions)> =
        clouds.iter().map(|(p, o)| (p.as_slice(), o)).collect();
    let together = fit_batch(&mut evaluator, &refs).unwrap();
    assert_eq!(together.len(), 3);
    for ((points, options), batched) in clouds.iter().zip(together) {
        let batched = batched.unwrap();
        let alone = fit(&mut evaluator, points, options).unwrap();
        assert_eq!(batched.method, options.method);
        assert_eq!(batched.fitted.0, alone.fitted.0, "{:?}", options.method);
        assert_eq!(batched.fitted.1, alone.fitted.1, "{:?}", options.method);
    }
}

/// A viewpoint said to be none is none, even for a cloud that is a view from its origin.
#[test]
fn a_viewpoint_said_to_be_none_is_not_inferred() {
    let mut evaluator = CpuEvaluator::new();
    let case = make_case(10_009, true, 0.0, 0.0);
    let (points, _) = case.in_camera_frame().unwrap();
    let options = FitOptions {
        seed: 1,
        viewpoint: supertoroid::fit::Viewpoint::None,
        ..Default::default()
    };
    let report = fit(&mut evaluator, &points, &options).unwrap();
    assert_eq!(
        report.viewpoint.source,
        supertoroid::fit::ViewpointSource::None
    );
    assert!(report.viewpoint.position.is_none());
    assert!(report.quality.visible_coverage.is_none());
}

/// A fit's time adds up: the search's rounds (the noise model inside stage 2) and each
/// later stage make its total, for one model and for both weighed; a stage left out (`FitOptions::skip`) neither runs nor
/// appears.
#[test]
fn the_time_of_a_fit_is_accounted_for_by_stage() {
    use supertoroid::fit::ablation::Stage;
    let mut evaluator = CpuEvaluator::new();
    // a noisy single view with outliers: the noise model and the polish run on it
    let seed = 10_017;
    let case = suite_case(10_000, seed);
    let options = view_options(seed, &case, true);
    let report = fit(&mut evaluator, &case.points, &options).unwrap();
    let t = &report.timing_ms;
    assert!(t.noise_model > 0.0 && t.noise_model <= t.stage2, "{t:?}");
    // every millisecond belongs to a part, whatever else the machine was doing
    let adds_up = |t: &supertoroid::fit::Timing| {
        let parts = t.stage1 + t.stage2 + t.stages.values().sum::<f64>();
        assert!(
            (t.total - parts).abs() <= 1e-9 * t.total,
            "the parts {parts} ms against the total {} ms: {t:?}",
            t.total
        );
    };
    adds_up(t);
    assert!(t.stages.contains_key("polish-on-more-points"), "{t:?}");
    // both models fitted and weighed: the weighing is a part too
    let auto = fit(
        &mut evaluator,
        &case.points,
        &FitOptions {
            model: supertoroid::fit::Model::Auto,
            ..options.clone()
        },
    )
    .unwrap();
    assert!(auto.timing_ms.stages.contains_key("model_choice"));
    adds_up(&auto.timing_ms);
    let skipped = fit(
        &mut evaluator,
        &case.points,
        &FitOptions {
            skip: vec![Stage::PolishOnMorePoints],
            ..options
        },
    )
    .unwrap();
    assert!(
        !skipped
            .timing_ms
            .stages
            .contains_key("polish-on-more-points"),
        "{:?}",
        skipped.timing_ms
    );
}

/// A fit whose time has reached its budget (`FitOptions::time_budget_ms`) cuts its
/// search's likelihood refinements short and skips the polish, names both and warns; the
/// search's fit still comes back. A budget that is no positive number of milliseconds is
/// refused; one past what a clock holds is no budget (the same fit as none).
#[test]
fn a_spent_time_budget_cuts_the_search_short_leaves_the_polish_out_and_says_so() {
    let mut evaluator = CpuEvaluator::new();
    let seed = 10_017;
    let case = suite_case(10_000, seed);
    let options = FitOptions {
        time_budget_ms: Some(1e-3),
        ..view_options(seed, &case, true)
    };
    let report = fit(&mut evaluator, &case.points, &options).unwrap();
    let t = &report.timing_ms;
    assert!(!t.stages.contains_key("polish-on-more-points"), "{t:?}");
    assert!(
        t.over_budget.iter().any(|c| c == "polish-on-more-points"),
        "{t:?}"
    );
    assert!(t.over_budget.iter().any(|c| c == "search"), "{t:?}");
    assert!(
        report
            .warnings
            .iter()
            .any(|w| w.starts_with("cut short by the time budget")),
        "{:?}",
        report.warnings
    );
    assert!(report.shape.a1 > 0.0);
    let unbounded = fit(
        &mut evaluator,
        &case.points,
        &view_options(seed, &case, true),
    )
    .unwrap();
    let past_any_clock = fit(
        &mut evaluator,
        &case.points,
        &FitOptions {
            time_budget_ms: Some(1e300),
            ..view_options(seed, &case, true)
        },
    )
    .unwrap();
    assert_eq!(past_any_clock.fitted, unbounded.fitted);
    assert!(past_any_clock.timing_ms.over_budget.is_empty());
    assert!(
        unbounded
            .warnings
            .iter()
            .all(|w| !w.starts_with("cut short"))
    );
    for bad in [0.0, -5.0, f64::NAN] {
        let refused = fit(
            &mut evaluator,
            &case.points,
            &FitOptions {
                time_budget_ms: Some(bad),
                ..view_options(seed, &case, true)
            },
        );
        assert!(
            matches!(&refused, Err(FitError::InvalidOption(m)) if m.contains("time budget")),
            "{bad}: {:?}",
            refused.as_ref().err()
        );
    }
}

/// Seen by a sensor, the objective of `method=search` describes a view of a ring with a
/// pinched section (sharp rims, eps1 1.46) as well as the grid noise model does: at the
/// truth they agree within 0.01 nats per point. (When a cell across a rim was dropped
/// because its centre faced away, the rims lost half their density and the objective
/// trailed by 0.04.)
#[test]
fn the_objective_keeps_the_rims_of_a_pinched_section_seen_by_a_sensor() {
    use supertoroid::fit::{LIKELIHOOD_OUTLIER_WEIGHT, likelihood, objective};
    let case = make_case(420_137, true, 0.02, 0.0);
    assert!(case.shape.eps1 > 1.3, "{:?}", case.shape);
    let norm = Normalization::of(&case.points);
    let points = norm.points(&case.points);
    let viewpoint = norm.point(case.viewpoint.expect("a view"));
    let truth = norm.candidate(&case.shape, &case.pose);
    let sigma = case.noise * case.shape.size() / norm.scale;
    let sensor = objective::Sensor::new(&points, supertoroid::fit::Sight::at(viewpoint));
    let data = objective::Data {
        points: &points,
        outlier_weight: LIKELIHOOD_OUTLIER_WEIGHT,
        outlier_density: LIKELIHOOD_OUTLIER_WEIGHT / likelihood::outlier_volume(&points, 2e-3),
        sensor: Some(&sensor),
        device: None,
    };
    let new = objective::value(&data, &truth, sigma);
    let grid = likelihood::objective(
        &points,
        &truth,
        sigma,
        LIKELIHOOD_OUTLIER_WEIGHT,
        Some(supertoroid::fit::Sight::at(viewpoint)),
    )
    .expect("a ring");
    assert!(
        (new - grid).abs() < 0.01,
        "objective {new}, grid model {grid} (mean negative log-likelihood per point)"
    );
}

/// Case `seed` of the model-choice suite (`bench models`: even cases holed, odd ones
/// superellipsoids) posted as users post it (the camera's frame, no options) and fitted with
/// `model: auto`: its kind, the case, the fit, and the pose taking the fit back to the
/// case's frame.
fn auto_fit_of_model_case(
    evaluator: &mut CpuEvaluator,
    seed: u64,
) -> (
    supertoroid::suite::ground_truth::Kind,
    Case,
    FitReport,
    supertoroid::model::Pose,
) {
    fit_of_model_case(evaluator, seed, supertoroid::fit::Model::Auto)
}

/// [`auto_fit_of_model_case`] fitted with `model`.
fn fit_of_model_case(
    evaluator: &mut CpuEvaluator,
    seed: u64,
    model: supertoroid::fit::Model,
) -> (
    supertoroid::suite::ground_truth::Kind,
    Case,
    FitReport,
    supertoroid::model::Pose,
) {
    use supertoroid::bench::synthetic::{Presentation, category, presented};
    use supertoroid::suite::ground_truth::{Kind, make_case_of};
    let i = (seed % 1000) as usize;
    let kind = if i % 2 == 0 {
        Kind::Holed
    } else {
        Kind::Superellipsoid
    };
    let (partial, noise, outliers) = category(i / 2);
    let case = make_case_of(kind, seed, partial, noise, outliers);
    let (points, viewpoint, back) = presented(&case, Presentation::Camera);
    let options = FitOptions {
        seed,
        viewpoint,
        model,
        ..Default::default()
    };
    let r = fit(evaluator, &points, &options).unwrap();
    (kind, case, r, back)
}

/// `model: superellipsoid` refines a noisy view by the likelihood where any candidate it
/// kept is thin against the noise, as the free fit does where it kept a ring: least squares
/// reads a slab blurred by the noise as a thicker body. Cases of `bench models` 610000
/// that least squares sent into wrong basins: a 0.13 x 0.13 x 0.022 m disc (2% noise)
/// fitted as a 0.18 x 0.18 x 0.28 m blob, a 0.06 x 0.05 x 0.12 m bar (1%) 16% off.
#[test]
fn a_superellipsoid_fit_of_a_noisy_view_takes_the_likelihood_where_a_candidate_is_thin() {
    use supertoroid::fit::Model;
    use supertoroid::suite::chamfer::{CHAMFER_BOUND, relative_chamfer};
    use supertoroid::suite::ground_truth::Kind;
    let mut evaluator = CpuEvaluator::new();
    for seed in [610_095u64, 610_093] {
        let (kind, case, r, back) = fit_of_model_case(&mut evaluator, seed, Model::Superellipsoid);
        assert_eq!(kind, Kind::Superellipsoid);
        let estimator = &r.search.as_ref().expect("a searched fit").estimator;
        assert_eq!(estimator, "likelihood", "{seed}");
        let pose = back.compose(&r.fitted.1);
        let d = relative_chamfer((&case.shape, &case.pose), (&r.fitted.0, &pose));
        assert!(d < CHAMFER_BOUND, "{seed}: chamfer {d}");
    }
}

#[test]
fn auto_tells_rings_from_boxes_and_cans_on_single_views() {
    use supertoroid::bench::synthetic::category;
    use supertoroid::fit::Model;
    use supertoroid::suite::chamfer::{CHAMFER_BOUND, relative_chamfer};
    use supertoroid::suite::ground_truth::{Kind, make_case_of};
    // noisy single views of the model-choice suite
    let mut evaluator = CpuEvaluator::new();
    for seed in [600_021u64, 600_027, 600_022, 600_026] {
        let (partial, noise, _) = category((seed % 1000) as usize / 2);
        assert!(partial && noise > 0.0);
        let (kind, case, r, back) = auto_fit_of_model_case(&mut evaluator, seed);
        let pose = back.compose(&r.fitted.1);
        let bic = r.model.bic.expect("auto reports both scores");
        match kind {
            Kind::Holed => {
                assert_eq!(r.model.kind, Model::Supertoroid, "{seed}: {bic:?}");
                let e = compare((&case.shape, &case.pose), (&r.fitted.0, &pose));
                assert!(e.success(), "{seed}: {e:?}");
            }
            Kind::Superellipsoid => {
                assert_eq!(r.model.kind, Model::Superellipsoid, "{seed}: {bic:?}");
                assert_eq!(r.shape.a4, 0.0);
                let d = relative_chamfer((&case.shape, &case.pose), (&r.fitted.0, &pose));
                assert!(d < CHAMFER_BOUND, "{seed}: chamfer {d}");
            }
        }
        assert_eq!(r.model.chosen_by, "bic");
    }
    // a superellipsoid cannot have a hole
    let case = make_case_of(Kind::Holed, 600_000, false, 0.0, 0.0);
    let options = FitOptions {
        model: Model::Superellipsoid,
        known_shape: [None, None, None, Some(2.0), None, None],
        ..Default::default()
    };
    assert!(matches!(
        fit(&mut evaluator, &case.points, &options),
        Err(supertoroid::fit::FitError::InvalidOption(_))
    ));
}

/// A view of a box fitted by `model: superellipsoid` tries the likeliest candidate with its
/// axes cycled too (`starts::axes_cycled`): cases of `bench models` 610000 and 620000 whose
/// search settled on a body with the wrong axis as its z (chamfer 5.8% and 9.7%).
#[test]
fn a_superellipsoid_fit_tries_its_best_candidate_with_its_axes_cycled() {
    use supertoroid::fit::Model;
    use supertoroid::suite::chamfer::{CHAMFER_BOUND, relative_chamfer};
    let mut evaluator = CpuEvaluator::new();
    for seed in [610_057u64, 620_057] {
        let (_, case, r, back) = fit_of_model_case(&mut evaluator, seed, Model::Superellipsoid);
        let pose = back.compose(&r.fitted.1);
        let d = relative_chamfer((&case.shape, &case.pose), (&r.fitted.0, &pose));
        assert!(d < CHAMFER_BOUND, "{seed}: chamfer {d}");
    }
}

/// `model: auto` weighs the two fits of a cloud by their likelihood, so both are refined by
/// it where either is: a superellipsoid fit that least squares left short of its
/// likelihood's maximum lost to a supertoroid the likelihood refined. Cases of the fresh
/// model-choice set 670000 that the superellipsoid fit refined by least squares lost (two
/// boxes' views taken for rings, and a full ring's cloud taken for a blob).
#[test]
fn both_models_of_a_cloud_are_weighed_at_their_likelihoods_maximum() {
    use supertoroid::fit::Model;
    use supertoroid::suite::ground_truth::Kind;
    let mut evaluator = CpuEvaluator::new();
    for seed in [670_063u64, 670_165, 670_010] {
        let (kind, _, r, _) = auto_fit_of_model_case(&mut evaluator, seed);
        let want = match kind {
            Kind::Holed => Model::Supertoroid,
            Kind::Superellipsoid => Model::Superellipsoid,
        };
        assert_eq!(r.model.kind, want, "{seed}: {:?}", r.model.bic);
        let estimator = &r.search.as_ref().expect("a searched fit").estimator;
        assert_eq!(estimator, "likelihood", "{seed}");
    }
}

/// A box whose free fit (an apple, its dimple under the noise) beats its superellipsoid fit
/// by less than positive evidence (`model_choice::MIN_EVIDENCE`) stays a superellipsoid:
/// the one such case of the model-choice sets 610000-680000 (a BIC margin of 0.8).
#[test]
fn a_free_fit_a_hair_likelier_does_not_make_a_box_an_apple() {
    use supertoroid::fit::Model;
    use supertoroid::fit::model_choice::MIN_EVIDENCE;
    use supertoroid::suite::ground_truth::Kind;
    let mut evaluator = CpuEvaluator::new();
    for seed in [680_083u64] {
        let (kind, _, r, _) = auto_fit_of_model_case(&mut evaluator, seed);
        assert_eq!(kind, Kind::Superellipsoid);
        let bic = r.model.bic.expect("auto reports both scores");
        let supertoroid = bic.supertoroid.expect("the free fit kept a dimple");
        // the free fit is the likelier, by less than the evidence asked for
        assert!(
            supertoroid < bic.superellipsoid && supertoroid + MIN_EVIDENCE > bic.superellipsoid,
            "{seed}: {bic:?}"
        );
        assert_eq!(r.model.kind, Model::Superellipsoid, "{seed}: {bic:?}");
    }
}

/// The broadened suite's CI subset (`suite::broad`): twelve views, three of each family
/// (the suite's ranges, tall rolls, thin washers, oval rings) through the D435-like
/// sensor, half with outliers over the scene's box, fitted with no options in the
/// camera's frame. `supertoroid bench broad` runs the full benchmark, where the fit gets
/// about four views in five (seeds 2000000, 2100000, 2900000 and 3000000); these twelve
/// give 8 (6 with the estimator judged on the likeliest candidate alone, which reads a
/// thin washer's blurred section as a thick precise one), and the solver's basin choices
/// have moved such a count by one or two, so 7 are asked.
#[test]
fn broadened_views_through_a_depth_sensor_are_fitted_with_no_options() {
    use supertoroid::suite::broad::{FAMILIES, view};
    let mut evaluator = CpuEvaluator::new();
    let mut right = 0;
    for seed in 2_400_000..2_400_012 {
        let case = view(seed);
        let options = FitOptions {
            seed,
            ..Default::default()
        };
        let report = fit(&mut evaluator, &case.points, &options).expect("a fit");
        let errors = compare(
            (&case.shape, &case.pose),
            (&report.fitted.0, &report.fitted.1),
        );
        eprintln!("{seed} ({}): {errors:?}", FAMILIES[(seed % 4) as usize]);
        right += usize::from(errors.success());
    }
    assert!(right >= 7, "{right} of 12 right (7 asked)");
}

/// A single view in its camera's frame is searched as a view and from nowhere; the
/// reading from nowhere rests on its points covering the object all round, so where they
/// cover less than `LIKELIHOOD_MIN_COVERAGE` of its likeliest round-1 candidate (as a
/// view's points do) and it is no likelier than the view, it goes no further than round 1. Twelve of the suite's views with noise
/// and outliers: every one fitted as a view, at least six with the other reading stopped
/// after round 1 (the rest go on until the likelihood tells them apart after round 2),
/// and at least eleven within tolerance (measured when written: 7 stopped, 1 without the
/// coverage cut; 12 right).
#[test]
fn a_views_reading_from_nowhere_that_its_points_do_not_cover_stops_after_round_one() {
    use supertoroid::fit::ViewpointSource;
    let mut evaluator = CpuEvaluator::new();
    let (mut right, mut stopped) = (0, 0);
    for (i, (noise, outliers)) in [(0.01, 0.0), (0.02, 0.05), (0.0, 0.1)]
        .into_iter()
        .cycle()
        .take(12)
        .enumerate()
    {
        let seed = 40 + i as u64;
        let case = make_case(seed, true, noise, outliers);
        let (_, r, pose) = fitted_as_posted(&mut evaluator, &case, seed);
        assert_eq!(
            r.viewpoint.source,
            ViewpointSource::FrameOrigin,
            "seed {seed}"
        );
        let s = r.search.as_ref().expect("the default method searches");
        stopped += usize::from(s.other_reading_went_to.as_deref() == Some("round 1"));
        right += usize::from(compare((&case.shape, &case.pose), (&r.fitted.0, &pose)).success());
    }
    assert!(
        stopped >= 6,
        "only {stopped} of 12 views' other readings stopped after round 1"
    );
    assert!(right >= 11, "{right} of 12 right");
}

/// The report says what the search tried and kept: a noisy single view in its camera's
/// frame is read both as a view and from nowhere (the report says how far the reading
/// not taken went) and refined by the likelihood; a precise full cloud said to be seen
/// from nowhere is read one way and refined by least squares; the paper's method does
/// not search.
#[test]
fn the_report_says_what_the_search_tried_and_kept() {
    use supertoroid::fit::{Method, Viewpoint};
    let mut evaluator = CpuEvaluator::new();
    let case = make_case(7, true, 0.02, 0.0);
    let (_, r, _) = fitted_as_posted(&mut evaluator, &case, 7);
    let s = r.search.expect("the default method searches");
    assert!(
        s.starts >= s.kept && s.kept >= 1 && s.refined >= s.kept,
        "{s:?}"
    );
    assert_eq!(s.estimator, "likelihood", "{s:?}");
    assert!((1..=2).contains(&s.finalists), "{s:?}");
    assert!(
        matches!(
            s.other_reading_went_to.as_deref(),
            Some("round 1" | "round 2" | "finalists")
        ),
        "{s:?}"
    );

    let case = make_case(8, false, 0.0, 0.0);
    let options = FitOptions {
        seed: 8,
        viewpoint: Viewpoint::None,
        ..Default::default()
    };
    let r = fit(&mut evaluator, &case.points, &options).unwrap();
    let s = r.search.expect("the default method searches");
    assert_eq!(s.estimator, "least_squares", "{s:?}");
    assert_eq!(s.finalists, 0, "{s:?}");
    assert_eq!(s.other_reading_went_to, None, "{s:?}");

    let options = FitOptions {
        method: Method::Paper,
        ..options
    };
    assert!(
        fit(&mut evaluator, &case.points, &options)
            .unwrap()
            .search
            .is_none()
    );
}

/// docs/constants.md lists every numeric constant of `src/fit` and `src/solve/mod.rs` (the
/// fit's tuning constants, in one place) under the file that defines it, with its value
/// as written there; a constant added, removed, renamed or retuned without the table
/// fails here.
#[test]
fn every_tuning_constant_of_the_fit_is_in_docs_constants_md() {
    use std::collections::BTreeSet;
    use std::path::{Path, PathBuf};
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    fn sources(dir: &Path, out: &mut Vec<PathBuf>) {
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                sources(&path, out);
            } else if path.extension().is_some_and(|e| e == "rs") {
                out.push(path);
            }
        }
    }
    let mut files = Vec::new();
    sources(&root.join("src/fit"), &mut files);
    files.push(root.join("src/solve/mod.rs"));
    files.push(root.join("src/solve/likelihood.rs"));
    // module-level `[pub[(..)]] const NAME: TYPE = VALUE;` with a numeric VALUE
    let numeric = |v: &str| {
        v.chars()
            .all(|c| c.is_ascii_digit() || ".e-+_[](), ".contains(c))
    };
    let mut in_sources = BTreeSet::new();
    for file in &files {
        let rel = file
            .strip_prefix(root)
            .unwrap()
            .to_string_lossy()
            .to_string();
        for line in std::fs::read_to_string(file).unwrap().lines() {
            let rest = [
                "pub const ",
                "pub(crate) const ",
                "pub(super) const ",
                "const ",
            ]
            .iter()
            .find_map(|p| line.strip_prefix(p));
            let Some((name, rest)) = rest.and_then(|r| r.split_once(':')) else {
                continue;
            };
            let Some((_, value)) = rest.split_once(" = ") else {
                continue;
            };
            let value = value.trim_end_matches(';');
            if numeric(value) {
                in_sources.insert((rel.clone(), name.to_string(), value.to_string()));
            }
        }
    }
    assert!(
        in_sources.len() > 50,
        "the scan found only {} constants",
        in_sources.len()
    );
    let table = std::fs::read_to_string(root.join("docs/constants.md")).unwrap();
    let mut in_table = BTreeSet::new();
    let mut file = String::new();
    for line in table.lines() {
        if let Some(heading) = line.strip_prefix("## `") {
            file = heading.trim_end_matches('`').to_string();
        } else if let Some(row) = line.strip_prefix("| `") {
            let cells: Vec<&str> = row.split(" | ").collect();
            in_table.insert((
                file.clone(),
                cells[0].trim_end_matches('`').to_string(),
                cells[1].trim_matches('`').to_string(),
            ));
        }
    }
    let missing: Vec<_> = in_sources.difference(&in_table).collect();
    let stale: Vec<_> = in_table.difference(&in_sources).collect();
    assert!(
        missing.is_empty() && stale.is_empty(),
        "docs/constants.md is out of date: not in it {missing:?}; not in the sources {stale:?}"
    );
}

/// Noise-free views left in a wrong basin a little past where `off a precise cloud`
/// stops (the suite's 90099 and 140030, as users post them: their hole axes came out 90
/// degrees off, 1.1e-3 and 2.0e-3 of their size from their points, when this was
/// written): a fit off the truth must not come out unwarned, and past the precise band
/// it is warned `off its points`.
#[test]
fn a_noise_free_view_a_little_off_its_points_is_not_a_confident_answer() {
    use supertoroid::bench::synthetic::category;
    let mut evaluator = CpuEvaluator::new();
    for (first, seed) in [(90_000u64, 90_099u64), (140_000, 140_030)] {
        let (partial, noise, outliers) = category((seed - first) as usize);
        assert_eq!((partial, noise), (true, 0.0));
        let case = make_case(seed, partial, noise, outliers);
        let (_, report, pose) = fitted_as_posted(&mut evaluator, &case, seed);
        let right = compare((&case.shape, &case.pose), (&report.fitted.0, &pose)).success();
        let relative = report.quality.median_distance / report.fitted.0.size();
        eprintln!(
            "{seed}: right {right}, median {relative:.1e} of the size, {:?}",
            report.warnings
        );
        assert!(
            right || !report.warnings.is_empty(),
            "{seed}: wrong and unwarned"
        );
        // a noise-free cloud's scatter is its surface's curvature alone: a wrong basin
        // past the precise band stands far over it
        if !right && relative >= supertoroid::fit::PRECISE_MISFIT.end {
            assert!(
                warned_off_its_points(&report),
                "{seed}: {:?}",
                report.warnings
            );
        }
    }
}

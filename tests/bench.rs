//! The benchmark harness on small settings: every sub-bench runs and writes JSON with
//! every field, CSV and markdown; the Good / Decent / Bad rule grades a ground-truth fit
//! Good and a planted bad fit Bad.

use glam::{DQuat, DVec3};
use serde_json::Value;
use std::process::Command;
use supertoroid::bench::paper::{Grade, grade_fit};
use supertoroid::model::{Pose, Shape};

fn out_dir(name: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("supertoroid-bench-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// `supertoroid bench ARGS --out OUT`, its output whatever the exit.
fn run_bench(args: &[&str], out: &std::path::Path) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_supertoroid"))
        .arg("bench")
        .args(args)
        .args(["--out", out.to_str().unwrap()])
        .output()
        .unwrap()
}

fn bench(args: &[&str], out: &std::path::Path, name: &str) -> Value {
    let o = run_bench(args, out);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let md = std::fs::read_to_string(out.join(format!("{name}.md"))).unwrap();
    assert!(md.contains("Machine:") && md.contains('|'), "{md}");
    assert_eq!(String::from_utf8_lossy(&o.stdout).trim(), md.trim());
    let csv = std::fs::read_to_string(out.join(format!("{name}.csv"))).unwrap();
    assert!(csv.lines().count() >= 2);
    serde_json::from_str(&std::fs::read_to_string(out.join(format!("{name}.json"))).unwrap())
        .unwrap()
}

fn has(v: &Value, keys: &[&str]) {
    for k in keys {
        assert!(!v[*k].is_null(), "missing {k} in {v}");
    }
}

#[test]
fn bench_paper_writes_the_table_with_every_field() {
    let out = out_dir("paper");
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/clouds/paper");
    let v = bench(
        &[
            "paper",
            dir,
            "--runs",
            "2",
            "--backend",
            "cpu",
            "--render",
            "pictures",
        ],
        &out,
        "paper",
    );
    has(
        &v["machine"],
        &["cpu", "cores", "adapter", "git_revision", "version"],
    );
    has(&v, &["backend", "rule", "median_total_ms"]);
    let clouds = v["clouds"].as_array().unwrap();
    assert_eq!(clouds.len(), 4);
    for c in clouds {
        has(
            c,
            &[
                "cloud",
                "points",
                "good",
                "decent",
                "bad",
                "t_stage1_ms",
                "t_stage2_ms",
                "t_total_ms",
                "s_total_ms",
                "median_relative_rms",
                "centre_spread",
                "axis_spread_deg",
                "paper",
            ],
        );
        let n = ["good", "decent", "bad"]
            .iter()
            .map(|k| c[*k].as_u64().unwrap())
            .sum::<u64>();
        assert_eq!(n, 2);
        assert!(c["t_total_ms"].as_f64().unwrap() > 0.0);
    }
    assert_eq!(v["runs"].as_array().unwrap().len(), 8);
    // one picture per cloud, embedded in the markdown
    let md = std::fs::read_to_string(out.join("paper.md")).unwrap();
    let pictures = v["pictures"].as_array().unwrap();
    assert_eq!(pictures.len(), 4);
    for p in pictures {
        let name = p.as_str().unwrap();
        assert!(name.starts_with("pictures/"), "{name}");
        assert!(out.join(name).is_file(), "{name}");
        assert!(md.contains(&format!("]({name})")), "{name} not embedded");
    }
    let csv = std::fs::read_to_string(out.join("paper.csv")).unwrap();
    assert_eq!(csv.lines().count(), 9);
}

#[test]
fn bench_synthetic_runs_several_seed_sets_as_one_report() {
    let out = out_dir("synthetic-sets");
    let v = bench(
        &[
            "synthetic",
            "--cases",
            "2",
            "--seed",
            "10000,20000",
            "--backend",
            "cpu",
        ],
        &out,
        "synthetic",
    );
    // each set's cases from its own first seed, in the categories of their place in it
    let cases = v["cases"].as_array().unwrap();
    let seeds: Vec<u64> = cases.iter().map(|c| c["seed"].as_u64().unwrap()).collect();
    assert_eq!(seeds, [10000, 10001, 20000, 20001]);
    assert_eq!(cases[0]["noise"], cases[2]["noise"]);
    assert_eq!(cases[1]["noise"], cases[3]["noise"]);
    let sets = v["sets"].as_array().unwrap();
    assert_eq!(sets.len(), 2);
    let md = std::fs::read_to_string(out.join("synthetic.md")).unwrap();
    for (k, set) in sets.iter().enumerate() {
        assert_eq!(set["seed"].as_u64(), Some(seeds[2 * k]));
        assert_eq!(set["cases"].as_u64(), Some(2));
        let successes = cases[2 * k..2 * k + 2]
            .iter()
            .filter(|c| c["success"] == true)
            .count();
        assert_eq!(set["successes"].as_u64(), Some(successes as u64));
        let row = format!("| {} | 2 | {successes}/2 ", seeds[2 * k]);
        assert!(md.contains(&row), "{row} not in {md}");
    }
    // the overall rate lies inside its interval, which lies inside [0, 1]
    let rate = v["overall_rate"].as_f64().unwrap();
    let interval: Vec<f64> = v["overall_interval"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    assert!(0.0 <= interval[0] && interval[0] <= rate && rate <= interval[1] && interval[1] <= 1.0);
    assert!(md.contains("95% interval"), "{md}");
}

/// `--from-truth`: every case is also refined from its true parameters by the fit's
/// estimator, noise-free ones count as within, and the set's and overall figures count
/// those outcomes; without the flag the fields are null.
#[test]
fn bench_synthetic_from_truth_reports_the_estimators_ceiling() {
    let out = out_dir("synthetic-truth");
    // cases 10000-10002: full clouds, noise 0, 1, 2% of the size
    let args = [
        "synthetic",
        "--cases",
        "3",
        "--backend",
        "cpu",
        "--from-truth",
    ];
    let v = bench(&args, &out, "synthetic");
    let cases = v["cases"].as_array().unwrap();
    let outcomes: Vec<bool> = cases
        .iter()
        .map(|c| c["from_truth"].as_bool().expect("from_truth on every case"))
        .collect();
    assert!(outcomes[0], "a noise-free case counts as within");
    let within = outcomes.iter().filter(|&&ok| ok).count();
    assert_eq!(
        v["sets"][0]["from_truth_successes"].as_u64(),
        Some(within as u64)
    );
    let rate = v["from_truth_overall_rate"].as_f64().unwrap();
    assert!((rate - within as f64 / 3.0).abs() < 1e-12);
    let md = std::fs::read_to_string(out.join("synthetic.md")).unwrap();
    assert!(md.contains("| from the truth |"), "{md}");
    assert!(md.contains(&format!("| {within}/3 (")), "{md}");
    let csv = std::fs::read_to_string(out.join("synthetic.csv")).unwrap();
    assert!(csv.lines().next().unwrap().ends_with(",from_truth"));
    assert!(csv.lines().nth(1).unwrap().ends_with(",true"));

    let plain = bench(&args[..5], &out, "synthetic");
    assert!(plain["cases"][0]["from_truth"].is_null());
    assert!(plain["from_truth_overall_rate"].is_null());
    assert!(plain["sets"][0]["from_truth_successes"].is_null());
}

#[test]
fn bench_synthetic_and_scaling_write_every_field() {
    let out = out_dir("synthetic");
    let v = bench(
        &[
            "synthetic",
            "--cases",
            "5",
            "--backend",
            "cpu",
            "--render",
            "shots",
        ],
        &out,
        "synthetic",
    );
    has(
        &v,
        &[
            "machine",
            "backend",
            "sets",
            "overall_rate",
            "overall_interval",
            "partial_with_outliers_interval",
            "full_rate",
            "partial_rate",
            "partial_with_outliers_rate",
            "errors_full",
            "errors_partial",
            "by_noise_ratio",
            "by_warning",
            "full_pose_rate",
            "partial_pose_rate",
        ],
    );
    let cases = v["cases"].as_array().unwrap();
    assert_eq!(cases.len(), 5);
    // every case falls in one noise-ratio band per cloud kind
    let total = |key: &str| {
        v[key]
            .as_array()
            .unwrap()
            .iter()
            .map(|b| b["cases"].as_u64().unwrap())
            .sum::<u64>()
    };
    assert_eq!(total("by_noise_ratio"), 5);
    assert_eq!(v["by_warning"].as_array().unwrap().len(), 10);
    for c in cases {
        has(
            c,
            &[
                "seed",
                "partial",
                "noise",
                "outliers",
                "success",
                "centre",
                "axis_degrees",
                "sizes",
                "a4",
                "eps",
                "t_total_ms",
                "t_stage1_ms",
                "t_stage2_ms",
                "t_noise_model_ms",
                "t_polish_ms",
                "noise_ratio",
                "refused",
                "uncertain_warning",
                "misfit_warning",
                "off_points_warning",
                "median_over_size",
                "median_over_scatter",
                "attainable",
                "warned",
            ],
        );
        // the stages' times are parts of the fit's: the noise model of stage 2, and stage 1,
        // stage 2 and the polish of the total
        let ms = |key: &str| c[key].as_f64().unwrap();
        assert!(ms("t_stage1_ms") > 0.0 && ms("t_stage2_ms") > 0.0, "{c}");
        assert!(
            (0.0..=ms("t_stage2_ms")).contains(&ms("t_noise_model_ms")),
            "{c}"
        );
        assert!(ms("t_polish_ms") >= 0.0, "{c}");
        let parts = ms("t_stage1_ms") + ms("t_stage2_ms") + ms("t_polish_ms");
        assert!(parts <= ms("t_total_ms") + 1e-6, "{c}");
        // the shape's standard errors over their tolerances (null where there are none),
        // and the uncertain-shape warning among the warnings
        let uncertainty = c["uncertainty"].as_f64();
        assert!(uncertainty.is_none_or(|u| u >= 0.0), "{c}");
        if c["uncertain_warning"] == true {
            assert_eq!(c["warned"], true, "{c}");
            assert!(
                uncertainty.is_some_and(|u| u >= supertoroid::fit::uncertainty::WARNING_SHARE),
                "{c}"
            );
        }
        // the two misfit warnings tile the median distances above rounding
        let median = c["median_over_size"].as_f64().unwrap();
        let band = supertoroid::fit::PRECISE_MISFIT;
        assert_eq!(c["misfit_warning"] == true, band.contains(&median), "{c}");
        if c["off_points_warning"] == true {
            assert!(median >= band.end && c["warned"] == true, "{c}");
        }
        // the efficient estimator's share (`suite::attainable`): a probability, and
        // certain on a noise-free cloud
        let attainable = c["attainable"].as_f64().unwrap();
        assert!((0.0..=1.0).contains(&attainable), "{attainable}");
        if c["noise"].as_f64() == Some(0.0) {
            assert_eq!(attainable, 1.0);
        }
        // the share of the visible surface with points: only single views have one
        match c["visible_coverage"].as_f64() {
            Some(coverage) => {
                assert!(
                    c["partial"] == true && (0.0..=1.0).contains(&coverage),
                    "{c}"
                )
            }
            None => assert!(
                c["partial"] == false && c["visible_coverage"].is_null(),
                "{c}"
            ),
        }
    }
    let overall = v["attainable_overall_rate"].as_f64().unwrap();
    assert!((0.0..=1.0).contains(&overall), "{overall}");
    assert_eq!(v["categories"].as_array().unwrap().len(), 5);
    png_with_content(&out.join("synthetic-errors.png"), 5 * 300, 300);
    let failures = cases.iter().filter(|c| c["success"] == false).count();
    let shots = v["pictures"].as_array().unwrap();
    assert_eq!(shots.len(), failures.min(6));
    for p in shots {
        assert!(out.join(p.as_str().unwrap()).is_file());
    }

    let out = out_dir("scaling");
    let v = bench(
        &[
            "scaling",
            "--points",
            "500,2000",
            "--candidates",
            "1,4",
            "--backends",
            "cpu,gpu",
            "--budget",
            "0.05",
        ],
        &out,
        "scaling",
    );
    let cells = v["cells"].as_array().unwrap();
    assert_eq!(cells.len(), 8);
    for c in cells {
        has(
            c,
            &[
                "backend",
                "points",
                "candidates",
                "time_ms",
                "point_jacobians_per_s",
                "samples",
            ],
        );
        assert!(c["time_ms"]["median"].as_f64().unwrap() > 0.0);
    }
    assert!(
        cells
            .iter()
            .any(|c| c["backend"].as_str().unwrap().starts_with("gpu"))
    );
    png_with_content(&out.join("scaling.png"), 2 * 360, 360);
    assert!(
        std::fs::read_to_string(out.join("scaling.md"))
            .unwrap()
            .contains("](scaling.png)")
    );
}

/// A PNG of the given size with lines on it (not blank).
fn png_with_content(path: &std::path::Path, width: u32, height: u32) {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(
        (info.width, info.height),
        (width, height),
        "{}",
        path.display()
    );
    let coloured = buf[..info.buffer_size()]
        .chunks_exact(3)
        .filter(|p| p[0] != p[1] || p[1] != p[2])
        .count();
    assert!(
        coloured > 500,
        "{}: {coloured} coloured pixels",
        path.display()
    );
}

#[test]
fn the_grading_rule_calls_the_truth_good_and_a_planted_fit_bad() {
    let shape = Shape::new(0.05, 0.045, 0.02, 2.0, 0.8, 1.1);
    let pose = Pose::new(DQuat::from_rotation_y(0.4), DVec3::new(0.1, 0.0, 0.6));
    let mut rng = supertoroid::synth::rng(3);
    let mut points = supertoroid::synth::sample_surface(&shape, &pose, 2000, &mut rng);
    supertoroid::synth::add_noise(&mut points, 0.005 * shape.size(), &mut rng);
    let size = shape.size();
    let truth = grade_fit(
        &points,
        (&shape, &pose),
        pose.translation,
        pose.axis(),
        size,
    );
    assert_eq!(truth.grade, Grade::Good, "{truth:?}");
    // the same shape, shifted by a fifth of its size and tilted 30 degrees
    let planted = Pose::new(
        DQuat::from_rotation_x(0.52) * pose.rotation,
        pose.translation + DVec3::new(0.2 * size, 0.0, 0.0),
    );
    let bad = grade_fit(
        &points,
        (&shape, &planted),
        pose.translation,
        pose.axis(),
        size,
    );
    assert_eq!(bad.grade, Grade::Bad, "{bad:?}");
    // a right surface that disagrees with the consensus of the other runs is not Good
    let far = grade_fit(
        &points,
        (&shape, &pose),
        pose.translation + DVec3::X * 0.1 * size,
        pose.axis(),
        size,
    );
    assert_eq!(far.grade, Grade::Decent, "{far:?}");
}

#[test]
fn bench_models_judges_the_choice_between_supertoroid_and_superellipsoid() {
    let out = out_dir("models");
    let v = bench(
        &[
            "models",
            "--cases",
            "4",
            "--seed",
            "600000",
            "--backend",
            "cpu",
        ],
        &out,
        "models",
    );
    assert_eq!(v["model"], "auto");
    let cases = v["cases"].as_array().unwrap();
    assert_eq!(cases.len(), 4);
    // even cases holed, odd ones superellipsoids; full noise-free clouds, all right
    for (i, c) in cases.iter().enumerate() {
        has(
            c,
            &[
                "seed",
                "chosen",
                "model_right",
                "success",
                "chamfer",
                "t_total_ms",
                "warned",
            ],
        );
        let kind = if i % 2 == 0 {
            "holed"
        } else {
            "superellipsoid"
        };
        assert_eq!(c["kind"], kind, "{c}");
        assert_eq!(c["success"], true, "{c}");
    }
    // one model asked for: no choice made, no margin
    let v = bench(
        &[
            "models",
            "--cases",
            "4",
            "--seed",
            "600000",
            "--backend",
            "cpu",
            "--model",
            "supertoroid",
        ],
        &out,
        "models",
    );
    assert_eq!(v["model"], "supertoroid");
    for c in v["cases"].as_array().unwrap() {
        assert!(c["margin"].is_null(), "{c}");
    }
    let auto = std::fs::read_to_string(out.join("models.csv")).unwrap();
    assert!(auto.lines().count() == 5, "{auto}");
    assert!(auto.starts_with("seed,") && auto.lines().next().unwrap().ends_with(",warned"));
    let md = std::fs::read_to_string(out.join("models.md")).unwrap();
    assert!(md.contains("Warnings: "), "{md}");
}

#[test]
fn bench_broad_judges_each_view_and_places_each_miss() {
    let out = out_dir("broad");
    let v = bench(
        &[
            "broad",
            "--cases",
            "2",
            "--seed",
            "2000003",
            "--backend",
            "cpu",
        ],
        &out,
        "broad",
    );
    let cases = v["cases"].as_array().unwrap();
    assert_eq!(cases.len(), 2);
    // seed % 4 is the family: an oval ring, then the suite's own ranges
    assert_eq!(cases[0]["family"], "oval rings");
    assert_eq!(cases[1]["family"], "suite ranges");
    for c in cases {
        has(
            c,
            &["seed", "success", "uncertainty", "t_total_ms", "warnings"],
        );
        // what an efficient estimator of the view would get right: a share
        let attainable = c["attainable"].as_f64().unwrap();
        assert!((0.0..=1.0).contains(&attainable), "{c}");
        // a miss, and only a miss, is placed: the search's, the estimator's or unscored
        let placed = c["miss"].as_str();
        assert_eq!(placed.is_some(), c["success"] == false, "{c}");
        assert!(
            placed.is_none_or(|m| ["search", "estimator", "unscored"].contains(&m)),
            "{c}"
        );
    }
    let csv = std::fs::read_to_string(out.join("broad.csv")).unwrap();
    assert_eq!(csv.lines().count(), 3, "{csv}");
    let md = std::fs::read_to_string(out.join("broad.md")).unwrap();
    assert!(md.contains("| all | ") && md.contains("Misses: "), "{md}");
    assert!(md.contains("What the views allow"), "{md}");
}

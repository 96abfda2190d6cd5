//! The command line end to end: real processes, real files.

use std::process::Command;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_supertoroid"))
}

fn tmp(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("supertoroid-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

/// `supertoroid fit --backend cpu ARGS CLOUD`, which must succeed: its JSON and its stderr.
fn fit_json(args: &[&str], cloud: &std::path::Path) -> (serde_json::Value, String) {
    let out = bin()
        .args(["fit", "--backend", "cpu"])
        .args(args)
        .arg(cloud)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{args:?}: {stderr}");
    (serde_json::from_slice(&out.stdout).unwrap(), stderr)
}

const SHAPE: &str = "0.05,0.04,0.02,2.2,0.7,1.2";

#[test]
fn sample_then_distance_is_zero_without_noise_and_not_with_it() {
    for (view, noise) in [(false, "0"), (true, "0"), (false, "0.02")] {
        let out = tmp(&format!("s-{view}-{noise}.xyz"));
        let mut cmd = bin();
        cmd.args([
            "sample",
            "--shape",
            SHAPE,
            "--translation",
            "0.3,-0.1,0.8",
            "--quaternion",
            "0.8,0.2,-0.3,0.1",
        ]);
        cmd.args([
            "--points",
            "500",
            "--noise",
            noise,
            "--seed",
            "4",
            "-o",
            out.to_str().unwrap(),
        ]);
        if view {
            cmd.arg("--view");
        }
        let status = cmd.status().unwrap();
        assert!(status.success());
        let text = std::fs::read_to_string(&out).unwrap();
        assert_eq!(text.lines().count(), 500);
        let d = bin()
            .args([
                "distance",
                "--shape",
                SHAPE,
                "--translation",
                "0.3,-0.1,0.8",
                "--quaternion",
                "0.8,0.2,-0.3,0.1",
            ])
            .arg(&out)
            .output()
            .unwrap();
        assert!(d.status.success(), "{}", String::from_utf8_lossy(&d.stderr));
        let distances: Vec<f64> = String::from_utf8(d.stdout)
            .unwrap()
            .lines()
            .map(|l| l.parse().unwrap())
            .collect();
        assert_eq!(distances.len(), 500);
        let max = distances.iter().cloned().fold(0.0, f64::max);
        if noise == "0" {
            assert!(max < 1e-9, "max distance {max}");
        } else {
            assert!(max > 1e-4, "noise did not move the points");
        }
    }
}

#[test]
fn ply_output_has_a_header_and_binary_body() {
    let out = tmp("s.ply");
    assert!(
        bin()
            .args([
                "sample",
                "--shape",
                SHAPE,
                "--points",
                "100",
                "-o",
                out.to_str().unwrap()
            ])
            .status()
            .unwrap()
            .success()
    );
    let bytes = std::fs::read(&out).unwrap();
    let header_end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap()
        + 11;
    assert!(String::from_utf8_lossy(&bytes[..header_end]).contains("element vertex 100"));
    assert_eq!(bytes.len() - header_end, 100 * 12);
}

#[test]
fn bad_input_gives_one_line_and_exit_code_2() {
    let bad_file = tmp("bad.xyz");
    std::fs::write(&bad_file, "1 2 3\n4 nan 6\n").unwrap();
    let empty = tmp("empty.xyz");
    std::fs::write(&empty, "").unwrap();
    let cases: Vec<Vec<String>> = vec![
        vec![
            "distance".into(),
            "--shape".into(),
            "1,2,3".into(),
            bad_file.display().to_string(),
        ],
        vec![
            "distance".into(),
            "--shape".into(),
            "1,1,1,2,1,-1".into(),
            bad_file.display().to_string(),
        ],
        vec![
            "distance".into(),
            "--shape".into(),
            SHAPE.into(),
            bad_file.display().to_string(),
        ],
        vec![
            "distance".into(),
            "--shape".into(),
            SHAPE.into(),
            empty.display().to_string(),
        ],
        vec![
            "distance".into(),
            "--shape".into(),
            SHAPE.into(),
            "/nonexistent/cloud.xyz".into(),
        ],
        vec![
            "sample".into(),
            "--shape".into(),
            SHAPE.into(),
            "--quaternion".into(),
            "0,0,0,0".into(),
            "-o".into(),
            "/tmp/x.xyz".into(),
        ],
        vec![
            "sample".into(),
            "--shape".into(),
            SHAPE.into(),
            "-o".into(),
            "/tmp/x.unknown".into(),
        ],
    ];
    for args in cases {
        let out = bin().args(&args).output().unwrap();
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            stderr.starts_with("error: ") && stderr.trim().lines().count() == 1,
            "{args:?}: {stderr}"
        );
    }
}

#[test]
fn distance_on_the_gpu_matches_the_cpu() {
    let out = tmp("g.xyz");
    assert!(
        bin()
            .args([
                "sample",
                "--shape",
                SHAPE,
                "--points",
                "300",
                "--noise",
                "0.05",
                "--seed",
                "9",
                "-o",
                out.to_str().unwrap()
            ])
            .status()
            .unwrap()
            .success()
    );
    let run = |backend: &str| -> Vec<f64> {
        let o = bin()
            .args(["distance", "--shape", SHAPE, "--backend", backend])
            .arg(&out)
            .env("WGPU_BACKEND", "vulkan")
            .output()
            .unwrap();
        assert!(
            o.status.success(),
            "{backend}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        String::from_utf8(o.stdout)
            .unwrap()
            .lines()
            .map(|l| l.parse().unwrap())
            .collect()
    };
    let (cpu, gpu) = (run("cpu"), run("gpu"));
    assert_eq!(cpu.len(), 300);
    let size = 0.05f64.hypot(0.04) * 3.2;
    for (a, b) in cpu.iter().zip(&gpu) {
        assert!((a - b).abs() < 1e-4 * size, "{a} vs {b}");
    }
}

#[test]
fn fit_reads_stdin_writes_mesh_and_residuals_and_mesh_reads_the_json() {
    use std::io::Write;
    let cloud = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../shared/clouds/paper/roll.pcd"
    );
    let bytes = std::fs::read(cloud).unwrap();
    let (mesh, residuals, json) = (tmp("roll-mesh.ply"), tmp("roll-res.ply"), tmp("roll.json"));
    let mut child = bin()
        .args([
            "fit",
            "-",
            "--format",
            "pcd",
            "--backend",
            "cpu",
            "--seed",
            "2",
        ])
        .args(["--mesh", mesh.to_str().unwrap()])
        .args(["--residuals", residuals.to_str().unwrap()])
        .args(["-o", json.to_str().unwrap()])
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    child.stdin.take().unwrap().write_all(&bytes).unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    assert_eq!(report["points"]["input"], 8406);

    // the mesh: a PLY with vertices, normals and faces, and every vertex on the fitted surface
    let header = |path: &std::path::Path| {
        let b = std::fs::read(path).unwrap();
        let end = b.windows(11).position(|w| w == b"end_header\n").unwrap();
        String::from_utf8_lossy(&b[..end]).into_owned()
    };
    let h = header(&mesh);
    assert!(
        h.contains("element vertex 8192")
            && h.contains("property float nx")
            && h.contains("element face 16384"),
        "{h}"
    );
    let h = header(&residuals);
    assert!(
        h.contains("element vertex 8406")
            && h.contains("property uchar red")
            && h.contains("property float distance"),
        "{h}"
    );
    let vertices = supertoroid::io::read_cloud(&mesh, None).unwrap();
    let (shape, pose) =
        supertoroid::fit::parse_report_json(&std::fs::read(&json).unwrap()).unwrap();
    let worst = vertices
        .iter()
        .map(|v| supertoroid::model::meridian_distance(&shape, pose.to_canonical(*v)).distance)
        .fold(0.0, f64::max);
    assert!(
        worst < 1e-5 * shape.size().max(1.0),
        "mesh vertex {worst} off the surface"
    );

    // `mesh --fit` redraws the same surface from the JSON
    let again = tmp("roll-again.ply");
    let o = bin()
        .args([
            "mesh",
            "--fit",
            json.to_str().unwrap(),
            "-o",
            again.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(
        std::fs::read(&again).unwrap(),
        std::fs::read(&mesh).unwrap()
    );
    // a broken JSON is bad input
    let o = bin()
        .args(["mesh", "--fit", cloud, "-o", again.to_str().unwrap()])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
}

/// `sample --view` names its camera as the `--viewpoint` to give `fit`, and `fit` takes
/// it without a warning.
#[test]
fn a_sampled_view_names_the_viewpoint_that_fit_takes() {
    let cloud = tmp("view.xyz");
    let out = bin()
        .args(["sample", "--shape", SHAPE, "--view", "--seed", "5", "-o"])
        .arg(&cloud)
        .output()
        .unwrap();
    assert!(out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    let viewpoint = stderr
        .lines()
        .find_map(|l| l.strip_prefix("camera at --viewpoint "))
        .unwrap_or_else(|| panic!("no camera line in {stderr:?}"))
        .trim()
        .to_owned();
    assert_eq!(viewpoint.split(',').count(), 3, "{viewpoint}");
    let (json, stderr) = fit_json(&["--viewpoint", &viewpoint], &cloud);
    assert!(!json.to_string().contains("viewpoint ignored"), "{json}");
    assert!(!stderr.contains("viewpoint ignored"));
    // the fit drawn from the viewpoint: what share of what it shows the sensor has points
    let covered = json["quality"]["visible_coverage"].as_f64().unwrap();
    assert!((0.0..=1.0).contains(&covered), "{json}");
    // a product's dimensions, held
    let (json, _) = fit_json(&["--known", "a1=0.05,a2=0.05,a4=2"], &cloud);
    assert!(
        (json["shape"]["a4"].as_f64().unwrap() - 2.0).abs() < 1e-9,
        "{json}"
    );
    // bad options are named: a3 given twice, an unknown parameter, an unknown flag
    for (args, named) in [
        (vec!["--known", "a3=0.02", "--a3", "0.02"], "a3 given twice"),
        (vec!["--known", "a9=1"], "a9"),
        (
            vec!["--viewpoint", &viewpoint, "--retries", "17"],
            "retries",
        ),
        // the fit's own sample sizes and estimators are not options
        (vec!["--no-noise-model"], "no-noise-model"),
        (vec!["--stage2-points", "2000"], "stage2-points"),
        (vec!["--polish-points", "0"], "polish-points"),
    ] {
        let bad = bin().arg("fit").args(&args).arg(&cloud).output().unwrap();
        assert_eq!(bad.status.code(), Some(2), "{args:?}");
        let stderr = String::from_utf8_lossy(&bad.stderr);
        assert!(stderr.contains(named), "{args:?}: {stderr}");
    }
}

/// A fit on the GPU (lavapipe in CI) in an environment without `XDG_RUNTIME_DIR`, as in a
/// container or a service, prints no error from the Vulkan loader's Wayland support.
#[test]
fn a_gpu_fit_without_a_runtime_dir_prints_no_loader_error() {
    let cloud = tmp("quiet.xyz");
    let sampled = bin()
        .args(["sample", "--shape", SHAPE, "--points", "500", "-o"])
        .arg(&cloud)
        .output()
        .unwrap();
    assert!(sampled.status.success());
    let out = bin()
        .args(["fit", "--backend", "gpu"])
        .arg(&cloud)
        .env_remove("XDG_RUNTIME_DIR")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "no GPU adapter? install mesa-vulkan-drivers and set WGPU_BACKEND=vulkan: {stderr}"
    );
    assert!(!stderr.contains("XDG_RUNTIME_DIR"), "{stderr}");
    let fit: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(fit["backend"]["kind"], "gpu");
}

#[test]
fn grasps_surface_and_export_read_the_fit_json() {
    let cloud = tmp("g-ring.xyz");
    let status = bin()
        .args([
            "sample",
            "--shape",
            "0.015,0.015,0.008,2.5,1,1",
            "--translation",
            "0,0,0.5",
        ])
        .args([
            "--points",
            "2000",
            "--seed",
            "2",
            "-o",
            cloud.to_str().unwrap(),
        ])
        .status()
        .unwrap();
    assert!(status.success());
    let (fit, _) = fit_json(&["--viewpoint", "none"], &cloud);
    let fit_path = tmp("g-fit.json");
    std::fs::write(&fit_path, fit.to_string()).unwrap();
    let run = |args: &[&str]| bin().args(args).output().unwrap();
    let f = fit_path.to_str().unwrap();

    let out = run(&["grasps", f, "--graspnet", "--max-grasps", "5"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let grasps: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let list = grasps["grasps"].as_array().unwrap();
    assert!(!list.is_empty() && list.len() <= 5, "{grasps}");
    assert_eq!(grasps["graspnet"].as_array().unwrap().len(), list.len());
    let width = list[0]["width"].as_f64().unwrap();
    assert!(width > 0.0 && width <= 0.08);

    let out = run(&["surface", f, "--grid", "4x8"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let surface: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(surface["points"].as_array().unwrap().len(), 32);
    let out = run(&["surface", f, "--nearest", cloud.to_str().unwrap()]);
    let surface: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(surface["points"].as_array().unwrap().len(), 2000);

    let dir = tmp("g-scene");
    let out = run(&[
        "export",
        f,
        "--plane",
        "0,0,1,-0.492",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mjcf = std::fs::read_to_string(dir.join("scene.xml")).unwrap();
    assert!(mjcf.contains("<freejoint") && mjcf.contains("type=\"plane\""));
    assert!(dir.join("scene.urdf").exists() && dir.join("object_0_visual.obj").exists());

    // bad input: exit 2 and one line
    for args in [
        vec!["grasps", f, "--max-opening=-1"],
        vec!["grasps", f, "--plane", "0,0,0,1"],
        vec!["surface", f],
        vec!["surface", f, "--grid", "4by8"],
        vec![
            "export",
            f,
            "--density",
            "0",
            "--out",
            dir.to_str().unwrap(),
        ],
        vec!["grasps", cloud.to_str().unwrap()],
    ] {
        let out = run(&args);
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(err.trim().lines().count(), 1, "{args:?}: {err}");
    }
}

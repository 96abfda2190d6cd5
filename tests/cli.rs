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

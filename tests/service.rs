//! The HTTP service over real HTTP on loopback (reqwest): every endpoint with real data,
//! every class of bad input, concurrency, overload, and the OpenAPI document.

use base64::Engine;
use reqwest::blocking::{Client, multipart};
use serde_json::{Value, json};
use std::path::PathBuf;
use std::process::Command;
use supertoroid::eval::Backend;
use supertoroid::model::{Pose, Shape};
use supertoroid::service::ServiceConfig;
use supertoroid::synth::{self, Camera, Intrinsics};

mod common;
use common::{Server, client};

/// A ground-truth case's cloud as JSON points.
fn case_points(seed: u64, partial: bool, noise: f64, outliers: f64) -> Vec<[f64; 3]> {
    supertoroid::suite::ground_truth::make_case(seed, partial, noise, outliers)
        .points
        .iter()
        .map(|p| p.to_array())
        .collect()
}

/// A request that keeps a worker busy for seconds: `/v1/fit/batch` with twelve noisy
/// single views with outliers (each a few hundred milliseconds on two cores).
fn slow_batch() -> Value {
    let clouds: Vec<Value> = (0..12)
        .map(|seed| json!({"points": case_points(100 + seed, true, 0.02, 0.05)}))
        .collect();
    json!({ "clouds": clouds })
}

/// A fittable cloud as JSON points.
fn planar_ok() -> Vec<[f64; 3]> {
    case_points(3, false, 0.0, 0.0)
}

fn cpu_config() -> ServiceConfig {
    ServiceConfig {
        backend: Backend::Cpu,
        ..Default::default()
    }
}

/// The GPU evaluator: lavapipe in CI.
fn gpu_config() -> ServiceConfig {
    ServiceConfig {
        backend: Backend::Gpu,
        ..Default::default()
    }
}

/// The Prometheus text the server exposes now.
fn metrics_text(c: &Client, server: &Server) -> String {
    c.get(server.url("/metrics"))
        .send()
        .unwrap()
        .text()
        .unwrap()
}

fn paper(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/clouds/paper")
        .join(name)
}

fn shape_of(v: &Value) -> [f64; 6] {
    let s = &v["shape"];
    ["a1", "a2", "a3", "a4", "eps1", "eps2"].map(|k| s[k].as_f64().unwrap())
}

/// The same fit to the last digits the formats carry (a cloud's numbers printed as PCD
/// text and as JSON agree to about 1e-9; the fit's iterations carry that on).
fn assert_same_fit(a: &Value, b: &Value, what: &str) {
    let (sa, sb) = (shape_of(a), shape_of(b));
    for (x, y) in sa.iter().zip(&sb) {
        assert!(
            (x - y).abs() <= 1e-6 * x.abs().max(1e-12),
            "{what}: {sa:?} vs {sb:?}"
        );
    }
    let translation = |v: &Value| -> Vec<f64> {
        v["pose"]["translation"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect()
    };
    for (x, y) in translation(a).iter().zip(translation(b)) {
        assert!((x - y).abs() <= 1e-9, "{what}: {a} vs {b}");
    }
}

/// POSTs a JSON body and reads the JSON answer.
fn post_json(c: &Client, s: &Server, path: &str, body: &Value) -> Value {
    c.post(s.url(path))
        .json(body)
        .send()
        .unwrap()
        .json()
        .unwrap()
}

fn post_pcd(c: &Client, s: &Server, bytes: Vec<u8>, query: &str) -> reqwest::blocking::Response {
    c.post(s.url(&format!("/v1/fit{query}")))
        .header("content-type", "application/octet-stream")
        .body(bytes)
        .send()
        .unwrap()
}

#[test]
fn a_paper_cloud_as_pcd_and_as_json_gives_the_cli_result() {
    let server = Server::start(cpu_config());
    let c = client();
    let path = paper("gearclean.pcd");
    let bytes = std::fs::read(&path).unwrap();
    let response = post_pcd(&c, &server, bytes.clone(), "?seed=3");
    assert_eq!(response.status(), 200);
    assert!(response.headers().contains_key("x-request-id"));
    let from_pcd: Value = response.json().unwrap();
    assert!(
        from_pcd["request_id"]
            .as_str()
            .is_some_and(|s| !s.is_empty())
    );
    for key in [
        "shape",
        "pose",
        "quality",
        "timing_ms",
        "iterations",
        "backend",
        "points",
    ] {
        assert!(from_pcd.get(key).is_some(), "missing {key}");
    }
    assert_eq!(from_pcd["points"]["input"], 2445);

    let points: Vec<[f64; 3]> = supertoroid::io::read_cloud(&path, None)
        .unwrap()
        .iter()
        .map(|p| p.to_array())
        .collect();
    let from_json: Value = c
        .post(server.url("/v1/fit"))
        .json(&json!({"points": points, "options": {"seed": 3}}))
        .send()
        .unwrap()
        .json()
        .unwrap();
    assert_same_fit(&from_pcd, &from_json, "pcd vs json");

    let cli = Command::new(env!("CARGO_BIN_EXE_supertoroid"))
        .args([
            "fit",
            path.to_str().unwrap(),
            "--seed",
            "3",
            "--backend",
            "cpu",
        ])
        .output()
        .unwrap();
    assert!(
        cli.status.success(),
        "{}",
        String::from_utf8_lossy(&cli.stderr)
    );
    let from_cli: Value = serde_json::from_slice(&cli.stdout).unwrap();
    assert_same_fit(&from_pcd, &from_cli, "service vs CLI");

    // options in the query for raw bodies, the axis prior as text
    let prior: Value = post_pcd(
        &c,
        &server,
        bytes.clone(),
        "?seed=3&axis=0,0,1&method=paper",
    )
    .json()
    .unwrap();
    assert_eq!(prior["method"], "paper");
    let z = prior["pose"]["rotation"][2][2].as_f64().unwrap();
    assert!(
        (z.abs() - 1.0).abs() < 1e-9,
        "the hole axis is not the given one: {prior}"
    );
    let bad = post_pcd(&c, &server, bytes.clone(), "?axis=0,0");
    assert_eq!(bad.status(), 422);
    // the sensor's position as text; a malformed one is named
    let seen = post_pcd(&c, &server, bytes.clone(), "?viewpoint=0,0,-2");
    assert_eq!(seen.status(), 200);
    let bad = post_pcd(&c, &server, bytes.clone(), "?viewpoint=0,0");
    assert_eq!(bad.status(), 422);
    assert!(bad.text().unwrap().contains("viewpoint"));
    // known dimensions, in a query string; a bad one is named
    let known: Value = post_pcd(&c, &server, bytes.clone(), "?known=a4:2,a3:0.02")
        .json()
        .unwrap();
    assert!(
        (known["shape"]["a4"].as_f64().unwrap() - 2.0).abs() < 1e-9,
        "{known}"
    );
    let bad = post_pcd(&c, &server, bytes.clone(), "?known=a9:1");
    assert_eq!(bad.status(), 422);
    assert!(bad.text().unwrap().contains("a9"));
    // an option the service does not have is named, not ignored
    let bad = post_pcd(&c, &server, bytes.clone(), "?retries=3");
    assert_eq!(bad.status(), 422);
    assert!(bad.text().unwrap().contains("retries"));

    // the fit's own sample sizes and estimators are not options: named, not ignored
    for (query, named) in [
        ("?noise_model=false", "noise_model"),
        ("?stage2_points=2000", "stage2_points"),
        ("?polish_points=0", "polish_points"),
    ] {
        let bad = post_pcd(&c, &server, bytes.clone(), query);
        assert_eq!(bad.status(), 422, "{query}");
        assert!(bad.text().unwrap().contains(named), "{query}");
    }

    // a different seed is a different downsampling
    let other: Value = post_pcd(&c, &server, bytes, "?seed=4").json().unwrap();
    assert_ne!(shape_of(&other), shape_of(&from_pcd));
}

/// A rendered depth frame of a known supertoroid, its camera and the cloud it makes.
fn depth_case() -> (Vec<u8>, Value, Shape, Pose, Camera) {
    let shape = Shape::new(0.06, 0.05, 0.025, 1.8, 0.8, 1.0);
    let pose = Pose::new(
        glam::DQuat::from_rotation_x(0.3),
        glam::DVec3::new(0.02, -0.01, 0.6),
    );
    let camera = Camera::look_at(
        Intrinsics::REALSENSE_640X480,
        glam::DVec3::new(0.0, -0.25, 0.25),
        pose.translation,
        glam::DVec3::Z,
    );
    let view = synth::render_view(&shape, &pose, &camera, 0.0001).unwrap();
    let png = supertoroid::io::depth::encode_depth_png(&view.depth);
    let k = camera.intrinsics;
    let params = json!({
        "intrinsics": {"fx": k.fx, "fy": k.fy, "cx": k.cx, "cy": k.cy},
        "depth_scale": 0.0001,
        "width": 640, "height": 480,
        "options": {"seed": 1}
    });
    (png, params, shape, pose, camera)
}

#[test]
fn a_depth_frame_as_json_and_as_multipart_fits_the_object() {
    let server = Server::start(cpu_config());
    let c = client();
    let (png, params, shape, pose, camera) = depth_case();
    let mut body = params.clone();
    body["depth_png"] = json!(base64::engine::general_purpose::STANDARD.encode(&png));
    let response = c
        .post(server.url("/v1/fit/depth"))
        .json(&body)
        .send()
        .unwrap();
    assert_eq!(response.status(), 200);
    let from_json: Value = response.json().unwrap();

    let form = multipart::Form::new()
        .part(
            "depth",
            multipart::Part::bytes(png.clone()).file_name("depth.png"),
        )
        .text("params", params.to_string());
    let response = c
        .post(server.url("/v1/fit/depth"))
        .multipart(form)
        .send()
        .unwrap();
    assert_eq!(response.status(), 200);
    let from_multipart: Value = response.json().unwrap();
    assert_same_fit(&from_json, &from_multipart, "json vs multipart");

    // the pose is in the camera frame: bring it to the world and compare with the truth
    let q = from_json["pose"]["quaternion_wxyz"].as_array().unwrap();
    let q = glam::DQuat::from_xyzw(
        q[1].as_f64().unwrap(),
        q[2].as_f64().unwrap(),
        q[3].as_f64().unwrap(),
        q[0].as_f64().unwrap(),
    );
    let t: Vec<f64> = from_json["pose"]["translation"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let fitted_pose = Pose::new(
        camera.pose.rotation * q,
        camera.pose.to_world(glam::DVec3::new(t[0], t[1], t[2])),
    );
    let s = shape_of(&from_json);
    let fitted_shape = Shape::new(s[0], s[1], s[2], s[3], s[4], s[5]);
    let e =
        supertoroid::suite::ground_truth::compare((&shape, &pose), (&fitted_shape, &fitted_pose));
    assert!(e.success(), "{e:?}");
    // a depth frame is fitted both ways unless the request names a model; the ring keeps
    // its hole
    assert_eq!(
        from_json["model"]["chosen_by"], "bic",
        "{}",
        from_json["model"]
    );
    assert_eq!(from_json["model"]["kind"], "supertoroid");

    // raw u16 with a mask part: only the masked half is fitted
    let image =
        supertoroid::io::depth::decode_depth_png(&png, 0.0001, None, Default::default()).unwrap();
    let raw: Vec<u8> = image.data.iter().flat_map(|v| v.to_le_bytes()).collect();
    let form = multipart::Form::new()
        .part("depth", multipart::Part::bytes(raw))
        .text("params", params.to_string());
    let raw_fit: Value = c
        .post(server.url("/v1/fit/depth"))
        .multipart(form)
        .send()
        .unwrap()
        .json()
        .unwrap();
    assert_same_fit(&from_json, &raw_fit, "png vs raw");
}

#[test]
fn every_bad_input_class_gets_its_status_and_a_json_error() {
    let server = Server::start(ServiceConfig {
        body_limit: 200_000,
        max_points: 400_000,
        ..cpu_config()
    });
    let c = client();
    let planar: Vec<[f64; 3]> = (0..400)
        .map(|i| [(i % 20) as f64, (i / 20) as f64, 1.0])
        .collect();
    let gear = std::fs::read(paper("gearclean.pcd")).unwrap();
    let mut corrupt = gear.clone();
    let n = corrupt.len();
    corrupt.truncate(n - 500);
    let (png, params, ..) = depth_case();
    let mut wrong_size = params.clone();
    wrong_size["width"] = json!(320);
    wrong_size["depth_png"] = json!(base64::engine::general_purpose::STANDARD.encode(&png));
    let mut bad_fx = params.clone();
    bad_fx["intrinsics"]["fx"] = json!(0.0);
    bad_fx["depth_png"] = wrong_size["depth_png"].clone();
    let mut zero_depth = params.clone();
    let blank = supertoroid::synth::DepthImage {
        width: 640,
        height: 480,
        scale: 0.0001,
        data: vec![0; 640 * 480],
    };
    zero_depth["depth_png"] = json!(
        base64::engine::general_purpose::STANDARD
            .encode(supertoroid::io::depth::encode_depth_png(&blank))
    );
    let mut off_image = bad_fx.clone();
    off_image["intrinsics"] = params["intrinsics"].clone();
    off_image["intrinsics"]["cx"] = json!(900.0);
    // a whole frame: depth on every pixel, no box or mask to pick the object
    let mut whole = params.clone();
    let wall = supertoroid::synth::DepthImage {
        data: vec![6000; 640 * 480],
        ..blank.clone()
    };
    whole["depth_png"] = json!(
        base64::engine::general_purpose::STANDARD
            .encode(supertoroid::io::depth::encode_depth_png(&wall))
    );
    // metres taken for tenths of a millimetre: an object 10,000 times too large
    let mut wrong_units = bad_fx.clone();
    wrong_units["intrinsics"] = params["intrinsics"].clone();
    wrong_units["depth_scale"] = json!(1.0);
    let mut no_size = wrong_units.clone();
    no_size["depth_scale"] = params["depth_scale"].clone();
    no_size["max_size"] = json!(-1.0);
    let json_case = |v: Value| ("application/json", v.to_string().into_bytes());
    let cases: Vec<(&str, &str, (&str, Vec<u8>), u16, &str)> = vec![
        (
            "max_size not positive",
            "/v1/fit/depth",
            json_case(no_size),
            422,
            "invalid_depth_options",
        ),
        (
            "principal point outside the image",
            "/v1/fit/depth",
            json_case(off_image),
            422,
            "invalid_depth_options",
        ),
        (
            "a whole frame",
            "/v1/fit/depth",
            json_case(whole),
            422,
            "whole_frame",
        ),
        (
            "depth scale of another unit",
            "/v1/fit/depth",
            json_case(wrong_units),
            422,
            "implausible_size",
        ),
        (
            "malformed JSON",
            "/v1/fit",
            ("application/json", b"{\"points\": [[1,2,3],".to_vec()),
            400,
            "malformed_json",
        ),
        (
            "NaN in JSON",
            "/v1/fit",
            ("application/json", b"{\"points\": [[1,2,NaN]]}".to_vec()),
            400,
            "malformed_json",
        ),
        (
            "wrong array shape",
            "/v1/fit",
            json_case(json!({"points": [[1, 2]]})),
            422,
            "invalid_request",
        ),
        (
            "points not an array",
            "/v1/fit",
            json_case(json!({"points": "many"})),
            422,
            "invalid_request",
        ),
        (
            "unknown option",
            "/v1/fit",
            json_case(json!({"points": [[1,2,3]], "options": {"sede": 1}})),
            422,
            "invalid_request",
        ),
        (
            "too few points",
            "/v1/fit",
            json_case(json!({"points": [[1,2,3],[4,5,6]]})),
            422,
            "too_few_points",
        ),
        (
            "planar cloud",
            "/v1/fit",
            json_case(json!({"points": planar})),
            422,
            "degenerate_cloud",
        ),
        (
            "negative a3",
            "/v1/fit",
            json_case(json!({"points": planar_ok(), "options": {"a3": -0.01}})),
            422,
            "invalid_option",
        ),
        (
            "negative time budget",
            "/v1/fit",
            json_case(json!({"points": planar_ok(), "options": {"time_budget_ms": -1.0}})),
            422,
            "invalid_option",
        ),
        (
            "zero axis",
            "/v1/fit",
            json_case(json!({"points": [[1,2,3]], "options": {"axis": [0,0,0]}})),
            422,
            "invalid_option",
        ),
        (
            "oversize body",
            "/v1/fit",
            ("application/octet-stream", vec![b'1'; 300_000]),
            413,
            "body_too_large",
        ),
        (
            "unsupported media type",
            "/v1/fit",
            ("image/jpeg", vec![1, 2, 3]),
            415,
            "unsupported_media_type",
        ),
        (
            "unknown format",
            "/v1/fit",
            ("application/octet-stream", vec![0xff, 0x00, 0x13]),
            415,
            "unsupported_format",
        ),
        (
            "corrupt PCD",
            "/v1/fit",
            ("application/octet-stream", corrupt),
            400,
            "malformed_cloud",
        ),
        (
            "inf in text",
            "/v1/fit",
            ("text/plain", b"1 2 3\n4 inf 6\n".to_vec()),
            422,
            "non_finite",
        ),
        (
            "empty body",
            "/v1/fit",
            ("application/octet-stream", vec![]),
            422,
            "empty_cloud",
        ),
        (
            "wrong PNG size",
            "/v1/fit/depth",
            json_case(wrong_size),
            400,
            "malformed_image",
        ),
        (
            "bad intrinsics",
            "/v1/fit/depth",
            json_case(bad_fx),
            422,
            "invalid_depth_options",
        ),
        (
            "zero depth",
            "/v1/fit/depth",
            json_case(zero_depth),
            422,
            "no_valid_depth",
        ),
        (
            "bad base64",
            "/v1/fit/depth",
            json_case(
                json!({"depth_png": "***", "intrinsics": {"fx": 1, "fy": 1, "cx": 0, "cy": 0}}),
            ),
            400,
            "malformed_base64",
        ),
        (
            "no depth",
            "/v1/fit/depth",
            json_case(json!({"intrinsics": {"fx": 1, "fy": 1, "cx": 0, "cy": 0}})),
            422,
            "invalid_request",
        ),
        (
            "empty batch",
            "/v1/fit/batch",
            json_case(json!({"clouds": []})),
            422,
            "invalid_request",
        ),
        (
            "unknown route",
            "/v2/fit",
            json_case(json!({})),
            404,
            "not_found",
        ),
    ];
    for (what, route, (kind, body), status, code) in cases {
        let response = c
            .post(server.url(route))
            .header("content-type", kind)
            .body(body)
            .send()
            .unwrap();
        let got = response.status().as_u16();
        let text = response.text().unwrap();
        assert_eq!(got, status, "{what}: {text}");
        let v: Value = serde_json::from_str(&text)
            .unwrap_or_else(|e| panic!("{what}: not JSON ({e}): {text}"));
        assert_eq!(v["error"]["code"], code, "{what}: {text}");
        assert!(
            v["error"]["message"]
                .as_str()
                .is_some_and(|m| !m.is_empty()),
            "{what}"
        );
    }
    // the server is still serving, and counted the errors by kind
    assert_eq!(c.get(server.url("/healthz")).send().unwrap().status(), 200);
    let metrics = metrics_text(&c, &server);
    assert!(
        metrics.contains("supertoroid_errors_total{code=\"too_few_points\"} 1"),
        "{metrics}"
    );
}

#[test]
fn batch_fits_every_cloud_and_reports_each_error() {
    let server = Server::start(cpu_config());
    let c = client();
    let cloud = |seed: u64| -> Vec<[f64; 3]> { case_points(seed, false, 0.005, 0.0) };
    let singles = [
        json!({"points": cloud(1), "options": {"seed": 1}}),
        json!({"points": [[0, 0, 0]]}),
        json!({"points": cloud(2)}),
        json!({"points": case_points(6, true, 0.0, 0.0), "options": {"seed": 3, "method": "paper"}}),
    ];
    let v = post_json(&c, &server, "/v1/fit/batch", &json!({ "clouds": singles }));
    let results = v["results"].as_array().unwrap();
    assert_eq!(results.len(), 4);
    assert_eq!(results[1]["error"]["code"], "too_few_points");
    assert_eq!(results[3]["fit"]["method"], "paper");
    // each cloud alone gives the same fit (the lockstep batch is exact on the CPU)
    for i in [0, 2, 3] {
        assert!(results[i]["fit"]["shape"].is_object());
        let single = post_json(&c, &server, "/v1/fit", &singles[i]);
        assert_same_fit(
            &results[i]["fit"],
            &single,
            &format!("batch vs single, cloud {i}"),
        );
    }
}

/// On a GPU service (lavapipe in CI) a batch runs on the device, all clouds in the same
/// dispatches, each fitted as well as alone.
#[test]
fn a_batch_fits_on_the_gpu_as_well_as_single_requests() {
    let server = Server::start(gpu_config());
    let c = client();
    let clouds: Vec<Value> = (0..3)
        .map(|i| json!({"points": case_points(100 + i, false, 0.005, 0.0), "options": {"seed": i}}))
        .collect();
    let v = post_json(&c, &server, "/v1/fit/batch", &json!({ "clouds": clouds }));
    let results = v["results"].as_array().unwrap();
    for (i, cloud) in clouds.iter().enumerate() {
        let fit = &results[i]["fit"];
        assert_eq!(fit["backend"]["kind"], "gpu", "{v}");
        let single = post_json(&c, &server, "/v1/fit", cloud);
        // (a1 and a2 in either order: a quarter turn about the axis swaps them, the same
        // surface)
        let sizes_in_order = |mut s: [f64; 6]| {
            if s[0] > s[1] {
                s.swap(0, 1);
            }
            s
        };
        let (a, b) = (
            sizes_in_order(shape_of(fit)),
            sizes_in_order(shape_of(&single)),
        );
        // f32 partial sums are added in another order in a batch: close, not identical
        for (x, y) in a.iter().zip(&b) {
            assert!(
                (x - y).abs() <= 0.02 * y.abs().max(0.1),
                "cloud {i}: {a:?} vs {b:?}"
            );
        }
    }
}

#[test]
fn concurrent_requests_all_succeed_and_match_the_sequential_results() {
    // the GPU evaluator (lavapipe in CI): the service shares one context among requests;
    // 32 fits queue behind its workers, which on a slow runner is longer than the default
    // timeout (the timeout's own test is elsewhere): this one is about the answers
    let server = Server::start(ServiceConfig {
        request_timeout: 600.0,
        ..gpu_config()
    });
    let c = client();
    let ready: Value = c.get(server.url("/readyz")).send().unwrap().json().unwrap();
    if std::env::var("CI").is_ok_and(|v| v == "true") {
        assert_eq!(ready["backend"], "gpu", "CI must find lavapipe: {ready}");
    }
    let bodies: Vec<Value> = (0..4u64)
        .map(|i| {
            let points: Vec<[f64; 3]> = case_points(10 + i, i % 2 == 1, 0.01, 0.0);
            json!({"points": points, "options": {"seed": i}})
        })
        .collect();
    let sequential: Vec<Value> = bodies
        .iter()
        .map(|b| {
            c.post(server.url("/v1/fit"))
                .json(b)
                .send()
                .unwrap()
                .json()
                .unwrap()
        })
        .collect();
    let concurrent: Vec<(usize, u16, Value)> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..32)
            .map(|i| {
                let (c, server, bodies) = (&c, &server, &bodies);
                scope.spawn(move || {
                    let r = c
                        .post(server.url("/v1/fit"))
                        .json(&bodies[i % 4])
                        .send()
                        .unwrap();
                    (i % 4, r.status().as_u16(), r.json::<Value>().unwrap())
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    let mut ids = std::collections::HashSet::new();
    for (k, status, v) in &concurrent {
        assert_eq!(*status, 200, "{v}");
        assert_same_fit(v, &sequential[*k], "concurrent vs sequential");
        assert!(
            ids.insert(v["request_id"].as_str().unwrap().to_owned()),
            "request ids are unique"
        );
    }
}

#[test]
fn a_full_queue_answers_503_with_retry_after_and_then_recovers() {
    let server = Server::start(ServiceConfig {
        workers: Some(1),
        queue_depth: 0,
        ..cpu_config()
    });
    let c = client();
    // a batch of noisy views keeps the worker busy long enough for the others to find it so
    let body = slow_batch();
    let results: Vec<(u16, Option<String>, Value)> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..8)
            .map(|_| {
                let (c, server, body) = (&c, &server, &body);
                scope.spawn(move || {
                    let r = c
                        .post(server.url("/v1/fit/batch"))
                        .json(body)
                        .send()
                        .unwrap();
                    let retry = r
                        .headers()
                        .get("retry-after")
                        .map(|v| v.to_str().unwrap().to_owned());
                    (r.status().as_u16(), retry, r.json::<Value>().unwrap())
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    let ok = results.iter().filter(|r| r.0 == 200).count();
    let rejected: Vec<_> = results.iter().filter(|r| r.0 == 503).collect();
    assert!(ok >= 1, "{results:?}");
    assert!(
        !rejected.is_empty(),
        "no request was turned away: {results:?}"
    );
    assert_eq!(ok + rejected.len(), 8);
    for (_, retry, v) in rejected {
        assert_eq!(retry.as_deref(), Some("1"));
        assert_eq!(v["error"]["code"], "overloaded");
    }
    let after = c
        .post(server.url("/v1/fit"))
        .json(&json!({"points": case_points(5, false, 0.01, 0.05)}))
        .send()
        .unwrap();
    assert_eq!(after.status(), 200);
}

/// Every way out of a request gives its queue slot back: requests that time out while
/// waiting for the worker (504) and clients that hang up leave `/readyz` `queued` and the
/// `supertoroid_queue_depth` gauge at 0 once the service is idle, and the queue never
/// holds more than its capacity.
#[test]
fn timeouts_and_disconnects_leave_no_queued_request_behind() {
    let server = Server::start(ServiceConfig {
        workers: Some(1),
        queue_depth: 4,
        request_timeout: 0.3,
        ..cpu_config()
    });
    let c = client();
    let impatient = Client::builder()
        .timeout(std::time::Duration::from_millis(150))
        .build()
        .unwrap();
    let body = slow_batch();
    let queued = |c: &Client| -> u64 {
        c.get(server.url("/readyz"))
            .send()
            .unwrap()
            .json::<Value>()
            .unwrap()["queued"]
            .as_u64()
            .unwrap()
    };
    let post = |client: &Client| {
        client
            .post(server.url("/v1/fit/batch"))
            .json(&body)
            .send()
            .ok()
            .map(|r| r.status().as_u16())
    };
    // clients that hang up while their fit waits or runs
    let gone: Vec<Option<u16>> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..4).map(|_| scope.spawn(|| post(&impatient))).collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    assert!(gone.contains(&None), "{gone:?}");
    // then more requests than one worker serves within the timeout
    let statuses: Vec<Option<u16>> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..8).map(|_| scope.spawn(|| post(&c))).collect();
        let mut most = 0;
        for _ in 0..10 {
            most = most.max(queued(&c));
            std::thread::sleep(std::time::Duration::from_millis(30));
        }
        assert!(most <= 4, "{most} queued, capacity 4");
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    assert!(statuses.contains(&Some(504)), "{statuses:?}");
    assert!(
        statuses
            .iter()
            .all(|s| s.is_some_and(|s| [200, 503, 504].contains(&s))),
        "{statuses:?}"
    );
    // fits already running finish on their own; then nothing is left queued
    let started = std::time::Instant::now();
    while queued(&c) != 0 {
        assert!(
            started.elapsed().as_secs() < 30,
            "still {} queued",
            queued(&c)
        );
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    let metrics = metrics_text(&c, &server);
    let gauge = metrics
        .lines()
        .find(|l| l.starts_with("supertoroid_queue_depth "))
        .unwrap_or_else(|| panic!("no queue gauge in {metrics}"));
    assert_eq!(gauge.split_whitespace().nth(1), Some("0"), "{gauge}");
}

/// The viewpoint option takes a position, "none" or "auto", in JSON and in a query
/// string, and the report says which viewpoint the fit used and where it came from.
#[test]
fn the_viewpoint_given_or_said_to_be_none_is_the_one_reported() {
    let server = Server::start(cpu_config());
    let c = client();
    // a single view in its camera's frame
    let (view, _) = supertoroid::suite::ground_truth::make_case(6, true, 0.0, 0.0)
        .in_camera_frame()
        .unwrap();
    let points: Vec<[f64; 3]> = view.iter().map(|p| p.to_array()).collect();
    for (viewpoint, source) in [(json!("none"), "none"), (json!([0.0, 0.0, 0.0]), "request")] {
        let r = c
            .post(server.url("/v1/fit"))
            .json(&json!({"points": points, "options": {"viewpoint": viewpoint}}))
            .send()
            .unwrap();
        assert_eq!(r.status(), 200);
        let v: Value = r.json().unwrap();
        assert_eq!(v["viewpoint"]["source"], source, "{}", v["viewpoint"]);
        assert!(
            v["viewpoint"]["reason"]
                .as_str()
                .is_some_and(|s| !s.is_empty())
        );
    }
    let text: String = points
        .iter()
        .map(|p| format!("{} {} {}\n", p[0], p[1], p[2]))
        .collect();
    let r = c
        .post(server.url("/v1/fit?viewpoint=none"))
        .header("content-type", "text/plain")
        .body(text)
        .send()
        .unwrap();
    assert_eq!(r.status(), 200);
    assert_eq!(r.json::<Value>().unwrap()["viewpoint"]["source"], "none");
    let r = c
        .post(server.url("/v1/fit"))
        .json(&json!({"points": points, "options": {"viewpoint": "sideways"}}))
        .send()
        .unwrap();
    assert_eq!(r.status(), 422);
    let v: Value = r.json().unwrap();
    assert!(
        v["error"]["message"]
            .as_str()
            .unwrap()
            .contains("viewpoint"),
        "{v}"
    );
}

#[test]
fn health_readiness_metrics_index_and_a_valid_openapi_document() {
    let server = Server::start(cpu_config());
    let c = client();
    let health: Value = c
        .get(server.url("/healthz"))
        .send()
        .unwrap()
        .json()
        .unwrap();
    assert_eq!(health["status"], "ok");
    let ready: Value = c.get(server.url("/readyz")).send().unwrap().json().unwrap();
    assert_eq!(ready["ready"], true);
    assert_eq!(ready["backend"], "cpu");
    let index = c.get(server.url("/")).send().unwrap().text().unwrap();
    assert!(index.contains("supertoroid") && index.contains("/openapi.json"));
    let metrics = metrics_text(&c, &server);
    for name in [
        "supertoroid_http_requests_total{route=\"/healthz\",status=\"200\"} 1",
        "supertoroid_queue_depth",
        "supertoroid_http_request_duration_seconds_bucket",
    ] {
        assert!(metrics.contains(name), "{name} missing from:\n{metrics}");
    }
    // a fit with a warning is counted by the warning's kind: a thin ring (a3 = 1 cm),
    // 300 points under 6 mm of noise
    let shape = Shape::new(0.05, 0.05, 0.01, 2.0, 1.0, 1.0);
    let mut rng = synth::rng(5);
    let mut points = synth::sample_surface(&shape, &Pose::default(), 300, &mut rng);
    synth::add_noise(&mut points, 0.006, &mut rng);
    let points: Vec<[f64; 3]> = points.iter().map(|p| p.to_array()).collect();
    let fit: Value = c
        .post(server.url("/v1/fit"))
        .json(&json!({ "points": points }))
        .send()
        .unwrap()
        .json()
        .unwrap();
    assert!(
        fit["warnings"][0]
            .as_str()
            .unwrap()
            .starts_with("uncertain shape"),
        "{fit}"
    );
    let metrics = metrics_text(&c, &server);
    // known dimensions as a JSON object in the options
    let held: Value = c
        .post(server.url("/v1/fit"))
        .json(&json!({ "points": points, "options": { "known": { "a3": 0.01 } } }))
        .send()
        .unwrap()
        .json()
        .unwrap();
    assert!(
        (held["shape"]["a3"].as_f64().unwrap() - 0.01).abs() < 1e-12,
        "{held}"
    );
    let counted = "supertoroid_fit_warnings_total{kind=\"uncertain_shape\"} 1";
    assert!(
        metrics.contains(counted),
        "{counted} missing from:\n{metrics}"
    );

    let doc: Value = c
        .get(server.url("/openapi.json"))
        .send()
        .unwrap()
        .json()
        .unwrap();
    assert!(doc["openapi"].as_str().unwrap().starts_with("3."));
    for (path, method) in [
        ("/v1/fit", "post"),
        ("/v1/fit/depth", "post"),
        ("/v1/fit/batch", "post"),
        ("/healthz", "get"),
        ("/readyz", "get"),
        ("/metrics", "get"),
        ("/openapi.json", "get"),
        ("/", "get"),
    ] {
        assert!(
            doc["paths"][path][method].is_object(),
            "{path} {method} missing"
        );
        assert!(
            doc["paths"][path][method]["responses"]["200"].is_object(),
            "{path}"
        );
    }
    // every $ref resolves
    fn refs(v: &Value, out: &mut Vec<String>) {
        match v {
            Value::Object(m) => {
                for (k, x) in m {
                    if k == "$ref" {
                        out.push(x.as_str().unwrap().to_owned());
                    } else {
                        refs(x, out);
                    }
                }
            }
            Value::Array(a) => a.iter().for_each(|x| refs(x, out)),
            _ => {}
        }
    }
    let mut all = Vec::new();
    refs(&doc, &mut all);
    assert!(!all.is_empty());
    for r in all {
        let name = r
            .strip_prefix("#/components/schemas/")
            .unwrap_or_else(|| panic!("{r}"));
        assert!(
            doc["components"]["schemas"][name].is_object(),
            "{r} does not resolve"
        );
    }
    // the documented response really has the documented top-level fields
    let fit_schema = &doc["components"]["schemas"]["FitResponse"];
    assert!(fit_schema.to_string().contains("request_id"));
}

/// A real `supertoroid serve` process on a free port, once it answers /healthz.
fn spawn_serve(args: &[&str], env: &[(&str, &str)]) -> (std::process::Child, String) {
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let bind = format!("127.0.0.1:{port}");
    let mut command = Command::new(env!("CARGO_BIN_EXE_supertoroid"));
    command
        .args(["serve", "--bind", &bind])
        .args(args)
        .envs(env.iter().copied())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null());
    let server = command.spawn().unwrap();
    let url = format!("http://{bind}");
    let started = std::time::Instant::now();
    while client().get(format!("{url}/healthz")).send().is_err() {
        assert!(started.elapsed().as_secs() < 30, "server did not start");
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    (server, url)
}

/// A service started with `--backend gpu` whose GPU is missing runs degraded: requests
/// that leave the backend to it fit on the CPU, requests that insist on the GPU get 422.
#[test]
fn a_gpu_service_without_its_gpu_fits_default_requests_on_the_cpu() {
    let (mut server, url) = spawn_serve(
        &["--backend", "gpu"],
        &[("SUPERTOROID_ADAPTER", "no-such-adapter")],
    );
    let c = client();
    let points = case_points(3, false, 0.0, 0.0);
    let fitted = c
        .post(format!("{url}/v1/fit"))
        .json(&json!({ "points": points }))
        .send()
        .unwrap();
    assert_eq!(fitted.status(), 200);
    let body: Value = fitted.json().unwrap();
    assert_eq!(body["backend"]["kind"], "cpu", "{body}");
    let refused = c
        .post(format!("{url}/v1/fit"))
        .json(&json!({ "points": points, "options": { "backend": "gpu" } }))
        .send()
        .unwrap();
    assert_eq!(refused.status(), 422);
    let body: Value = refused.json().unwrap();
    assert_eq!(body["error"]["code"], "gpu_unavailable", "{body}");
    let ready: Value = c
        .get(format!("{url}/readyz"))
        .send()
        .unwrap()
        .json()
        .unwrap();
    assert!(ready["degraded"].is_string(), "{ready}");
    server.kill().unwrap();
    server.wait().unwrap();
}

#[test]
fn sigterm_lets_the_in_flight_fit_finish() {
    let (mut server, url) =
        spawn_serve(&["--backend", "cpu"], &[("SUPERTOROID_LOG_FORMAT", "json")]);
    let c = client();
    // a slow request (a batch of noisy views: seconds), and SIGTERM while it runs
    let body = slow_batch();
    let sent = std::time::Instant::now();
    let response = std::thread::scope(|scope| {
        let request = scope.spawn(|| {
            c.post(format!("{url}/v1/fit/batch"))
                .json(&body)
                .send()
                .unwrap()
        });
        std::thread::sleep(std::time::Duration::from_millis(400));
        // the shell's own kill: no procps needed
        let kill = Command::new("sh")
            .args(["-c", &format!("kill -TERM {}", server.id())])
            .status()
            .unwrap();
        assert!(kill.success());
        request.join().unwrap()
    });
    assert_eq!(response.status(), 200);
    // the fit was still running when the signal came
    assert!(
        sent.elapsed().as_millis() > 600,
        "the fit ended too soon to test shutdown"
    );
    let status = server.wait().unwrap();
    assert!(status.success(), "{status:?}");
    let mut logs = String::new();
    use std::io::Read;
    server
        .stdout
        .take()
        .unwrap()
        .read_to_string(&mut logs)
        .unwrap();
    // structured JSON logs on stdout, one object per line
    assert!(
        logs.lines()
            .any(|l| l.contains("\"route\":\"/v1/fit/batch\"") && l.contains("\"status\":200")),
        "{logs}"
    );
}

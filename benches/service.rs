//! Whole `/v1/fit/depth` requests through the HTTP service: a 640x480 depth frame (16-bit
//! PNG, D435-like noise growing with range, flying pixels) of a ring on a table seen from
//! 0.28 m, its object given by a segmenter's mask of about 60,000 pixels, and by a
//! detector's box instead (the table in it taken away); with the route's default model
//! (`auto`: both models fitted and weighed) and with `supertoroid` named. Each request
//! encodes nothing: the body is built once, the time is the round trip on localhost
//! (decoding, reading the pixels, the table, the fit, the answer).
//! And whole `/v1/scene` requests of a frame with five objects.
//! `cargo bench --bench service` (a server on the CPU evaluator, and one on the GPU where
//! wgpu finds an adapter: lavapipe on a machine without one).

use base64::Engine;
use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use glam::{DQuat, DVec3};
use serde_json::{Value, json};
use std::net::SocketAddr;
use std::time::Duration;
use supertoroid::bench::scenes::BenchFrame;
use supertoroid::eval::{AdapterChoice, Backend, GpuContext};
use supertoroid::io::depth::encode_depth_png;
use supertoroid::model::{Plane, Pose, Shape};
use supertoroid::service::ServiceConfig;
use supertoroid::synth::scene::with_sensor_noise;
use supertoroid::synth::{Camera, DepthImage, Intrinsics, render_view, with_table};

/// Depth units of the frame (0.1 mm).
const DEPTH_SCALE: f64 = 1e-4;

/// The frame, its camera and the ring's mask (non-zero on its pixels).
fn ring_on_a_table() -> (DepthImage, Camera, DepthImage) {
    let shape = Shape::new(0.025, 0.025, 0.03, 1.6, 0.7, 1.0);
    let pose = Pose::new(DQuat::IDENTITY, DVec3::new(0.0, 0.0, 0.03));
    let eye = DVec3::new(0.0, -0.2, 0.23);
    let camera = Camera::look_at(
        Intrinsics::REALSENSE_640X480,
        eye,
        pose.translation,
        DVec3::Z,
    );
    let view = render_view(&shape, &pose, &camera, DEPTH_SCALE).expect("the ring renders");
    let table = Plane::through(DVec3::ZERO, DVec3::Z);
    let depth = with_sensor_noise(&with_table(&view.depth, &camera, &table), 0.001, 0.3, 1);
    let mut mask = DepthImage {
        data: vec![0; view.depth.data.len()],
        ..view.depth.clone()
    };
    for [u, v] in &view.pixels {
        mask.data[(v * mask.width + u) as usize] = 1;
    }
    (depth, camera, mask)
}

/// A server on its own runtime, for the life of the benchmark.
fn start(backend: Backend) -> SocketAddr {
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .enable_all()
            .build()
            .expect("a tokio runtime");
        runtime.block_on(async move {
            let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
            tx.send(listener.local_addr().unwrap()).unwrap();
            let config = ServiceConfig {
                backend,
                ..Default::default()
            };
            supertoroid::service::serve_on(listener, config, std::future::pending())
                .await
                .unwrap();
        });
    });
    rx.recv().expect("the server's address")
}

fn bench_depth_requests(c: &mut Criterion) {
    let (depth, camera, mask) = ring_on_a_table();
    let k = camera.intrinsics;
    let encode = |image: &DepthImage| {
        base64::engine::general_purpose::STANDARD.encode(encode_depth_png(image))
    };
    let mask_pixels = mask.data.iter().filter(|&&m| m != 0).count();
    let (xs, ys): (Vec<u32>, Vec<u32>) = (0..mask.data.len() as u32)
        .filter(|&i| mask.data[i as usize] != 0)
        .map(|i| (i % k.width, i / k.width))
        .unzip();
    let (x0, x1) = (xs.iter().min().unwrap(), xs.iter().max().unwrap());
    let (y0, y1) = (ys.iter().min().unwrap(), ys.iter().max().unwrap());
    // (a detector's box: the mask's bounding box widened by 10% on every side)
    let (pad_x, pad_y) = ((x1 - x0) / 10, (y1 - y0) / 10);
    let roi = json!({
        "x": *x0 as i64 - pad_x as i64, "y": *y0 as i64 - pad_y as i64,
        "width": x1 - x0 + 1 + 2 * pad_x, "height": y1 - y0 + 1 + 2 * pad_y
    });
    let body = |selection: &str, model: Option<&str>| -> Value {
        let mut body = json!({
            "depth_png": encode(&depth),
            "intrinsics": {"fx": k.fx, "fy": k.fy, "cx": k.cx, "cy": k.cy},
            "depth_scale": DEPTH_SCALE,
            "options": {"seed": 1}
        });
        match selection {
            "mask" => body["mask_png"] = json!(encode(&mask)),
            _ => body["roi"] = roi.clone(),
        }
        if let Some(model) = model {
            body["options"]["model"] = json!(model);
        }
        body
    };
    let client = reqwest::blocking::Client::new();
    let mut group = c.benchmark_group(format!("depth request, mask of {mask_pixels} pixels"));
    group
        .sample_size(20)
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(5));
    for backend in backends() {
        let url = format!("http://{}/v1/fit/depth", start(backend));
        for (selection, model) in [("mask", None), ("mask", Some("supertoroid")), ("box", None)] {
            let body = body(selection, model).to_string();
            let name = format!("{selection}, model {}", model.unwrap_or("auto (default)"));
            let post = || post_json(&client, &url, &body);
            post();
            group.bench_function(BenchmarkId::new(format!("{backend:?}"), name), |b| {
                b.iter(post)
            });
        }
    }
    group.finish();
}

/// Whole `/v1/scene` requests: `bench scenes`' frame 860002 (five objects on a table, with
/// and without a hole, the D435-like sensor), every object fitted with `model` auto.
fn bench_scene_requests(c: &mut Criterion) {
    let frame = BenchFrame::new(860_002).expect("the frame renders");
    let k = frame.scene.camera.intrinsics;
    let body = json!({
        "depth_png": base64::engine::general_purpose::STANDARD.encode(encode_depth_png(&frame.depth)),
        "intrinsics": {"fx": k.fx, "fy": k.fy, "cx": k.cx, "cy": k.cy},
        "depth_scale": frame.depth.scale,
        "options": {"seed": 1}
    })
    .to_string();
    let client = reqwest::blocking::Client::new();
    let mut group = c.benchmark_group(format!(
        "scene request, {} objects",
        frame.scene.objects.len()
    ));
    group
        .sample_size(10)
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(15));
    for backend in backends() {
        let url = format!("http://{}/v1/scene", start(backend));
        let post = || post_json(&client, &url, &body);
        post();
        group.bench_function(format!("{backend:?}"), |b| b.iter(post));
    }
    group.finish();
}

/// `body` posted as JSON to `url`, answered 200: the answer's length (read whole).
fn post_json(client: &reqwest::blocking::Client, url: &str, body: &str) -> usize {
    let response = client
        .post(url)
        .header("content-type", "application/json")
        .body(body.to_owned())
        .send()
        .expect("the service answers");
    assert_eq!(response.status(), 200, "{}", response.text().unwrap());
    response.bytes().unwrap().len()
}

/// The CPU evaluator, and the GPU one where wgpu finds an adapter.
fn backends() -> Vec<Backend> {
    let mut backends = vec![Backend::Cpu];
    match GpuContext::shared(&AdapterChoice::from_env()) {
        Ok(_) => backends.push(Backend::Gpu),
        Err(e) => eprintln!("no GPU adapter, CPU only: {e}"),
    }
    backends
}

criterion_group!(benches, bench_depth_requests, bench_scene_requests);
criterion_main!(benches);

//! Load and soak for the service: N concurrent clients post clouds to /v1/fit and depth
//! frames to /v1/fit/depth, for a number of requests or for a time, and the report gives
//! fits per second, latency percentiles, every status seen, dropped connections, the
//! server's resident memory at the start, once a minute and at the end (with SERVER_PID
//! set) and the queue gauge once the clients are done.
//!
//!   cargo run --release --example load -- http://127.0.0.1:8080 4 200 ../shared/clouds/paper/*.pcd
//!   SERVER_PID=$(pidof supertoroid) cargo run --release --example load -- URL 16 600s depth ../shared/clouds/paper/*.pcd
//!
//! Arguments: base URL, concurrency, a request count or a duration (`600s`), then one or
//! more bodies sent in turn: cloud files (application/octet-stream, seed = request
//! number), or `depth`, a synthetic 640x480 frame of a ring on a table with the ring's box.
//! With PER_CLIENT_HZ set, each client sends at most that many requests a second (a camera's
//! frame rate) instead of the next as soon as the last is answered.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

enum Body {
    Cloud(Vec<u8>),
    Depth(serde_json::Value),
}

/// A RealSense-sized frame of a ring on a table seen from 0.5 m, and a detector's box
/// around the ring, as the depth route takes them.
fn depth_request() -> serde_json::Value {
    use base64::Engine;
    use glam::{DQuat, DVec3};
    use supertoroid::model::{Plane, Pose, Shape};
    use supertoroid::synth::{self, Camera, Intrinsics};
    let shape = Shape::new(0.02, 0.02, 0.012, 2.2, 0.8, 1.0);
    let pose = Pose::new(DQuat::from_rotation_z(0.4), DVec3::new(0.0, 0.0, shape.a3));
    let camera = Camera::look_at(
        Intrinsics::REALSENSE_640X480,
        DVec3::new(0.05, -0.35, 0.4),
        pose.translation,
        DVec3::Z,
    );
    let view = synth::render_view(&shape, &pose, &camera, 0.0001).expect("the ring is in view");
    let depth = synth::with_table(&view.depth, &camera, &Plane::through(DVec3::ZERO, DVec3::Z));
    let (u0, v0, u1, v1) = view.pixels.iter().fold((u32::MAX, u32::MAX, 0, 0), |b, p| {
        (b.0.min(p[0]), b.1.min(p[1]), b.2.max(p[0]), b.3.max(p[1]))
    });
    let k = camera.intrinsics;
    serde_json::json!({
        "depth_png": base64::engine::general_purpose::STANDARD
            .encode(supertoroid::io::depth::encode_depth_png(&depth)),
        "depth_scale": 0.0001,
        "intrinsics": {"fx": k.fx, "fy": k.fy, "cx": k.cx, "cy": k.cy},
        "roi": {"x": u0 as i64 - 15, "y": v0 as i64 - 15, "width": u1 - u0 + 30, "height": v1 - v0 + 30},
    })
}

/// The server's resident set in MB, from /proc (SERVER_PID).
fn server_rss_mb() -> Option<f64> {
    let pid = std::env::var("SERVER_PID").ok()?;
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let kb: f64 = status
        .lines()
        .find(|l| l.starts_with("VmRSS:"))?
        .split_whitespace()
        .nth(1)?
        .parse()
        .ok()?;
    Some(kb / 1024.0)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 4 {
        eprintln!("usage: load URL CONCURRENCY REQUESTS|SECONDSs BODY...");
        std::process::exit(2);
    }
    let url = args[0].trim_end_matches('/').to_owned();
    let concurrency: usize = args[1].parse().expect("concurrency");
    let (total, duration) = match args[2].strip_suffix('s') {
        Some(secs) => (
            usize::MAX,
            Some(Duration::from_secs(secs.parse().expect("seconds"))),
        ),
        None => (args[2].parse().expect("requests"), None),
    };
    let bodies: Vec<Body> = args[3..]
        .iter()
        .map(|f| match f.as_str() {
            "depth" => Body::Depth(depth_request()),
            file => Body::Cloud(std::fs::read(file).expect("file")),
        })
        .collect();
    let client = reqwest::blocking::Client::builder()
        .timeout(Duration::from_secs(60))
        .build()
        .unwrap();
    let pace = std::env::var("PER_CLIENT_HZ")
        .ok()
        .map(|hz| Duration::from_secs_f64(1.0 / hz.parse::<f64>().expect("PER_CLIENT_HZ")));
    let rss_start = server_rss_mb();
    let next = AtomicUsize::new(0);
    let start = Instant::now();
    let finished = std::sync::atomic::AtomicBool::new(false);
    let mut rss_by_minute = Vec::new();
    let results: Vec<(Duration, u16)> = std::thread::scope(|scope| {
        // the server's memory once a minute while the clients run
        let sampler = scope.spawn(|| {
            let mut samples = Vec::new();
            let mut due = Instant::now();
            while !finished.load(Ordering::Relaxed) {
                if Instant::now() >= due {
                    samples.extend(server_rss_mb().map(f64::round));
                    due += Duration::from_secs(60);
                }
                std::thread::sleep(Duration::from_millis(200));
            }
            samples
        });
        let handles: Vec<_> = (0..concurrency)
            .map(|_| {
                let (client, next, bodies, url) = (&client, &next, &bodies, &url);
                scope.spawn(move || {
                    let mut mine = Vec::new();
                    let mut due = Instant::now();
                    loop {
                        if let Some(period) = pace {
                            std::thread::sleep(due.saturating_duration_since(Instant::now()));
                            due += period;
                        }
                        let i = next.fetch_add(1, Ordering::Relaxed);
                        if i >= total || duration.is_some_and(|d| start.elapsed() >= d) {
                            break;
                        }
                        let t = Instant::now();
                        let request = match &bodies[i % bodies.len()] {
                            Body::Cloud(bytes) => client
                                .post(format!("{url}/v1/fit?seed={i}"))
                                .header("content-type", "application/octet-stream")
                                .body(bytes.clone()),
                            Body::Depth(json) => {
                                client.post(format!("{url}/v1/fit/depth")).json(json)
                            }
                        };
                        // status 0: the connection dropped or timed out
                        let status = request
                            .send()
                            .map(|r| {
                                let s = r.status().as_u16();
                                let _ = r.bytes();
                                s
                            })
                            .unwrap_or(0);
                        mine.push((t.elapsed(), status));
                    }
                    mine
                })
            })
            .collect();
        let results = handles
            .into_iter()
            .flat_map(|h| h.join().unwrap())
            .collect();
        finished.store(true, Ordering::Relaxed);
        rss_by_minute = sampler.join().unwrap();
        results
    });
    let wall = start.elapsed().as_secs_f64();
    let rss_end = server_rss_mb();
    let queued = client
        .get(format!("{url}/readyz"))
        .send()
        .ok()
        .and_then(|r| r.json::<serde_json::Value>().ok())
        .and_then(|r| r["queued"].as_u64());
    let ok = results.iter().filter(|r| r.1 == 200).count();
    let mut statuses = std::collections::BTreeMap::<u16, usize>::new();
    for (_, s) in &results {
        *statuses.entry(*s).or_default() += 1;
    }
    let mut ms: Vec<f64> = results.iter().map(|r| r.0.as_secs_f64() * 1e3).collect();
    ms.sort_by(f64::total_cmp);
    let pct = |p: f64| ms[((ms.len() - 1) as f64 * p).round() as usize];
    let report = serde_json::json!({
        "concurrency": concurrency,
        "per_client_hz": pace.map(|p| 1.0 / p.as_secs_f64()),
        "seconds": (wall * 10.0).round() / 10.0,
        "requests": results.len(),
        "ok": ok,
        "statuses": statuses,
        "fits_per_s": (ok as f64 / wall * 10.0).round() / 10.0,
        "p50_ms": pct(0.5).round(),
        "p90_ms": pct(0.9).round(),
        "p99_ms": pct(0.99).round(),
        "max_ms": ms[ms.len() - 1].round(),
        "rss_mb_start": rss_start.map(f64::round),
        "rss_mb_end": rss_end.map(f64::round),
        "rss_mb_by_minute": rss_by_minute,
        "queued_after": queued,
    });
    println!("{report}");
}

//! A small load generator for the service's benchmark (issue 6): posts cloud files to
//! /v1/fit from N concurrent clients and reports fits per second and latency percentiles.
//!
//!   cargo run --release --example load -- http://127.0.0.1:8080 4 200 ../shared/clouds/paper/*.pcd
//!
//! Arguments: base URL, concurrency, total requests, then one or more cloud files (sent
//! in turn as application/octet-stream with seed = request number).

use std::time::{Duration, Instant};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 4 {
        eprintln!("usage: load URL CONCURRENCY REQUESTS FILE...");
        std::process::exit(2);
    }
    let url = args[0].trim_end_matches('/').to_owned();
    let concurrency: usize = args[1].parse().expect("concurrency");
    let total: usize = args[2].parse().expect("requests");
    let bodies: Vec<Vec<u8>> = args[3..]
        .iter()
        .map(|f| std::fs::read(f).expect("file"))
        .collect();
    let client = reqwest::blocking::Client::builder()
        .timeout(Duration::from_secs(60))
        .build()
        .unwrap();
    let next = std::sync::atomic::AtomicUsize::new(0);
    let start = Instant::now();
    let results: Vec<(Duration, u16)> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..concurrency)
            .map(|_| {
                let (client, next, bodies, url) = (&client, &next, &bodies, &url);
                scope.spawn(move || {
                    let mut mine = Vec::new();
                    loop {
                        let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        if i >= total {
                            break;
                        }
                        let t = Instant::now();
                        let status = client
                            .post(format!("{url}/v1/fit?seed={i}"))
                            .header("content-type", "application/octet-stream")
                            .body(bodies[i % bodies.len()].clone())
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
        handles
            .into_iter()
            .flat_map(|h| h.join().unwrap())
            .collect()
    });
    let wall = start.elapsed().as_secs_f64();
    let ok = results.iter().filter(|r| r.1 == 200).count();
    let mut ms: Vec<f64> = results.iter().map(|r| r.0.as_secs_f64() * 1e3).collect();
    ms.sort_by(f64::total_cmp);
    let pct = |p: f64| ms[((ms.len() - 1) as f64 * p).round() as usize];
    println!(
        "{{\"concurrency\": {concurrency}, \"requests\": {total}, \"ok\": {ok}, \"fits_per_s\": {:.1}, \"p50_ms\": {:.1}, \"p90_ms\": {:.1}, \"p99_ms\": {:.1}, \"max_ms\": {:.1}}}",
        ok as f64 / wall,
        pct(0.5),
        pct(0.9),
        pct(0.99),
        ms[ms.len() - 1]
    );
}

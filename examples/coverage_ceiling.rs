//! How much of a real cloud any supertoroid near the fit can cover: the fit (seed 0), then
//! a random local search that maximises the share of points within a *fixed* tolerance of
//! the surface (2% of the fit's size, the paper grade's coverage rule), over all twelve
//! parameters, from several seeds. The tolerance is held at the fit's size because the
//! grade's tolerance grows with the surface's own size, which a search would otherwise
//! inflate to loosen it.
//!
//! Why: the paper's gear grades Decent, not Good, on coverage alone (68-73% of its points
//! within 2% of the size; Good needs 75%). If no supertoroid near the fit reaches 75%,
//! the shortfall is the model's (a gear's teeth are not supertoroid-shaped), not the
//! fit's.
//!
//! `cargo run --release --example coverage_ceiling -- CLOUD [RESTARTS] [STEPS]`

use glam::{DQuat, DVec3};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;
use std::path::Path;
use supertoroid::eval::Backend;
use supertoroid::fit::{FitOptions, fit};
use supertoroid::model::{Pose, Shape, meridian_distance};

/// The share of `points` within `tolerance` of the surface (meridian distance).
fn coverage(shape: &Shape, pose: &Pose, points: &[DVec3], tolerance: f64) -> f64 {
    let within = points
        .par_iter()
        .filter(|p| meridian_distance(shape, pose.to_canonical(**p)).distance <= tolerance)
        .count();
    within as f64 / points.len() as f64
}

/// One perturbation of (shape, pose) at relative step `k`: sizes and a4 by a factor
/// 1 + k·N(0,1), eps by 3k·N(0,1) within [0.1, 2], the centre by 0.3k of the size, the
/// rotation by 0.5k radians; one group at a time, or all together.
fn perturb(shape: &Shape, pose: &Pose, size: f64, k: f64, rng: &mut StdRng) -> (Shape, Pose) {
    let which: u32 = rng.random_range(0..4);
    let mut normal = || -> f64 { StandardNormal.sample(&mut *rng) };
    let (mut s, mut p) = (*shape, *pose);
    if which == 0 || which == 3 {
        s.a1 *= 1.0 + k * normal();
        s.a2 *= 1.0 + k * normal();
        s.a3 *= 1.0 + k * normal();
        s.a4 *= 1.0 + k * normal();
    }
    if which == 1 || which == 3 {
        s.eps1 = (s.eps1 + 3.0 * k * normal()).clamp(0.1, 2.0);
        s.eps2 = (s.eps2 + 3.0 * k * normal()).clamp(0.1, 2.0);
    }
    if which == 2 || which == 3 {
        p.translation += DVec3::new(normal(), normal(), normal()) * (0.3 * k * size);
        let turn = DVec3::new(normal(), normal(), normal()) * (0.5 * k);
        p.rotation = (DQuat::from_scaled_axis(turn) * p.rotation).normalize();
    }
    (s, p)
}

fn main() {
    let mut args = std::env::args().skip(1);
    let path = args
        .next()
        .expect("usage: coverage_ceiling CLOUD [RESTARTS] [STEPS]");
    let restarts: u64 = args
        .next()
        .map_or(6, |s| s.parse().expect("RESTARTS is a number"));
    let steps: usize = args
        .next()
        .map_or(4000, |s| s.parse().expect("STEPS is a number"));
    let points = supertoroid::io::read_cloud(Path::new(&path), None).expect("a readable cloud");
    let mut evaluator = supertoroid::eval::make_evaluator(Backend::Cpu, 1000).expect("the CPU");
    let report = fit(evaluator.as_mut(), &points, &FitOptions::default()).expect("a fit");
    let (shape, pose) = report.fitted;
    let size = shape.size();
    let tolerance = 0.02 * size;
    let start = coverage(&shape, &pose, &points, tolerance);
    println!(
        "{path}: {} points, fit coverage {:.1}% within {:.3e} (2% of the size {:.3e})",
        points.len(),
        100.0 * start,
        tolerance,
        size
    );
    let mut best = start;
    for restart in 0..restarts {
        let mut rng = StdRng::seed_from_u64(restart);
        let (mut s, mut p, mut covered) = (shape, pose, start);
        for step in 0..steps {
            // steps shrink from 3.2% to 0.2% (relative) over the search
            let k = 0.03 * (1.0 - step as f64 / steps as f64) + 0.002;
            let (ts, tp) = perturb(&s, &p, size, k, &mut rng);
            let c = coverage(&ts, &tp, &points, tolerance);
            if c >= covered {
                (s, p, covered) = (ts, tp, c);
            }
        }
        println!(
            "  search {restart}: {:.1}%  (a1 {:.4} a2 {:.4} a3 {:.4} a4 {:.3} eps1 {:.3} eps2 {:.3}, centre moved {:.2}% of the size)",
            100.0 * covered,
            s.a1,
            s.a2,
            s.a3,
            s.a4,
            s.eps1,
            s.eps2,
            100.0 * (p.translation - pose.translation).length() / size
        );
        best = best.max(covered);
    }
    println!("most covered: {:.1}%", 100.0 * best);
}

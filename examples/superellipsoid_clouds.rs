//! The model-choice suite's superellipsoid cases as plain clouds, for fitting them with
//! another method, and those fits judged by the suite's rule beside this crate's own.
//!
//! ```sh
//! # each superellipsoid case of `bench models --seed S` as DIR/<case seed>.xyz (x y z a
//! # line, metres; a single view in its camera's frame, as users post it)
//! cargo run --release --example superellipsoid_clouds -- export DIR S CASES
//! # fits of those clouds (DIR/fits.json: [{"seed", "shape": [a1, a2, a3, eps1, eps2],
//! # "rotation": 3x3 row-major, "translation": [x, y, z], "ms"}] in each cloud's own
//! # frame) judged by the surface chamfer under 2% of the size, beside this crate's fits
//! # of the same clouds with model superellipsoid and model auto
//! cargo run --release --example superellipsoid_clouds -- judge DIR S CASES
//! ```
//!
//! `scripts/ems_fits.py` writes `fits.json` with EMS (Liu et al., CVPR 2022, its
//! released Python implementation); `docs/scenes.md` has the comparison.

use glam::{DMat3, DQuat, DVec3};
use supertoroid::bench::synthetic::{Presentation, category, presented};
use supertoroid::eval::CpuEvaluator;
use supertoroid::fit::{FitOptions, Model, fit};
use supertoroid::model::{Pose, Shape};
use supertoroid::suite::chamfer::{CHAMFER_BOUND, relative_chamfer};
use supertoroid::suite::ground_truth::{Case, Kind, make_case_of};

/// The superellipsoid cases of a model-choice run of `cases` from `seed` (its odd cases),
/// each with its seed and its category.
fn superellipsoid_cases(seed: u64, cases: usize) -> Vec<(u64, Case)> {
    (1..cases)
        .step_by(2)
        .map(|i| {
            let (partial, noise, outliers) = category(i / 2);
            let case_seed = seed + i as u64;
            let case = make_case_of(Kind::Superellipsoid, case_seed, partial, noise, outliers);
            (case_seed, case)
        })
        .collect()
}

fn export(dir: &str, seed: u64, cases: usize) {
    std::fs::create_dir_all(dir).expect("the output directory");
    for (case_seed, case) in superellipsoid_cases(seed, cases) {
        let (points, _, _) = presented(&case, Presentation::Camera);
        let text: String = points
            .iter()
            .map(|p| format!("{} {} {}\n", p.x, p.y, p.z))
            .collect();
        std::fs::write(format!("{dir}/{case_seed}.xyz"), text).expect("a cloud written");
    }
}

#[derive(serde::Deserialize)]
struct OtherFit {
    seed: u64,
    shape: [f64; 5],
    rotation: [[f64; 3]; 3],
    translation: [f64; 3],
    ms: f64,
}

/// One method's fits: how many were right (chamfer under the bound) of how many, full
/// clouds and single views apart, and their times.
struct Tally {
    name: &'static str,
    right: [usize; 2],
    cases: [usize; 2],
    ms: Vec<f64>,
}

impl Tally {
    fn new(name: &'static str) -> Self {
        Self {
            name,
            right: [0; 2],
            cases: [0; 2],
            ms: Vec::new(),
        }
    }
    fn add(&mut self, partial: bool, right: bool, ms: f64) {
        self.cases[partial as usize] += 1;
        self.right[partial as usize] += right as usize;
        self.ms.push(ms);
    }
    fn line(&mut self) -> String {
        self.ms.sort_by(f64::total_cmp);
        let at = |q: f64| self.ms[((self.ms.len() - 1) as f64 * q).round() as usize];
        format!(
            "| {} | {} of {} | {} of {} | {} of {} | {:.0} / {:.0} |",
            self.name,
            self.right[0] + self.right[1],
            self.cases[0] + self.cases[1],
            self.right[0],
            self.cases[0],
            self.right[1],
            self.cases[1],
            at(0.5),
            at(0.9)
        )
    }
}

fn judge(dir: &str, seed: u64, cases: usize) {
    let text = std::fs::read_to_string(format!("{dir}/fits.json")).expect("DIR/fits.json");
    let others: Vec<OtherFit> = serde_json::from_str(&text).expect("fits.json as documented");
    let mut tallies = [
        Tally::new("other"),
        Tally::new("superellipsoid"),
        Tally::new("auto"),
    ];
    let mut evaluator = CpuEvaluator::new();
    for (case_seed, case) in superellipsoid_cases(seed, cases) {
        let (points, viewpoint, back) = presented(&case, Presentation::Camera);
        let truth = (&case.shape, &case.pose);
        let chamfer =
            |shape: &Shape, pose: &Pose| relative_chamfer(truth, (shape, &back.compose(pose)));
        let Some(other) = others.iter().find(|o| o.seed == case_seed) else {
            panic!("no fit of case {case_seed} in fits.json");
        };
        let [a1, a2, a3, eps1, eps2] = other.shape;
        let rotation = DMat3::from_cols_array_2d(&other.rotation).transpose();
        let pose = Pose::new(DQuat::from_mat3(&rotation), DVec3::from(other.translation));
        let c = chamfer(&Shape::new(a1, a2, a3, 0.0, eps1, eps2), &pose);
        tallies[0].add(case.partial, c < CHAMFER_BOUND, other.ms);
        let mut line = format!(
            "{case_seed} partial {} noise {} outliers {} other {c:.4}",
            case.partial, case.noise, case.outlier_fraction
        );
        for (k, model) in [Model::Superellipsoid, Model::Auto].into_iter().enumerate() {
            let options = FitOptions {
                seed: case_seed,
                viewpoint,
                model,
                ..Default::default()
            };
            let (right, ms, c) = match fit(&mut evaluator, &points, &options) {
                Ok(r) => {
                    let c = chamfer(&r.fitted.0, &r.fitted.1);
                    let model_right = r.model.kind == Model::Superellipsoid;
                    (model_right && c < CHAMFER_BOUND, r.timing_ms.total, c)
                }
                Err(_) => (false, f64::NAN, f64::NAN),
            };
            tallies[k + 1].add(case.partial, right, ms);
            line += &format!(" {model:?} {c:.4}");
        }
        eprintln!("{line}");
    }
    println!("| fit | right | full clouds | single views | median / p90 ms |");
    println!("|---|---|---|---|---|");
    for t in &mut tallies {
        println!("{}", t.line());
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let usage = "usage: superellipsoid_clouds export|judge DIR SEED CASES";
    let [_, command, dir, seed, cases] = &args[..] else {
        eprintln!("{usage}");
        std::process::exit(2);
    };
    let (Ok(seed), Ok(cases)) = (seed.parse(), cases.parse()) else {
        eprintln!("{usage}");
        std::process::exit(2);
    };
    match command.as_str() {
        "export" => export(dir, seed, cases),
        "judge" => judge(dir, seed, cases),
        _ => {
            eprintln!("{usage}");
            std::process::exit(2);
        }
    }
}

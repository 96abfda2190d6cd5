//! Writes, for each case of the ground-truth suite, the true object as an MJCF scene
//! (`export`) and the best grasp planned on its fit (`grasp.json`), for
//! `scripts/grasp_lift.py` to close a simulated gripper at that grasp in MuJoCo and lift.
//! A case whose fit is refused or whose fit has no grasp gets a `grasp.json` with a null
//! grasp and the reason, so that the lift check counts it as not held.
//! `cargo run --release --example grasp_lift -- CASES SEED OUT_DIR`

use supertoroid::bench::grasps::{FRICTION, gripper_for};
use supertoroid::eval::CpuEvaluator;
use supertoroid::fit::{FitOptions, fit};
use supertoroid::grasp::{GraspRequest, plan::plan};
use supertoroid::suite::ground_truth::{compare, make_case};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let cases: usize = args.get(1).and_then(|a| a.parse().ok()).unwrap_or(36);
    let seed: u64 = args.get(2).and_then(|a| a.parse().ok()).unwrap_or(260_000);
    let out = std::path::PathBuf::from(args.get(3).map_or("grasp-lift", |s| s.as_str()));
    let mut evaluator = CpuEvaluator::new();
    for i in 0..cases {
        let (partial, noise, outliers) = supertoroid::bench::synthetic::category(i);
        let case_seed = seed + i as u64;
        let case = make_case(case_seed, partial, noise, outliers);
        let dir = out.join(format!("case-{case_seed}"));
        let scene = supertoroid::export::SceneExport::new(
            vec![(case.shape, case.pose)],
            None,
            None,
            supertoroid::export::DEFAULT_DENSITY,
        )
        .expect("scene");
        supertoroid::export::write(&scene, &dir).expect("write");
        let gripper = gripper_for(&case.shape);
        let mut record = serde_json::json!({
            "seed": case_seed, "partial": partial, "noise": noise, "outliers": outliers,
            "gripper": gripper, "finger_thickness": gripper.thickness(),
            "fit_success": false, "grasp": null,
        });
        let options = FitOptions {
            seed: case_seed,
            viewpoint: case.viewpoint.into(),
            ..Default::default()
        };
        match fit(&mut evaluator, &case.points, &options) {
            Err(error) => record["why_none"] = format!("fit refused: {error}").into(),
            Ok(report) => {
                let (shape, pose) = report.fitted;
                record["fit_success"] = compare((&case.shape, &case.pose), (&shape, &pose))
                    .success()
                    .into();
                let planned = plan(&GraspRequest {
                    shape,
                    pose,
                    gripper,
                    friction: FRICTION,
                    plane: None,
                    viewpoint: case.viewpoint,
                    max_grasps: 1,
                })
                .expect("plan");
                match planned.grasps.first() {
                    Some(grasp) => record["grasp"] = serde_json::to_value(grasp).expect("json"),
                    None => {
                        record["why_none"] =
                            format!("no grasp on the fit: {:?}", planned.rejected).into()
                    }
                }
            }
        }
        std::fs::write(dir.join("grasp.json"), record.to_string()).expect("grasp.json");
    }
}

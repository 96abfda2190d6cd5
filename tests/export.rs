//! Scene export: the meshes' mass properties against closed forms, the MJCF loaded and
//! simulated in real MuJoCo (the `mujoco` Python package), the URDF parsed by urdfdom's
//! `check_urdf`. Both tools are installed by `.ci/run`; a missing one fails the test.

use glam::{DQuat, DVec3};
use std::path::Path;
use std::process::Command;
use supertoroid::export::{self, SceneExport, meshes};
use supertoroid::model::{Plane, Pose, Shape};

#[test]
fn mass_properties_match_a_sphere_and_a_torus() {
    let r = 0.05;
    let sphere = Shape::new(r, r, r, 0.0, 1.0, 1.0);
    let (volume, com, inertia) = meshes::mass_properties(&meshes::visual(&sphere));
    let exact = 4.0 / 3.0 * std::f64::consts::PI * r.powi(3);
    assert!((volume / exact - 1.0).abs() < 0.01, "{volume} vs {exact}");
    assert!(com.length() < 1e-9);
    let i_exact = 0.4 * exact * r * r;
    for i in [inertia.x_axis.x, inertia.y_axis.y, inertia.z_axis.z] {
        assert!((i / i_exact - 1.0).abs() < 0.02, "{i} vs {i_exact}");
    }
    assert!(inertia.x_axis.y.abs() < 1e-6 * i_exact);
    // torus: tube radius a, centre radius R = a4·a: V = 2 pi² R a²
    let (a, big_r) = (0.01, 0.03);
    let torus = Shape::new(a, a, a, big_r / a, 1.0, 1.0);
    let (volume, _, _) = meshes::mass_properties(&meshes::visual(&torus));
    let exact = 2.0 * std::f64::consts::PI.powi(2) * big_r * a * a;
    assert!((volume / exact - 1.0).abs() < 0.01, "{volume} vs {exact}");
}

/// A ring lying flat, a box and an upright can, each resting on the table z = 0.
fn table_scene(sink: f64) -> SceneExport {
    let ring = Shape::new(0.015, 0.015, 0.008, 2.5, 1.0, 1.0);
    let cracker_box = Shape::new(0.03, 0.02, 0.05, 0.0, 0.2, 0.2);
    let can = Shape::new(0.033, 0.033, 0.05, 0.0, 0.2, 1.0);
    let objects = vec![
        (
            ring,
            Pose::new(
                DQuat::from_rotation_z(0.3),
                DVec3::new(0.0, 0.0, ring.a3 - sink),
            ),
        ),
        (
            cracker_box,
            Pose::new(
                DQuat::from_rotation_z(-0.5),
                DVec3::new(0.15, 0.0, cracker_box.a3),
            ),
        ),
        (
            can,
            Pose::new(DQuat::IDENTITY, DVec3::new(-0.15, 0.05, can.a3)),
        ),
    ];
    SceneExport::new(
        objects,
        Some(Plane::through(DVec3::ZERO, DVec3::Z)),
        None,
        500.0,
    )
    .unwrap()
}

fn mujoco_rest(scene: &Path) -> (bool, String) {
    let out = Command::new("python3")
        .arg(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/scripts/mujoco_rest.py"
        ))
        .arg(scene)
        .output()
        .expect("python3");
    let text =
        String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
    assert!(
        !text.contains("No module named 'mujoco'"),
        "the mujoco Python package is missing (pip install mujoco; .ci/run installs it)"
    );
    (out.status.success(), text)
}

#[test]
fn the_exported_scene_rests_on_its_table_in_mujoco_and_parses_as_urdf() {
    let dir = std::env::temp_dir().join(format!("supertoroid-export-{}", std::process::id()));
    let written = export::write(&table_scene(0.0), &dir).unwrap();
    // the ring in 16 convex pieces, the box and the can in one each
    let pieces = written
        .iter()
        .filter(|p| p.extension().unwrap() == "stl")
        .count();
    assert_eq!(pieces, 16 + 1 + 1);
    let (ok, report) = mujoco_rest(&dir.join("scene.xml"));
    println!("{report}");
    assert!(ok, "{report}");
    assert!(report.contains("\"bodies\": 3"), "{report}");
    let check = Command::new("check_urdf")
        .arg(dir.join("scene.urdf"))
        .output()
        .expect("check_urdf (Debian's liburdfdom-tools; .ci/run installs it)");
    let text = String::from_utf8_lossy(&check.stdout);
    assert!(
        check.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&check.stderr)
    );
    assert!(
        text.contains("robot name is: supertoroid_scene") && text.contains("object_2"),
        "{text}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn an_object_sunk_into_the_table_fails_the_rest_check() {
    // the negative control: the same check refuses a ring put 5 mm into the table
    let dir = std::env::temp_dir().join(format!("supertoroid-export-sunk-{}", std::process::id()));
    export::write(&table_scene(0.005), &dir).unwrap();
    let (ok, report) = mujoco_rest(&dir.join("scene.xml"));
    println!("{report}");
    assert!(!ok, "{report}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_world_frame_moves_objects_and_table_and_gravity_follows_the_table() {
    // a camera 0.5 m above the table looking down (optical z down the world's -z)
    let world_from_camera = Pose::new(
        DQuat::from_rotation_x(std::f64::consts::PI),
        DVec3::new(0.0, 0.0, 0.5),
    );
    let plane_in_camera = Plane::through(DVec3::new(0.0, 0.0, 0.5), -DVec3::Z);
    let shape = Shape::new(0.03, 0.03, 0.03, 0.0, 1.0, 1.0);
    let in_camera = Pose::new(DQuat::IDENTITY, DVec3::new(0.0, 0.0, 0.47));
    let scene = SceneExport::new(
        vec![(shape, in_camera)],
        Some(plane_in_camera),
        Some(world_from_camera),
        500.0,
    )
    .unwrap();
    assert!((scene.objects[0].pose.translation - DVec3::new(0.0, 0.0, 0.03)).length() < 1e-12);
    assert!((scene.gravity() - DVec3::new(0.0, 0.0, -9.81)).length() < 1e-12);
    assert!(SceneExport::new(vec![], None, None, 500.0).is_err());
    assert!(SceneExport::new(vec![(shape, in_camera)], None, None, -1.0).is_err());
}

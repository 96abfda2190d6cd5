//! Synthetic clouds: surface sampling, the single-view renderer and its depth image.

use glam::{DQuat, DVec3};
use supertoroid::model::{Pose, Shape, meridian_distance};
use supertoroid::synth::{self, Camera, Intrinsics};

fn mug() -> (Shape, Pose) {
    let shape = Shape::new(0.05, 0.04, 0.03, 2.0, 0.6, 1.3);
    let pose = Pose::new(
        DQuat::from_euler(glam::EulerRot::XYZ, 0.4, -0.3, 1.0),
        DVec3::new(0.1, -0.2, 0.6),
    );
    (shape, pose)
}

#[test]
fn surface_samples_are_on_the_surface_and_reproducible() {
    let (shape, pose) = mug();
    let a = synth::sample_surface(&shape, &pose, 3000, &mut synth::rng(1));
    let b = synth::sample_surface(&shape, &pose, 3000, &mut synth::rng(1));
    let c = synth::sample_surface(&shape, &pose, 3000, &mut synth::rng(2));
    assert_eq!(a, b);
    assert_ne!(a, c);
    for p in &a {
        assert!(meridian_distance(&shape, pose.to_canonical(*p)).distance < 1e-12);
    }
}

#[test]
fn surface_samples_are_spread_by_area() {
    // Circular torus: the area element is proportional to the distance from the axis,
    // (a4 + cos eta), so the outer half (rho > a·a4) holds (pi·a4 + 2)/(2·pi·a4) of the area.
    let a4 = 2.0;
    let shape = Shape::new(1.0, 1.0, 1.0, a4, 1.0, 1.0);
    let pts = synth::sample_surface(&shape, &Pose::IDENTITY, 40_000, &mut synth::rng(3));
    let outer = pts.iter().filter(|p| p.x.hypot(p.y) > a4).count() as f64 / pts.len() as f64;
    let expected = (std::f64::consts::PI * a4 + 2.0) / (2.0 * std::f64::consts::PI * a4);
    assert!(
        (outer - expected).abs() < 0.01,
        "outer fraction {outer}, expected {expected}"
    );
    // and evenly around the axis
    let quadrant = pts.iter().filter(|p| p.x > 0.0 && p.y > 0.0).count() as f64 / pts.len() as f64;
    assert!((quadrant - 0.25).abs() < 0.01);
}

#[test]
fn noise_and_outliers_have_the_requested_size() {
    let (shape, pose) = mug();
    let mut rng = synth::rng(4);
    let clean = synth::sample_surface(&shape, &pose, 5000, &mut rng);
    let mut noisy = clean.clone();
    let sigma = 0.01 * shape.size();
    synth::add_noise(&mut noisy, sigma, &mut rng);
    let var: f64 = clean
        .iter()
        .zip(&noisy)
        .map(|(a, b)| (*a - *b).length_squared())
        .sum::<f64>()
        / (3.0 * clean.len() as f64);
    assert!((var.sqrt() / sigma - 1.0).abs() < 0.05);
    let mut with_outliers = clean.clone();
    synth::add_outliers(&mut with_outliers, &shape, &pose, 0.1, &mut rng);
    assert_eq!(with_outliers.len(), (5000.0 / 0.9f64).round() as usize);
    let half = shape.half_extents() * 1.1 + DVec3::splat(1e-12);
    for p in &with_outliers[5000..] {
        let c = pose.to_canonical(*p);
        assert!(c.abs().cmple(half).all());
    }
}

#[test]
fn rendered_points_face_the_camera_are_unoccluded_and_match_the_depth_image() {
    let (shape, pose) = mug();
    let intrinsics = Intrinsics {
        fx: 300.0,
        fy: 300.0,
        cx: 79.5,
        cy: 59.5,
        width: 160,
        height: 120,
    };
    for seed in 0..4u64 {
        let camera = Camera::random_view(&shape, &pose, intrinsics, &mut synth::rng(seed));
        let view = synth::render_view(&shape, &pose, &camera, 1e-4).unwrap();
        assert!(
            view.points.len() > 500,
            "only {} points seen",
            view.points.len()
        );
        let eye = camera.pose.translation;
        let eye_c = pose.to_canonical(eye);
        for p in &view.points {
            let c = pose.to_canonical(*p);
            // on the surface
            assert!(meridian_distance(&shape, c).distance < 1e-7 * shape.size());
            // faces the camera: the outward gradient of F_t points towards the eye
            let h = 1e-7;
            let grad = DVec3::new(
                shape.inside_outside(c + DVec3::X * h) - shape.inside_outside(c - DVec3::X * h),
                shape.inside_outside(c + DVec3::Y * h) - shape.inside_outside(c - DVec3::Y * h),
                shape.inside_outside(c + DVec3::Z * h) - shape.inside_outside(c - DVec3::Z * h),
            );
            assert!(grad.dot(eye_c - c) > 0.0, "a back-facing point was kept");
            // unoccluded: dense samples of the segment eye -> p stay outside the solid
            // (up to the last 1e-4 of the way, where the segment meets the surface)
            for i in 1..2000 {
                let q = eye_c + (c - eye_c) * (i as f64 / 2000.0 * (1.0 - 1e-4));
                assert!(shape.inside_outside(q) > 1.0, "occluded point kept");
            }
        }
        // the depth image back-projects to the same points (within the depth quantum)
        let from_depth = view.depth.back_project(&intrinsics);
        assert_eq!(from_depth.len(), view.points.len());
        for (cam_point, world) in from_depth.iter().zip(&view.points) {
            let expected = camera.pose.to_canonical(*world);
            assert!(
                (*cam_point - expected).length() < 1e-4,
                "{cam_point} vs {expected}"
            );
        }
        // every pixel with depth has exactly one point, in row-major order
        let lit = view.depth.data.iter().filter(|&&d| d != 0).count();
        assert_eq!(lit, view.pixels.len());
    }
}

#[test]
fn renderer_rejects_bad_input() {
    let (shape, pose) = mug();
    let mut k = Intrinsics::REALSENSE_640X480;
    k.fx = 0.0;
    let camera = Camera::look_at(k, DVec3::new(0.0, 0.0, -1.0), DVec3::ZERO, DVec3::Y);
    assert!(synth::render_view(&shape, &pose, &camera, 0.001).is_err());
    let camera = Camera::look_at(
        Intrinsics::REALSENSE_640X480,
        DVec3::new(0.0, 0.0, -1.0),
        DVec3::ZERO,
        DVec3::Y,
    );
    assert!(synth::render_view(&shape, &pose, &camera, 0.0).is_err());
}

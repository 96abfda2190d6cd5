//! The broadened single-view suite: shapes users have beyond the ground-truth suite's
//! ranges, seen through a D435-like sensor, given as users post them (the cloud in its
//! camera's frame).
//!
//! - Shape families, by seed mod 4 ([`FAMILIES`]): the suite's ranges; tall rolls and
//!   tubes (a3 from one to three times a1·a4, the hole along the longest extent); thin
//!   washers (a3 4-12 mm); oval rings (a1/a2 from 1.3 to 2).
//! - The sensor ([`crate::synth::scene::with_sensor_noise`]): depth noise along the ray of
//!   1 mm at 0.5 m growing with the range squared, 1 mm quantisation, flying pixels at 30%
//!   of the silhouette edges; the object 0.4-0.9 m from the camera (farther where it would
//!   not fit in the image).
//! - 1000-5000 of the view's points; on every other cloud 5% outliers over the scene's
//!   box (twice the object's extent about it, towards the camera as well).
//!
//! Success is the ground-truth suite's rule ([`super::ground_truth::compare`]).

use super::ground_truth::{Case, random_shape};
use crate::model::{Pose, Shape};
use crate::synth::scene::with_sensor_noise;
use crate::synth::{self, Camera, Intrinsics, SeededRng};
use glam::{DQuat, DVec3};
use rand::Rng;

/// The shape families, in the order of `seed % 4`.
pub const FAMILIES: [&str; 4] = ["suite ranges", "tall rolls", "thin washers", "oval rings"];

/// The sensor's depth noise at half a metre (it grows with the range squared).
pub const SIGMA_AT_HALF_METRE: f64 = 0.001;

/// A shape of family `family` and a random rotation axis.
fn shape_of(family: usize, rng: &mut SeededRng) -> (Shape, DVec3) {
    let (suite, axis) = random_shape(rng);
    let shape = match family {
        1 => {
            let a1 = rng.random_range(0.02..0.05);
            let a4 = rng.random_range(1.2..2.0);
            Shape::new(
                a1,
                a1 * rng.random_range(0.9..1.1),
                a1 * a4 * rng.random_range(1.0..3.0),
                a4,
                rng.random_range(0.2..1.0),
                rng.random_range(0.8..1.2),
            )
        }
        2 => Shape::new(
            rng.random_range(0.03..0.10),
            rng.random_range(0.03..0.10),
            rng.random_range(0.004..0.012),
            rng.random_range(1.5..3.0),
            rng.random_range(0.3..1.5),
            rng.random_range(0.3..1.5),
        ),
        3 => {
            let a1 = rng.random_range(0.05..0.12);
            Shape::new(
                a1,
                a1 / rng.random_range(1.3..2.0),
                rng.random_range(0.01..0.05),
                rng.random_range(1.2..3.0),
                rng.random_range(0.3..1.8),
                rng.random_range(0.3..1.8),
            )
        }
        _ => suite,
    };
    (shape, axis)
}

/// Where a single view puts its object: turned about `axis` by a random angle,
/// `distance` in front of a camera at the origin of its optical frame (x right, y down,
/// z forward) and up to a tenth of that off its axis; the camera looking at it.
pub fn in_front_of_camera(
    rng: &mut SeededRng,
    axis: DVec3,
    distance: f64,
    intrinsics: Intrinsics,
) -> (Pose, Camera) {
    let pose = Pose::new(
        DQuat::from_axis_angle(axis, rng.random_range(-3.1..3.1)),
        DVec3::new(
            rng.random_range(-0.1..0.1) * distance,
            rng.random_range(-0.1..0.1) * distance,
            distance,
        ),
    );
    let camera = Camera::look_at(intrinsics, DVec3::ZERO, pose.translation, DVec3::NEG_Y);
    (pose, camera)
}

/// The view of seed `seed` in its camera's frame through the sensor, with the truth in
/// that frame; its noise is the sensor's sigma at the object's range over the size, its
/// viewpoint the origin. Its family is `FAMILIES[seed % 4]`.
pub fn view(seed: u64) -> Case {
    let mut rng = synth::rng(seed);
    let (shape, axis) = shape_of((seed % 4) as usize, &mut rng);
    let intrinsics = Intrinsics::REALSENSE_640X480;
    // a table-top robot's range, and far enough for the object to fit in the image
    let distance = rng
        .random_range(0.4f64..0.9)
        .max(intrinsics.fy * shape.size() / (0.8 * intrinsics.height as f64));
    let (pose, camera) = in_front_of_camera(&mut rng, axis, distance, intrinsics);
    let rendered = synth::render_view(&shape, &pose, &camera, 0.001).expect("a valid view");
    let depth = with_sensor_noise(&rendered.depth, SIGMA_AT_HALF_METRE, 0.3, seed);
    let seen = depth.back_project(&intrinsics);
    let count = rng.random_range(1000..=5000);
    let mut points = synth::subsample(&seen, count, &mut rng);
    let in_camera = Pose::new(
        camera.pose.rotation.inverse() * pose.rotation,
        camera.pose.to_canonical(pose.translation),
    );
    let inliers = points.len();
    let with_outliers = seed % 2 == 1;
    if with_outliers {
        let half = shape.half_extents().max_element() * 2.0;
        let extra = points.len() * 5 / 95;
        for _ in 0..extra {
            let offset = DVec3::new(
                rng.random_range(-half..half),
                rng.random_range(-half..half),
                rng.random_range(-half..half),
            );
            points.push(in_camera.translation + offset);
        }
    }
    Case {
        shape,
        pose: in_camera,
        partial: true,
        noise: SIGMA_AT_HALF_METRE * (distance / 0.5).powi(2) / shape.size(),
        outlier_fraction: if with_outliers { 0.05 } else { 0.0 },
        points,
        inliers,
        viewpoint: Some(DVec3::ZERO),
    }
}

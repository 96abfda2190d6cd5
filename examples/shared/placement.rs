//! Where the examples' single views put their object: in front of a camera at the origin
//! of its optical frame (x right, y down, z forward), a little off the optical axis.

use glam::{DQuat, DVec3};
use rand::Rng;
use supertoroid::model::Pose;
use supertoroid::synth::{Camera, Intrinsics, SeededRng};

/// The object turned about `axis` by a random angle, `distance` in front of the camera
/// and up to a tenth of that off its axis; the camera at the origin looking at it.
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

//! What the robot does with a fit (paper §IV): surface queries (points, normals,
//! principal curvatures) and parallel-jaw grasps on the fitted surface.
//!
//! * [`surface`]: the surface's differential geometry in the world frame, on a grid, at
//!   parameters, or nearest to points.
//! * [`gripper`]: the gripper's parameters and the boxes its fingers and palm sweep.
//! * [`plan`]: candidate grasps from the shape, checked (opening, friction cone,
//!   collisions with the surface and the support plane, approach from behind) and ranked.

pub mod gripper;
pub mod plan;
pub mod surface;

pub use gripper::Gripper;
pub use plan::{Grasp, GraspKind, GraspPlan, GraspRequest, Rejections, ScoreTerms, graspnet_row};
pub use surface::SurfacePoint;

use crate::model::{Pose, Shape};
use glam::DVec3;

/// A grasp planned on one surface, checked on another (the true object's, in tests and
/// benchmarks): how far its contacts lie from that surface and whether that surface's
/// normals at the nearest points are inside the friction cone of the closing line.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ContactCheck {
    pub distance: [f64; 2],
    pub antipodal: bool,
}

pub fn check_on_surface(shape: &Shape, pose: &Pose, grasp: &Grasp, friction: f64) -> ContactCheck {
    let closing = DVec3::from_array(grasp.closing);
    let cone_cos = 1.0 / (1.0 + friction * friction).sqrt();
    let mut distance = [f64::INFINITY; 2];
    let mut antipodal = true;
    for (i, side) in [-1.0, 1.0].into_iter().enumerate() {
        let contact = DVec3::from_array(grasp.contacts[i]);
        match surface::nearest(shape, pose, contact) {
            Ok(near) => {
                distance[i] = contact.distance(DVec3::from_array(near.point));
                antipodal &= DVec3::from_array(near.normal).dot(closing * side) >= cone_cos;
            }
            Err(_) => antipodal = false,
        }
    }
    ContactCheck {
        distance,
        antipodal,
    }
}

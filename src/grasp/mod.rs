//! What the robot does with a fit (paper §IV): surface queries (points, normals,
//! principal curvatures) and parallel-jaw grasps on the fitted surface.
//!
//! * [`surface`]: the surface's differential geometry in the world frame, on a grid, at
//!   parameters, or nearest to points.
//! * [`gripper`]: the gripper's parameters and the boxes its fingers and palm sweep.
//! * [`collision`]: whether the hand meets the surface (bounding spheres of cells,
//!   split near the hand).
//! * [`plan`]: candidate grasps from the shape, checked (opening, friction cone,
//!   collisions with the surface and the support plane, approach from behind) and ranked.

pub mod collision;
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

/// Default Coulomb friction at the contacts (rubber pads on plastic or cardboard).
pub const DEFAULT_FRICTION: f64 = 0.5;
/// Default number of grasps answered.
pub const DEFAULT_MAX_GRASPS: usize = 10;
/// The most grasps a request may ask for.
pub const MAX_GRASPS_LIMIT: usize = 1000;

/// What a caller says about the grasps it wants (the fit's `options.grasps`,
/// `/v1/grasps`, `supertoroid grasps`).
#[derive(Clone, Debug, PartialEq, serde::Deserialize, serde::Serialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct GraspOptions {
    pub gripper: Gripper,
    /// friction coefficient at the contacts (default 0.5)
    pub friction: Option<f64>,
    /// how many grasps to answer, best first (default 10, at most 1000)
    pub max_grasps: Option<usize>,
    /// the table in the fit's frame; no part of the hand goes below it
    pub plane: Option<crate::model::Plane>,
    /// the camera's position in the fit's frame, [x, y, z]: no approach from behind the
    /// object (default: the viewpoint the fit used, where it had one)
    #[schema(value_type = Option<Vec<f64>>)]
    pub viewpoint: Option<[f64; 3]>,
    /// also answer each grasp as a GraspNet-1Billion row of 17 numbers
    pub graspnet: Option<bool>,
}

/// The grasps of one object as callers get them.
#[derive(Clone, Debug, PartialEq, serde::Serialize, utoipa::ToSchema)]
pub struct GraspsOut {
    #[serde(flatten)]
    pub plan: GraspPlan,
    /// the grasps as GraspNet rows (score, width, height, depth, rotation row-major,
    /// translation, object id), where asked for
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schema(value_type = Option<Vec<Vec<f64>>>)]
    pub graspnet: Option<Vec<[f64; 17]>>,
}

impl GraspOptions {
    /// The planner's request for an object, `viewpoint` standing in where none is given.
    pub fn request(
        &self,
        shape: Shape,
        pose: Pose,
        viewpoint: Option<DVec3>,
    ) -> Result<GraspRequest, String> {
        let max_grasps = self.max_grasps.unwrap_or(DEFAULT_MAX_GRASPS);
        if max_grasps > MAX_GRASPS_LIMIT {
            return Err(format!(
                "max_grasps must be at most {MAX_GRASPS_LIMIT}, got {max_grasps}"
            ));
        }
        let request = GraspRequest {
            shape,
            pose,
            gripper: self.gripper,
            friction: self.friction.unwrap_or(DEFAULT_FRICTION),
            plane: self.plane.map(|p| p.validated()).transpose()?,
            viewpoint: self.viewpoint.map(DVec3::from_array).or(viewpoint),
            max_grasps,
        };
        plan::validate(&request)?;
        Ok(request)
    }

    /// Plans and formats the grasps (object id 0 in GraspNet rows).
    pub fn plan(
        &self,
        shape: Shape,
        pose: Pose,
        viewpoint: Option<DVec3>,
    ) -> Result<GraspsOut, String> {
        let request = self.request(shape, pose, viewpoint)?;
        let plan = plan::plan(&request)?;
        let graspnet = self.graspnet.unwrap_or(false).then(|| {
            plan.grasps
                .iter()
                .map(|g| graspnet_row(g, &self.gripper, 0))
                .collect()
        });
        Ok(GraspsOut { plan, graspnet })
    }
}

//! A fitted object as callers hand it back: the `shape` and `pose` of a fit's JSON
//! (`supertoroid fit`, `/v1/fit`), every other field of that JSON ignored, so a fit's
//! answer can be posted as it is.

use super::{Pose, Shape};
use glam::{DQuat, DVec3};
use serde::{Deserialize, Serialize};

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct PoseIn {
    #[schema(value_type = Vec<f64>)]
    pub translation: [f64; 3],
    /// unit quaternion (normalised here), world = R·canonical + t
    #[schema(value_type = Vec<f64>)]
    pub quaternion_wxyz: [f64; 4],
}

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct FittedObject {
    pub shape: Shape,
    pub pose: PoseIn,
}

impl FittedObject {
    pub fn new(shape: Shape, pose: &Pose) -> Self {
        let q = pose.rotation;
        Self {
            shape,
            pose: PoseIn {
                translation: pose.translation.to_array(),
                quaternion_wxyz: [q.w, q.x, q.y, q.z],
            },
        }
    }

    /// The shape checked and the pose built, or what is wrong with them.
    pub fn validated(&self) -> Result<(Shape, Pose), String> {
        self.shape.validate()?;
        let t = DVec3::from_array(self.pose.translation);
        let [w, x, y, z] = self.pose.quaternion_wxyz;
        let q = DQuat::from_xyzw(x, y, z, w);
        if !t.is_finite() || !q.is_finite() || q.length() < 1e-9 {
            return Err(format!(
                "pose: translation and a non-zero quaternion_wxyz must be finite, got {:?} and {:?}",
                self.pose.translation, self.pose.quaternion_wxyz
            ));
        }
        Ok((self.shape, Pose::new(q, t)))
    }
}

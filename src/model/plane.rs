//! A plane, such as the table an object rests on: the points x with n·x + offset = 0,
//! n a unit normal pointing to the side the objects are on.

use glam::DVec3;
use serde::{Deserialize, Serialize};

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct Plane {
    /// unit normal, pointing away from the table towards the objects
    #[schema(value_type = Vec<f64>)]
    pub normal: [f64; 3],
    pub offset: f64,
}

impl Plane {
    /// The plane through `point` with the given normal (normalised here).
    pub fn through(point: DVec3, normal: DVec3) -> Self {
        let n = normal.normalize();
        Self {
            normal: n.to_array(),
            offset: -n.dot(point),
        }
    }

    pub fn normal(&self) -> DVec3 {
        DVec3::from_array(self.normal)
    }

    /// Signed distance, positive on the objects' side.
    pub fn signed_distance(&self, p: DVec3) -> f64 {
        self.normal().dot(p) + self.offset
    }

    /// Normalises the normal (and the offset with it); refuses a zero or non-finite one.
    pub fn validated(self) -> Result<Self, String> {
        let n = self.normal();
        let len = n.length();
        if !len.is_finite() || !self.offset.is_finite() || len < 1e-9 {
            return Err(format!(
                "plane: normal must be a non-zero finite vector and offset finite, got {:?}, {}",
                self.normal, self.offset
            ));
        }
        Ok(Self {
            normal: (n / len).to_array(),
            offset: self.offset / len,
        })
    }
}

//! A parallel-jaw gripper and the boxes its fingers and palm sweep.
//!
//! The grasp frame: `position` p midway between the two contacts, `approach` a (the
//! direction the hand moves in), `closing` b (from the first finger to the second),
//! `binormal` c = a × b. Each finger is a box `finger_thickness` along b, `finger_width`
//! along c, and `finger_depth` long along a, its tip reaching past the contacts by a
//! part of its depth (the grasp's posture, see [`POSTURES`]); behind the fingers sits the
//! palm, as wide as the open hand. The hand comes
//! in along a from outside the object, so a finger or the palm collides where any point
//! of the surface (or the support plane) lies in the volume they sweep on the way in
//! with the jaws open to the pre-grasp width.

use glam::DVec3;
use serde::{Deserialize, Serialize};

/// The postures tried for each grasp, in order, the first that is free kept: the part of
/// the finger's depth reaching past the contact line, and how much wider than the object
/// the jaws open before they close (each side gets half; at most the gripper's opening).
/// A deep grasp with room to spare first; a shallow one, or a narrow opening, where the
/// table or the hole leaves no room for it.
pub const POSTURES: [Posture; 4] = [
    Posture {
        tip: 0.2,
        clearance: 0.01,
    },
    Posture {
        tip: 0.2,
        clearance: 0.004,
    },
    Posture {
        tip: 0.05,
        clearance: 0.01,
    },
    Posture {
        tip: 0.05,
        clearance: 0.004,
    },
];

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Posture {
    /// fraction of the finger depth past the contacts
    pub tip: f64,
    /// pre-grasp opening less the object's width
    pub clearance: f64,
}
/// The least room on each side of the object as the open jaws come in.
pub const MIN_CLEARANCE: f64 = 0.001;

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct Gripper {
    /// the widest opening between the fingers' inner faces
    pub max_opening: f64,
    /// the narrowest it closes to (default 0)
    #[serde(default)]
    pub min_opening: f64,
    /// finger length from the palm to the tip, along the approach
    pub finger_depth: f64,
    /// finger size across the closing direction (along the binormal)
    pub finger_width: f64,
    /// finger size along the closing direction (default: a quarter of the depth)
    #[serde(default)]
    pub finger_thickness: Option<f64>,
}

impl Gripper {
    /// A Franka-Hand-like gripper in metres (8 cm opening, 4.5 cm fingers, 2 cm pads).
    pub const FRANKA_LIKE: Self = Self {
        max_opening: 0.08,
        min_opening: 0.0,
        finger_depth: 0.045,
        finger_width: 0.02,
        finger_thickness: None,
    };

    pub fn thickness(&self) -> f64 {
        self.finger_thickness.unwrap_or(self.finger_depth / 4.0)
    }

    pub fn validate(&self) -> Result<(), String> {
        let fields = [
            ("max_opening", self.max_opening),
            ("finger_depth", self.finger_depth),
            ("finger_width", self.finger_width),
            ("finger_thickness", self.thickness()),
        ];
        for (name, v) in fields {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!(
                    "gripper: {name} must be positive and finite, got {v}"
                ));
            }
        }
        if !(self.min_opening.is_finite()
            && self.min_opening >= 0.0
            && self.min_opening < self.max_opening)
        {
            return Err(format!(
                "gripper: min_opening must be in [0, max_opening), got {} (max_opening {})",
                self.min_opening, self.max_opening
            ));
        }
        Ok(())
    }

    /// Whether an object `width` across fits between the jaws.
    pub fn fits(&self, width: f64) -> bool {
        width >= self.min_opening && width + 2.0 * MIN_CLEARANCE <= self.max_opening
    }

    /// The pre-grasp opening for an object `width` across in a posture.
    pub fn pregrasp_opening(&self, width: f64, posture: &Posture) -> f64 {
        (width + posture.clearance).min(self.max_opening)
    }
}

/// An oriented box in the grasp frame: [lo, hi] along (a, b, c); the hand's boxes are
/// symmetric about c = 0.
#[derive(Clone, Copy, Debug)]
pub struct FrameBox {
    pub lo: DVec3,
    pub hi: DVec3,
}

/// The grasp frame's axes and origin.
#[derive(Clone, Copy, Debug)]
pub struct GraspFrame {
    pub position: DVec3,
    pub approach: DVec3,
    pub closing: DVec3,
    pub binormal: DVec3,
}

impl GraspFrame {
    pub fn local(&self, p: DVec3) -> DVec3 {
        let d = p - self.position;
        DVec3::new(
            d.dot(self.approach),
            d.dot(self.closing),
            d.dot(self.binormal),
        )
    }

    pub fn world(&self, local: DVec3) -> DVec3 {
        self.position + self.approach * local.x + self.closing * local.y + self.binormal * local.z
    }
}

impl FrameBox {
    pub fn contains(&self, local: DVec3) -> bool {
        local.cmpge(self.lo).all() && local.cmple(self.hi).all()
    }

    pub fn corners(&self) -> [DVec3; 8] {
        std::array::from_fn(|i| {
            DVec3::new(
                if i & 1 == 0 { self.lo.x } else { self.hi.x },
                if i & 2 == 0 { self.lo.y } else { self.hi.y },
                if i & 4 == 0 { self.lo.z } else { self.hi.z },
            )
        })
    }
}

/// The two fingers and the palm, open to `opening`, the tips `tip` past the contacts,
/// swept back by `sweep` along the approach (the way in from outside the object).
pub fn hand_boxes(gripper: &Gripper, opening: f64, tip: f64, sweep: f64) -> [FrameBox; 3] {
    let base = tip - gripper.finger_depth;
    let t = gripper.thickness();
    let half_w = gripper.finger_width / 2.0;
    let half_o = opening / 2.0;
    let finger = |side: f64| {
        let (y0, y1) = if side < 0.0 {
            (-half_o - t, -half_o)
        } else {
            (half_o, half_o + t)
        };
        FrameBox {
            lo: DVec3::new(base - sweep, y0, -half_w),
            hi: DVec3::new(tip, y1, half_w),
        }
    };
    let palm = FrameBox {
        lo: DVec3::new(base - t - sweep, -half_o - t, -half_w),
        hi: DVec3::new(base, half_o + t, half_w),
    };
    [finger(-1.0), finger(1.0), palm]
}

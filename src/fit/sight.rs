//! What a sensor saw: where it stood and, for a camera, the edges of its frame. The noise
//! model expects points on the surface the sensor sees ([`super::objective`]); a camera
//! sees nothing past its frame's edges (or the region of it the points were read from),
//! so surface out there is not expected to show points. Without the edges, an object the
//! frame cuts was fitted as if its hidden part had been looked at and found empty: the
//! fit stopped at the edge.

use glam::DVec3;

/// The edges of a camera's frame: four planes through its viewpoint, each given by its
/// normal pointing into the frame (the cloud's frame, so any translation and scaling of
/// the cloud leaves them as they are).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FieldOfView {
    pub inward: [DVec3; 4],
}

impl FieldOfView {
    /// The frame of a pinhole camera at the origin of its optical frame (x right, y down,
    /// z forward), over the pixel rectangle [x, y, width, height]: its outer edges lie
    /// half a pixel past the outer pixels' centres.
    pub fn of_pixels(fx: f64, fy: f64, cx: f64, cy: f64, [x, y, width, height]: [u32; 4]) -> Self {
        let left = (x as f64 - 0.5 - cx) / fx;
        let right = ((x + width) as f64 - 0.5 - cx) / fx;
        let top = (y as f64 - 0.5 - cy) / fy;
        let bottom = ((y + height) as f64 - 0.5 - cy) / fy;
        Self {
            inward: [
                DVec3::new(1.0, 0.0, -left),
                DVec3::new(-1.0, 0.0, right),
                DVec3::new(0.0, 1.0, -top),
                DVec3::new(0.0, -1.0, bottom),
            ],
        }
    }

    /// Whether `point` lies inside the frame of a sensor at `viewpoint`.
    pub fn holds(&self, viewpoint: DVec3, point: DVec3) -> bool {
        let q = point - viewpoint;
        self.inward.iter().all(|n| n.dot(q) >= 0.0)
    }

    pub fn is_finite(&self) -> bool {
        self.inward
            .iter()
            .all(|n| n.is_finite() && n.length_squared() > 0.0)
    }
}

/// Where a sensor stood, and the edges of its frame where they are known.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sight {
    pub viewpoint: DVec3,
    pub field: Option<FieldOfView>,
}

impl Sight {
    /// A sensor at `viewpoint` that saw all round it.
    pub fn at(viewpoint: DVec3) -> Self {
        Self {
            viewpoint,
            field: None,
        }
    }

    /// Whether the sensor's frame holds `point` (always, without known edges).
    pub fn frames(&self, point: DVec3) -> bool {
        self.field.is_none_or(|f| f.holds(self.viewpoint, point))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pixel_rectangle_frames_what_projects_into_it() {
        let (fx, fy, cx, cy) = (600.0, 600.0, 319.5, 239.5);
        let field = FieldOfView::of_pixels(fx, fy, cx, cy, [100, 50, 200, 100]);
        let project = |u: f64, v: f64| DVec3::new((u - cx) / fx * 0.7, (v - cy) / fy * 0.7, 0.7);
        for (u, v, inside) in [
            (100.0, 50.0, true),
            (299.0, 149.0, true),
            (200.0, 100.0, true),
            (99.0, 100.0, false),
            (300.0, 100.0, false),
            (200.0, 49.0, false),
            (200.0, 150.0, false),
        ] {
            assert_eq!(
                field.holds(DVec3::ZERO, project(u, v)),
                inside,
                "pixel ({u}, {v})"
            );
        }
        // behind the camera nothing is framed
        assert!(!field.holds(DVec3::ZERO, DVec3::new(0.0, 0.0, -1.0)));
    }
}

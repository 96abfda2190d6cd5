//! A pinhole camera that renders a single view of a supertoroid by ray casting: one ray
//! per pixel, the first surface crossing wins (a z-buffer by construction), so only the
//! points the camera really sees survive. It also yields the u16 depth image that a
//! RealSense-like sensor would send.

use super::SeededRng;
use crate::model::{Pose, Shape};
use glam::{DMat3, DQuat, DVec3};
use rand::Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Pinhole intrinsics in pixels (OpenCV convention: pixel (u, v) has its centre at
/// integer coordinates; optical frame x right, y down, z forward).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Intrinsics {
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    pub width: u32,
    pub height: u32,
}

impl Intrinsics {
    /// Intel RealSense D435-like 640x480 depth stream.
    pub const REALSENSE_640X480: Self = Self {
        fx: 615.0,
        fy: 615.0,
        cx: 319.5,
        cy: 239.5,
        width: 640,
        height: 480,
    };

    /// Ray direction (not unit) of pixel (u, v) in the optical frame, with z = 1.
    pub fn ray(&self, u: f64, v: f64) -> DVec3 {
        DVec3::new((u - self.cx) / self.fx, (v - self.cy) / self.fy, 1.0)
    }

    /// Back-projects pixel (u, v) at optical depth z (metres along the optical axis).
    pub fn back_project(&self, u: f64, v: f64, z: f64) -> DVec3 {
        self.ray(u, v) * z
    }

    pub fn validate(&self) -> Result<(), String> {
        let ok = [self.fx, self.fy, self.cx, self.cy]
            .iter()
            .all(|x| x.is_finite())
            && self.fx > 0.0
            && self.fy > 0.0
            && self.width > 0
            && self.height > 0;
        if ok {
            Ok(())
        } else {
            Err(format!(
                "invalid intrinsics {self:?}: fx, fy must be > 0 and finite, width and height > 0"
            ))
        }
    }
}

/// A camera: intrinsics plus its pose (world_from_camera: optical-frame point c maps to
/// the world as R·c + t).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub intrinsics: Intrinsics,
    pub pose: Pose,
}

impl Camera {
    /// A camera at `eye` looking at `target`, image "up" towards `up`.
    pub fn look_at(intrinsics: Intrinsics, eye: DVec3, target: DVec3, up: DVec3) -> Self {
        let z = (target - eye).normalize();
        let up = if z.cross(up).length() < 1e-6 {
            DVec3::Y
        } else {
            up
        };
        let x = z.cross(up).normalize();
        let y = z.cross(x);
        let rotation = DQuat::from_mat3(&DMat3::from_cols(x, y, z));
        Self {
            intrinsics,
            pose: Pose::new(rotation, eye),
        }
    }

    /// A seeded random viewpoint looking at the object's centre from a random direction,
    /// at the distance where the object spans about 60% of the image height.
    pub fn random_view(
        shape: &Shape,
        object: &Pose,
        intrinsics: Intrinsics,
        rng: &mut SeededRng,
    ) -> Self {
        let dir = loop {
            let v = DVec3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            );
            let n = v.length();
            if n > 0.1 && n <= 1.0 {
                break v / n;
            }
        };
        let distance = intrinsics.fy * 2.0 * shape.size() / (0.6 * intrinsics.height as f64);
        Self::look_at(
            intrinsics,
            object.translation + dir * distance,
            object.translation,
            DVec3::Z,
        )
    }
}

/// A 16-bit depth image: depth in metres = value · scale; 0 means no return.
#[derive(Clone, Debug, PartialEq)]
pub struct DepthImage {
    pub width: u32,
    pub height: u32,
    /// metres per unit (0.001 for RealSense D400)
    pub scale: f64,
    /// row-major, `width * height` values
    pub data: Vec<u16>,
}

impl DepthImage {
    /// Back-projects every valid pixel to the camera's optical frame.
    pub fn back_project(&self, intrinsics: &Intrinsics) -> Vec<DVec3> {
        let mut out = Vec::new();
        for v in 0..self.height {
            for u in 0..self.width {
                let raw = self.data[(v * self.width + u) as usize];
                if raw != 0 {
                    out.push(intrinsics.back_project(u as f64, v as f64, raw as f64 * self.scale));
                }
            }
        }
        out
    }
}

/// What one view sees.
#[derive(Clone, Debug)]
pub struct RenderedView {
    /// visible surface points in world coordinates, in pixel (row-major) order
    pub points: Vec<DVec3>,
    /// the pixel (u, v) of each point
    pub pixels: Vec<[u32; 2]>,
    pub depth: DepthImage,
}

/// Renders the visible part of the surface by sphere tracing each pixel's ray.
///
/// In the canonical frame the section norm N = F_t^(eps1/2) (see `Shape::section_norm`)
/// changes by at most `lipschitz` per unit length for eps1, eps2 <= 2, so stepping by
/// (N - 1)/lipschitz from outside never jumps over the surface: the first crossing found
/// is the nearest one, and nothing behind it is kept.
pub fn render_view(
    shape: &Shape,
    object: &Pose,
    camera: &Camera,
    depth_scale: f64,
) -> Result<RenderedView, String> {
    shape.validate()?;
    camera.intrinsics.validate()?;
    if shape.eps1 > 2.0 || shape.eps2 > 2.0 {
        return Err("the renderer needs eps1, eps2 <= 2".into());
    }
    if !(depth_scale > 0.0 && depth_scale.is_finite()) {
        return Err(format!("depth scale must be > 0, got {depth_scale}"));
    }
    let k = camera.intrinsics;
    let min_a = shape.a1.min(shape.a2);
    let lipschitz = 2.0f64.sqrt() * (2.0 / (min_a * min_a) + 1.0 / (shape.a3 * shape.a3)).sqrt();
    let tolerance = 1e-9 * shape.size();
    let half = shape.half_extents() * 1.001;
    let origin = object.to_canonical(camera.pose.translation);
    let to_canonical = object.rotation.inverse() * camera.pose.rotation;

    // one pixel's ray: its optical depth and surface point (world frame), or None
    let trace = |u: u32, v: u32| -> Option<(u16, DVec3)> {
        let ray_cam = k.ray(u as f64, v as f64);
        let dir = (to_canonical * ray_cam).normalize();
        let (t_in, t_out) = ray_box(origin, dir, half)?;
        let mut t = t_in.max(0.0);
        let mut hit = None;
        for _ in 0..20_000 {
            if t > t_out {
                break;
            }
            let gap = (shape.section_norm(origin + dir * t) - 1.0) / lipschitz;
            if gap <= tolerance {
                hit = Some(t);
                break;
            }
            t += gap;
        }
        let t = hit?;
        // optical depth: distance along the ray times the ray's z component per unit length
        let z_cam = t / ray_cam.length();
        let raw = (z_cam / depth_scale).round();
        // like a real sensor: beyond the u16 range there is no return
        (1.0..=u16::MAX as f64)
            .contains(&raw)
            .then(|| (raw as u16, object.to_world(origin + dir * t)))
    };
    // rows traced in parallel; `collect` keeps row-major order, so the view is the same
    // whatever the threads
    let hits: Vec<([u32; 2], u16, DVec3)> = (0..k.height)
        .into_par_iter()
        .flat_map_iter(|v| {
            (0..k.width).filter_map(move |u| trace(u, v).map(|(raw, p)| ([u, v], raw, p)))
        })
        .collect();
    let mut depth = vec![0u16; (k.width * k.height) as usize];
    let mut points = Vec::with_capacity(hits.len());
    let mut pixels = Vec::with_capacity(hits.len());
    for ([u, v], raw, p) in hits {
        depth[(v * k.width + u) as usize] = raw;
        points.push(p);
        pixels.push([u, v]);
    }
    Ok(RenderedView {
        points,
        pixels,
        depth: DepthImage {
            width: k.width,
            height: k.height,
            scale: depth_scale,
            data: depth,
        },
    })
}

/// Slab test: the parameter interval where the ray is inside the box |p_i| <= half_i.
fn ray_box(origin: DVec3, dir: DVec3, half: DVec3) -> Option<(f64, f64)> {
    let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
    for i in 0..3 {
        let (o, d, h) = (origin[i], dir[i], half[i]);
        if d.abs() < 1e-300 {
            if o.abs() > h {
                return None;
            }
            continue;
        }
        let (a, b) = ((-h - o) / d, (h - o) / d);
        t0 = t0.max(a.min(b));
        t1 = t1.min(a.max(b));
    }
    (t1 >= t0.max(0.0)).then_some((t0, t1))
}

/// A rendered depth image with a table put under it: every pixel whose ray meets the
/// plane in front of the camera, nearer than what the image holds there (or where it
/// holds nothing), takes the table's depth. The plane is in world coordinates.
pub fn with_table(depth: &DepthImage, camera: &Camera, table: &crate::model::Plane) -> DepthImage {
    let k = camera.intrinsics;
    let mut out = depth.clone();
    let eye = camera.pose.translation;
    for v in 0..k.height {
        for u in 0..k.width {
            let ray = k.ray(u as f64, v as f64);
            let dir = camera.pose.rotation * ray;
            let along = table.normal().dot(dir);
            if along.abs() < 1e-12 {
                continue;
            }
            // the ray's parameter t at the plane: optical depth t (the ray has z = 1)
            let t = -table.signed_distance(eye) / along;
            if t <= 0.0 {
                continue;
            }
            let value = (t / depth.scale).round();
            if !(1.0..65535.0).contains(&value) {
                continue;
            }
            let i = (v * k.width + u) as usize;
            if out.data[i] == 0 || (value as u16) < out.data[i] {
                out.data[i] = value as u16;
            }
        }
    }
    out
}

//! A triangle mesh of a supertoroid's surface, for viewers and grasp planners.
//!
//! The surface is the parametric r_t(eta, omega) of paper eq. (2) on a regular grid:
//! omega wraps around the hole axis; eta wraps too when a4 >= 1 (a torus), and runs
//! between the two points on the axis otherwise ([`Shape::eta_range`]). Vertex normals
//! are area-weighted face normals, which stay finite at the parameter seams where the
//! analytic normal of eq. (18) does not for eps != 1.

use crate::model::{Pose, Shape};
use glam::DVec3;

#[derive(Clone, Debug, Default)]
pub struct Mesh {
    pub vertices: Vec<DVec3>,
    pub normals: Vec<DVec3>,
    /// counter-clockwise seen from outside
    pub triangles: Vec<[u32; 3]>,
}

/// Tessellates the surface in world coordinates with `rings` steps in eta and
/// `segments` steps in omega (each at least 3).
pub fn tessellate(shape: &Shape, pose: &Pose, rings: usize, segments: usize) -> Mesh {
    let rings = rings.max(3);
    let segments = segments.max(3);
    let eta_max = shape.eta_range();
    let closed_eta = shape.a4 >= 1.0;
    // rows of vertices in eta: a closed torus has `rings` distinct rows, an open
    // surface `rings + 1` rows from -eta_max to +eta_max (its ends on the axis)
    let rows = if closed_eta { rings } else { rings + 1 };
    let mut vertices = Vec::with_capacity(rows * segments);
    for i in 0..rows {
        let eta = -eta_max + 2.0 * eta_max * i as f64 / rings as f64;
        for j in 0..segments {
            let omega = -std::f64::consts::PI + std::f64::consts::TAU * j as f64 / segments as f64;
            vertices.push(pose.to_world(shape.surface_point(eta, omega)));
        }
    }
    let index = |i: usize, j: usize| ((i % rows) * segments + j % segments) as u32;
    let mut triangles = Vec::with_capacity(2 * rings * segments);
    for i in 0..rings {
        for j in 0..segments {
            let (a, b, c, d) = (
                index(i, j),
                index(i, j + 1),
                index(i + 1, j + 1),
                index(i + 1, j),
            );
            triangles.push([a, b, c]);
            triangles.push([a, c, d]);
        }
    }
    // drop triangles collapsed at the axis ends
    triangles.retain(|t| t[0] != t[1] && t[1] != t[2] && t[0] != t[2]);
    let mut mesh = Mesh {
        vertices,
        normals: Vec::new(),
        triangles,
    };
    orient_outward(&mut mesh, shape, pose);
    mesh.normals = vertex_normals(&mesh);
    mesh
}

/// Flips every triangle whose normal points into the solid (F_t decreasing along it), so
/// that the winding is outward whatever the parameterisation's handedness.
fn orient_outward(mesh: &mut Mesh, shape: &Shape, pose: &Pose) {
    let step = 1e-4 * shape.size();
    for t in &mut mesh.triangles {
        let [a, b, c] = t.map(|i| mesh.vertices[i as usize]);
        let n = (b - a).cross(c - a);
        if n.length_squared() == 0.0 {
            continue;
        }
        let centre = (a + b + c) / 3.0;
        let n = n.normalize() * step;
        let ahead = shape.inside_outside(pose.to_canonical(centre + n));
        let behind = shape.inside_outside(pose.to_canonical(centre - n));
        if ahead < behind {
            t.swap(1, 2);
        }
    }
}

fn vertex_normals(mesh: &Mesh) -> Vec<DVec3> {
    let mut normals = vec![DVec3::ZERO; mesh.vertices.len()];
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|i| mesh.vertices[i as usize]);
        let n = (b - a).cross(c - a); // length = twice the area: area weighting
        for &i in t {
            normals[i as usize] += n;
        }
    }
    normals
        .into_iter()
        .map(|n| n.try_normalize().unwrap_or(DVec3::Z))
        .collect()
}

//! The meshes of an exported object, in its canonical frame: the visual surface, the
//! convex pieces simulators collide with, and the mass properties of the solid.

use crate::io::mesh::{Mesh, tessellate};
use crate::model::{Pose, Shape};
use glam::{DMat3, DVec3};
use std::f64::consts::{PI, TAU};
use std::io::Write;

/// Grid of the visual mesh (eta x omega).
pub const VISUAL_GRID: (usize, usize) = (32, 64);
/// Pieces a ring is cut into around its axis for collisions. Simulators (MuJoCo,
/// Bullet) collide meshes by their convex hulls, and a ring's hull fills its hole; the
/// hull of one sixteenth of a ring is within 2% of its section's size of the piece.
pub const RING_PIECES: usize = 16;
/// Grid of each collision piece (eta x omega across the piece).
pub const PIECE_GRID: (usize, usize) = (16, 4);

pub fn visual(shape: &Shape) -> Mesh {
    tessellate(shape, &Pose::IDENTITY, VISUAL_GRID.0, VISUAL_GRID.1)
}

/// A ring's collision pieces: point sets of [`RING_PIECES`] arcs whose convex hulls
/// together cover the solid without filling its hole.
pub fn ring_pieces(shape: &Shape) -> Vec<Vec<DVec3>> {
    let (n_eta, n_omega) = PIECE_GRID;
    (0..RING_PIECES)
        .map(|k| {
            let start = -PI + TAU * k as f64 / RING_PIECES as f64;
            let mut points = Vec::with_capacity(n_eta * (n_omega + 1));
            for j in 0..=n_omega {
                let omega = start + TAU / RING_PIECES as f64 * j as f64 / n_omega as f64;
                for i in 0..n_eta {
                    let eta = -PI + TAU * i as f64 / n_eta as f64;
                    points.push(crate::grasp::surface::surface_point(shape, eta, omega));
                }
            }
            points
        })
        .collect()
}

/// Volume, centre of mass and the inertia tensor about it per unit density of a closed
/// outward mesh, by signed tetrahedra from the origin.
pub fn mass_properties(mesh: &Mesh) -> (f64, DVec3, DMat3) {
    let mut volume = 0.0;
    let mut first = DVec3::ZERO;
    let mut second = DMat3::ZERO;
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|i| mesh.vertices[i as usize]);
        let det = a.dot(b.cross(c));
        volume += det / 6.0;
        first += det / 24.0 * (a + b + c);
        // ∫ x xᵀ over the tetrahedron (0, a, b, c)
        let s = a + b + c;
        let outer = |u: DVec3| DMat3::from_cols(u * u.x, u * u.y, u * u.z);
        second += (outer(a) + outer(b) + outer(c) + outer(s)) * (det / 120.0);
    }
    let com = first / volume;
    let covariance = second - DMat3::from_cols(com * com.x, com * com.y, com * com.z) * volume;
    let trace = covariance.x_axis.x + covariance.y_axis.y + covariance.z_axis.z;
    let inertia = DMat3::from_diagonal(DVec3::splat(trace)) - covariance;
    (volume, com, inertia)
}

pub fn write_obj(out: &mut impl Write, mesh: &Mesh) -> std::io::Result<()> {
    writeln!(out, "# supertoroid surface")?;
    for v in &mesh.vertices {
        writeln!(out, "v {:.9} {:.9} {:.9}", v.x, v.y, v.z)?;
    }
    for n in &mesh.normals {
        writeln!(out, "vn {:.6} {:.6} {:.6}", n.x, n.y, n.z)?;
    }
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|i| i + 1);
        writeln!(out, "f {a}//{a} {b}//{b} {c}//{c}")?;
    }
    Ok(())
}

/// Binary STL of a collision piece: triangle strips over its grid, `rows` points per
/// column (simulators collide with the hull of the vertices, so the strips need not close).
pub fn write_stl_points(
    out: &mut impl Write,
    points: &[DVec3],
    rows: usize,
) -> std::io::Result<()> {
    let columns = points.len() / rows;
    let mut triangles = Vec::new();
    for j in 0..columns.saturating_sub(1) {
        for i in 0..rows {
            let at = |jj: usize, ii: usize| points[jj * rows + ii % rows];
            triangles.push([at(j, i), at(j + 1, i), at(j + 1, i + 1)]);
            triangles.push([at(j, i), at(j + 1, i + 1), at(j, i + 1)]);
        }
    }
    write_stl(out, &triangles)
}

pub fn write_stl(out: &mut impl Write, triangles: &[[DVec3; 3]]) -> std::io::Result<()> {
    let mut header = [0u8; 80];
    header[..20].copy_from_slice(b"supertoroid piece   ");
    out.write_all(&header)?;
    out.write_all(&(triangles.len() as u32).to_le_bytes())?;
    for [a, b, c] in triangles {
        let n = (*b - *a).cross(*c - *a).normalize_or_zero();
        for v in [n, *a, *b, *c] {
            for x in [v.x, v.y, v.z] {
                out.write_all(&(x as f32).to_le_bytes())?;
            }
        }
        out.write_all(&[0, 0])?;
    }
    Ok(())
}

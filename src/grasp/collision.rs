//! Does the hand meet the surface? The surface is a grid of nodes uniform in polar
//! angle (spread evenly over flat faces and corners alike, where a grid uniform in eq.
//! (2)'s parameters crowds into the corners of small-eps shapes), about
//! [`NODE_SPACING`] of the finger apart, each node with the radius that holds its
//! adjacent cells. A node inside a box is a collision; a node whose sphere only reaches
//! into one is decided on its cells' finer grids ([`FINE`] x [`FINE`] cells each, built
//! once per object when first needed and shared by every candidate): a fine node whose
//! own sphere reaches in is a collision. Conservative by at most a fine cell, tight near
//! the hand, cheap away from it.

use super::gripper::{FrameBox, GraspFrame, Gripper};
use crate::model::{Pose, Shape, signed_pow};
use glam::DVec3;
use std::f64::consts::{PI, TAU};

/// Node spacing as a fraction of the finger's thinner side (the grid between 16 x 32
/// and 64 x 128 nodes).
pub const NODE_SPACING: f64 = 0.5;
/// Each cell's fine grid is this many cells a side.
pub const FINE: usize = 8;
/// Spheres are this much larger than half their cell's longest diagonal, for the surface
/// bulging between the corners.
const BULGE: f64 = 1.25;

/// The parameter of eq. (2) whose point lies at polar angle `phi` of a superellipse of
/// exponent `eps` (tan^eps(t) = tan(phi)).
pub fn polar_to_parameter(phi: f64, eps: f64) -> f64 {
    let (s, c) = phi.sin_cos();
    signed_pow(s, 1.0 / eps).atan2(signed_pow(c, 1.0 / eps))
}

/// A cell's fine grid: (FINE + 1)² nodes and the radius that holds each fine cell.
struct FineGrid {
    nodes: Vec<DVec3>,
    radius: f64,
}

pub struct SurfaceCells {
    shape: Shape,
    pose: Pose,
    /// row-major nodes (rows round the section, columns round the axis)
    nodes: Vec<DVec3>,
    radii: Vec<f64>,
    /// polar angles of the rows and columns (one more than there are cells each way)
    row_angles: Vec<f64>,
    column_angles: Vec<f64>,
    /// whether the rows wrap (a torus) or end on the axis
    closed: bool,
    /// per cell (row-major), built when first needed
    fine: Vec<std::sync::OnceLock<FineGrid>>,
    /// per cell (row-major): a sphere around it, tested before its fine grid
    cell_spheres: Vec<(DVec3, f64)>,
    /// the signed powers of each cell row's and column's fine angles (eq. 2 separates)
    fine_rows: Vec<Vec<(f64, f64)>>,
    fine_columns: Vec<Vec<(f64, f64)>>,
    /// blocks of nearby nodes with spheres holding them and their radii: the hand's
    /// boxes are tested against these first
    blocks: Vec<Block>,
}

/// Nodes of a [`BLOCK`] x [`BLOCK`] patch of the grid and a sphere around them.
struct Block {
    nodes: Vec<usize>,
    centre: DVec3,
    radius: f64,
}

/// Side of a block, in nodes.
const BLOCK: usize = 8;

impl SurfaceCells {
    pub fn new(shape: &Shape, pose: &Pose, gripper: &Gripper) -> Self {
        let finger = gripper.finger_width.min(gripper.thickness());
        let spacing = NODE_SPACING * finger;
        let around = TAU * shape.a1.max(shape.a2) * (1.0 + shape.a4);
        let section = TAU * shape.a1.max(shape.a2).max(shape.a3);
        let count =
            |length: f64, lo: usize, hi: usize| ((length / spacing).ceil() as usize).clamp(lo, hi);
        let (n_eta, n_omega) = (count(section, 16, 64), count(around, 32, 128));
        let closed = shape.a4 >= 1.0;
        let phi_max = if closed {
            PI
        } else {
            // polar angle of the axis end: tan(phi) = tan^eps1(eta_max)
            let e = shape.eta_range();
            signed_pow(e.sin(), shape.eps1).atan2(signed_pow(e.cos(), shape.eps1))
        };
        let row_angles: Vec<f64> = (0..=n_eta)
            .map(|i| -phi_max + 2.0 * phi_max * i as f64 / n_eta as f64)
            .collect();
        let column_angles: Vec<f64> = (0..=n_omega)
            .map(|j| -PI + TAU * j as f64 / n_omega as f64)
            .collect();
        let rows = if closed { n_eta } else { n_eta + 1 };
        let nodes = grid_nodes(shape, pose, &row_angles[..rows], &column_angles[..n_omega]);
        let mut cells = Self {
            shape: *shape,
            pose: *pose,
            radii: vec![0.0; nodes.len()],
            nodes,
            row_angles: row_angles.clone(),
            column_angles: column_angles.clone(),
            closed,
            fine: (0..n_eta * n_omega)
                .map(|_| std::sync::OnceLock::new())
                .collect(),
            cell_spheres: Vec::with_capacity(n_eta * n_omega),
            fine_rows: fine_powers(&row_angles, shape.eps1),
            fine_columns: fine_powers(&column_angles, shape.eps2),
            blocks: Vec::new(),
        };
        for i in 0..n_eta {
            for j in 0..n_omega {
                let corners = cells.cell_nodes(i, j);
                let [a, b, c, d] = corners.map(|k| cells.nodes[k]);
                let half_diagonal = BULGE * a.distance(c).max(b.distance(d)) / 2.0;
                for k in corners {
                    cells.radii[k] = cells.radii[k].max(half_diagonal);
                }
                let centre = (a + b + c + d) / 4.0;
                let reach = [a, b, c, d]
                    .map(|p| p.distance(centre))
                    .into_iter()
                    .fold(0.0, f64::max);
                cells.cell_spheres.push((centre, BULGE * reach));
            }
        }
        for bi in (0..rows).step_by(BLOCK) {
            for bj in (0..n_omega).step_by(BLOCK) {
                let nodes: Vec<usize> = (bi..(bi + BLOCK).min(rows))
                    .flat_map(|i| (bj..(bj + BLOCK).min(n_omega)).map(move |j| i * n_omega + j))
                    .collect();
                let centre =
                    nodes.iter().map(|&k| cells.nodes[k]).sum::<DVec3>() / nodes.len() as f64;
                let radius = nodes
                    .iter()
                    .map(|&k| cells.nodes[k].distance(centre) + cells.radii[k])
                    .fold(0.0, f64::max);
                cells.blocks.push(Block {
                    nodes,
                    centre,
                    radius,
                });
            }
        }
        cells
    }

    fn columns(&self) -> usize {
        self.column_angles.len() - 1
    }

    fn row_count(&self) -> usize {
        self.nodes.len() / self.columns()
    }

    /// The node indices of cell (i, j), counter-clockwise.
    fn cell_nodes(&self, i: usize, j: usize) -> [usize; 4] {
        let (rows, cols) = (self.row_count(), self.columns());
        let k = |i: usize, j: usize| (i % rows) * cols + j % cols;
        [k(i, j), k(i, j + 1), k(i + 1, j + 1), k(i + 1, j)]
    }

    /// Whether any part of the surface lies in one of the boxes (grasp-frame boxes,
    /// symmetric about the binormal's zero like the hand's).
    pub fn meets(&self, boxes: &[FrameBox], frame: &GraspFrame) -> bool {
        let half_slab = boxes.iter().map(|b| b.hi.z).fold(0.0, f64::max);
        let mut borderline = Vec::new();
        let near = self.blocks.iter().filter(|b| {
            let local = frame.local(b.centre);
            boxes.iter().any(|x| sphere_meets_box(local, b.radius, x))
        });
        for k in near.flat_map(|b| b.nodes.iter().copied()) {
            let (p, r) = (self.nodes[k], self.radii[k]);
            let d = p - frame.position;
            // every box spans the same binormal slab: test that first
            let z = d.dot(frame.binormal);
            if z.abs() > half_slab + r {
                continue;
            }
            let local = DVec3::new(d.dot(frame.approach), d.dot(frame.closing), z);
            if boxes.iter().any(|b| b.contains(local)) {
                return true;
            }
            if boxes.iter().any(|b| sphere_meets_box(local, r, b)) {
                borderline.push(k);
            }
        }
        // the cells around borderline nodes, decided on their fine grids
        let cols = self.columns();
        let cell_rows = self.row_angles.len() - 1;
        // neighbouring borderline nodes share cells: each cell once
        let mut done = vec![false; self.fine.len()];
        for k in borderline {
            let (i, j) = (k / cols, k % cols);
            let below = if self.closed {
                Some((i + cell_rows - 1) % cell_rows)
            } else {
                i.checked_sub(1)
            };
            let above = (i < cell_rows).then_some(i);
            for ci in [below, above].into_iter().flatten() {
                for cj in [(j + cols - 1) % cols, j] {
                    if std::mem::replace(&mut done[ci * cols + cj], true) {
                        continue;
                    }
                    let (centre, reach) = self.cell_spheres[ci * cols + cj];
                    let local = frame.local(centre);
                    if !boxes.iter().any(|b| sphere_meets_box(local, reach, b)) {
                        continue;
                    }
                    let fine = self.fine_grid(ci, cj);
                    let hit = fine.nodes.iter().any(|&p| {
                        let local = frame.local(p);
                        boxes
                            .iter()
                            .any(|b| sphere_meets_box(local, fine.radius, b))
                    });
                    if hit {
                        return true;
                    }
                }
            }
        }
        false
    }

    fn fine_grid(&self, ci: usize, cj: usize) -> &FineGrid {
        self.fine[ci * self.columns() + cj].get_or_init(|| {
            let nodes = nodes_from_powers(
                &self.shape,
                &self.pose,
                &self.fine_rows[ci],
                &self.fine_columns[cj],
            );
            let n = FINE + 1;
            let mut diagonal: f64 = 0.0;
            for i in 0..FINE {
                for j in 0..FINE {
                    let at = |i: usize, j: usize| nodes[i * n + j];
                    diagonal = diagonal
                        .max(at(i, j).distance(at(i + 1, j + 1)))
                        .max(at(i + 1, j).distance(at(i, j + 1)));
                }
            }
            FineGrid {
                nodes,
                radius: BULGE * diagonal / 2.0,
            }
        })
    }

    /// How far the surface reaches back from the contact line (towards the palm) within
    /// the jaws' opening and the fingers' width, to the nodes' spacing.
    pub fn reach_behind(&self, frame: &GraspFrame, opening: f64, finger_width: f64) -> f64 {
        let mut depth: f64 = 0.0;
        for &p in &self.nodes {
            let local = frame.local(p);
            if local.y.abs() <= opening / 2.0 && local.z.abs() <= finger_width / 2.0 {
                depth = depth.max(-local.x);
            }
        }
        depth
    }
}

/// cos^eps and sin^eps (signed) of the parameter at polar angle `phi`.
fn powers(phi: f64, eps: f64) -> (f64, f64) {
    let (s, c) = polar_to_parameter(phi, eps).sin_cos();
    let snap = |v: f64| if v.abs() < 1e-14 { 0.0 } else { v };
    (signed_pow(snap(c), eps), signed_pow(snap(s), eps))
}

/// For each interval between consecutive angles, the powers at its FINE + 1 fine angles.
fn fine_powers(angles: &[f64], eps: f64) -> Vec<Vec<(f64, f64)>> {
    angles
        .windows(2)
        .map(|w| {
            (0..=FINE)
                .map(|t| powers(w[0] + (w[1] - w[0]) * t as f64 / FINE as f64, eps))
                .collect()
        })
        .collect()
}

/// The surface's nodes at the given polar angles, row-major.
fn grid_nodes(shape: &Shape, pose: &Pose, rows: &[f64], columns: &[f64]) -> Vec<DVec3> {
    let rows: Vec<(f64, f64)> = rows.iter().map(|&p| powers(p, shape.eps1)).collect();
    let columns: Vec<(f64, f64)> = columns.iter().map(|&p| powers(p, shape.eps2)).collect();
    nodes_from_powers(shape, pose, &rows, &columns)
}

/// Eq. (2) from each row's (cos^eps1, sin^eps1) and each column's (cos^eps2, sin^eps2).
fn nodes_from_powers(
    shape: &Shape,
    pose: &Pose,
    rows: &[(f64, f64)],
    columns: &[(f64, f64)],
) -> Vec<DVec3> {
    let mut nodes = Vec::with_capacity(rows.len() * columns.len());
    for &(c_eta, s_eta) in rows {
        let radius = shape.a4 + c_eta;
        for &(c_om, s_om) in columns {
            nodes.push(pose.to_world(DVec3::new(
                shape.a1 * radius * c_om,
                shape.a2 * radius * s_om,
                shape.a3 * s_eta,
            )));
        }
    }
    nodes
}

fn sphere_meets_box(centre: DVec3, radius: f64, b: &FrameBox) -> bool {
    let outside = (b.lo - centre).max(DVec3::ZERO) + (centre - b.hi).max(DVec3::ZERO);
    outside.length_squared() <= radius * radius
}

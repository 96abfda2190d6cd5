//! The normaliser A of the likelihood: the surface's area, or seen from a sensor the
//! integral over the surface it sees of its density of points, cos(incidence) / range²
//! (relative to a reference range). A is a sum over a coarse grid of the surface (its
//! integrand is smooth; the cells are `likelihood::Curves::cells`), its derivatives in
//! closed form through each grid corner's (an open section's a4 and eps1, which move its
//! ends, by differences of the grid made again), the visibility (a z-buffer of the
//! grid's mesh, `likelihood::visibility`) found where the caller asks and otherwise held:
//! a refinement holds it through each line search, so the function it minimises does not
//! jump where a cell's visibility flips. The per-point sums look the visibility up in the
//! same grid, so the density they integrate is the one A normalises.

use super::tables::section_range;
use crate::fit::likelihood::{
    Cells, Curves, d_log_view_weight, d_log_view_weight_pose, visibility::View,
};
use crate::fit::sight::Sight;
use crate::model::Shape;
use glam::{DQuat, DVec3};
use rayon::prelude::*;
use std::f64::consts::TAU;

/// The normaliser's grids, rings along the section by sectors about the axis: the one a
/// refinement differentiates, and the coarser one that ranks candidates.
pub const FINE: (usize, usize) = (48, 96);
pub const COARSE: (usize, usize) = (24, 48);

/// A and d ln A / d(shape, translation, turn), and which cells the sensor sees.
pub struct Normaliser {
    pub area: f64,
    pub d_log_area: [f64; 12],
    /// per cell (ring-major), with a sensor: seen by it
    pub visible: Option<Vec<bool>>,
    /// the section's polar range the rings divide
    pub range: (f64, f64),
    pub grid: (usize, usize),
}

impl Normaliser {
    /// Whether the sensor sees the cell (true without a sensor).
    pub fn sees(&self, ring: usize, sector: usize) -> bool {
        self.visible
            .as_ref()
            .is_none_or(|v| v[ring * self.grid.1 + sector])
    }

    /// The ring holding section angle `phi`.
    pub fn ring_of(&self, phi: f64) -> usize {
        let (lo, hi) = self.range;
        let rings = self.grid.0 as isize;
        (((phi - lo) / (hi - lo) * rings as f64).floor() as isize).clamp(0, rings - 1) as usize
    }

    /// The sector holding sweep angle `psi` (in [0, 2 pi)).
    pub fn sector_of(&self, psi: f64) -> usize {
        ((psi / TAU * self.grid.1 as f64).floor() as usize).min(self.grid.1 - 1)
    }
}

/// The normaliser at a shape and pose on a `grid`, seen from `sensor` (viewpoint,
/// reference squared range) if any; derivatives with `with_gradient`.
pub fn normaliser(
    shape: &Shape,
    rotation: DQuat,
    translation: DVec3,
    sensor: Option<(Sight, f64)>,
    grid: (usize, usize),
    held: Option<&[bool]>,
    with_gradient: bool,
) -> Normaliser {
    let (lo, hi, closed) = section_range(shape);
    let curves = Curves::new(&shape.to_array(), (lo, hi), grid.0, grid.1);
    let cells = curves.cells(&shape.to_array());
    let world_cells: Vec<DVec3> = cells
        .centres
        .iter()
        .map(|c| rotation * *c + translation)
        .collect();
    let world_normals: Vec<DVec3> = cells.normals.iter().map(|n| rotation * *n).collect();
    let visible = sensor.map(|(sight, _)| match held {
        Some(held) if held.len() == cells.areas.len() => held.to_vec(),
        _ => View::unoccluded(&world_cells, &cells.areas, &world_normals, grid, sight),
    });
    // each cell's weight: its area, or seen by the sensor its density of points,
    // cos(incidence) / range² relative to the reference (zero where it does not see)
    let weight = |j: usize, area: f64, cell: DVec3, normal: DVec3| -> f64 {
        let Some((Sight { viewpoint, .. }, reference)) = sensor else {
            return area;
        };
        if !visible.as_ref().is_some_and(|v| v[j]) {
            return 0.0;
        }
        let q = cell - viewpoint;
        let range2 = q.length_squared();
        let cos = (-normal.dot(q)).max(0.0) / range2.sqrt();
        area * cos * reference / range2
    };
    let weights: Vec<f64> = (0..cells.areas.len())
        .map(|j| weight(j, cells.areas[j], world_cells[j], world_normals[j]))
        .collect();
    let area = weights.iter().sum::<f64>().max(1e-300);
    let mut d_log_area = [0.0; 12];
    if with_gradient {
        let world = World {
            rotation,
            translation,
            cells: &world_cells,
            normals: &world_normals,
        };
        d_log_area = log_area_derivatives(shape, &curves, &cells, &world, sensor, &weights, area);
        // an open section's ends move with a4 and eps1: those two by differences of the
        // grid made again
        for k in if closed { 3..3 } else { 3..5 } {
            let mut moved = shape.to_array();
            let step = 1e-6 * moved[k].abs().max(1e-2);
            moved[k] += step;
            let (lo, hi, _) = section_range(&Shape::from_array(moved));
            let cells = Curves::new(&moved, (lo, hi), grid.0, grid.1).cells(&moved);
            let moved_area: f64 = (0..cells.areas.len())
                .map(|j| {
                    let normal = rotation * cells.normals[j];
                    weight(
                        j,
                        cells.areas[j],
                        rotation * cells.centres[j] + translation,
                        normal,
                    )
                })
                .sum();
            d_log_area[k] = (moved_area / area - 1.0) / step;
        }
    }
    Normaliser {
        area,
        d_log_area,
        visible,
        range: (lo, hi),
        grid,
    }
}

/// The grid's cells in the world: the pose and each cell's centre and unit normal.
struct World<'a> {
    rotation: DQuat,
    translation: DVec3,
    cells: &'a [DVec3],
    normals: &'a [DVec3],
}

/// d ln A / d(shape, translation, turn) in closed form, A the sum of the cells' `weights`
/// (a4 and eps1 of an open section left to the caller). ln weight = ln area, and seen
/// from a sensor + ln(-n·q) - 3 ln|q|, q = centre - viewpoint; the shape moves each
/// cell through its corners (`curves`, `likelihood::derivatives`), the pose through its
/// centre and normal (a left turn about world axis k, the turn parameters' convention).
fn log_area_derivatives(
    shape: &Shape,
    curves: &Curves,
    cells: &Cells,
    world: &World,
    sensor: Option<(Sight, f64)>,
    weights: &[f64],
    area: f64,
) -> [f64; 12] {
    let shape = shape.to_array();
    let sectors = curves.sectors();
    // the view weight's dot products are the same in the body's frame: the viewpoint
    // taken there once spares each cell's twelve derivatives a turn into the world
    let inverse = world.rotation.inverse();
    let viewpoints = sensor
        .map(|(Sight { viewpoint, .. }, _)| (viewpoint, inverse * (viewpoint - world.translation)));
    // each weighed cell's d ln weight, side by side; summed in the cells' order below
    let per_cell: Vec<(f64, [f64; 12])> = (0..weights.len())
        .into_par_iter()
        .filter(|&j| weights[j] > 0.0)
        .map(|j| {
            let d = curves.cell(&shape, j / sectors, j % sectors, cells.normals[j]);
            let mut d_log = [0.0; 12];
            let Some((viewpoint, viewpoint_canonical)) = viewpoints else {
                d_log[..6].copy_from_slice(&d.log_area);
                return (weights[j], d_log);
            };
            let q = cells.centres[j] - viewpoint_canonical;
            for k in 0..6 {
                d_log[k] =
                    d_log_view_weight(d.log_area[k], d.centre[k], d.normal[k], cells.normals[j], q);
            }
            let (centre, normal) = (world.cells[j], world.normals[j]);
            let pose = d_log_view_weight_pose(normal, centre, world.translation, viewpoint);
            d_log[6..].copy_from_slice(&pose);
            (weights[j], d_log)
        })
        .collect();
    // (without a sensor the pose's six stay zero)
    let mut d_log_area = [0.0; 12];
    for (w, d_log) in per_cell {
        let share = w / area;
        for k in 0..12 {
            d_log_area[k] += share * d_log[k];
        }
    }
    d_log_area
}

//! The normaliser A of the likelihood: the surface's area, or seen from a sensor the
//! integral over the surface it sees of its density of points, cos(incidence) / range²
//! (relative to a reference range). A is a sum over a coarse grid of the surface (its
//! integrand is smooth), its derivatives by differences of that grid, the visibility (a
//! z-buffer of the grid's mesh, `likelihood::visibility`) found once per evaluation and
//! held for the differences. The per-point sums look the visibility up in the same grid,
//! so the density they integrate is the one A normalises.

use super::tables::{section_range, unit_superellipse};
use crate::fit::likelihood::visibility::View;
use crate::model::Shape;
use glam::{DQuat, DVec3};
use std::f64::consts::TAU;

/// The normaliser's grid: rings along the section, sectors about the axis.
pub const RINGS: usize = 48;
pub const SECTORS: usize = 96;

/// A and d ln A / d(shape, translation, turn), and which cells the sensor sees.
pub struct Normaliser {
    pub area: f64,
    pub d_log_area: [f64; 12],
    /// per cell (ring-major), with a sensor: seen by it
    pub visible: Option<Vec<bool>>,
    /// the section's polar range the rings divide
    pub range: (f64, f64),
}

impl Normaliser {
    /// Whether the sensor sees the surface at section angle `phi` and sweep angle `psi`
    /// (true without a sensor).
    pub fn sees(&self, ring: usize, sector: usize) -> bool {
        self.visible
            .as_ref()
            .is_none_or(|v| v[ring * SECTORS + sector])
    }

    /// The ring holding section angle `phi`.
    pub fn ring_of(&self, phi: f64) -> usize {
        let (lo, hi) = self.range;
        (((phi - lo) / (hi - lo) * RINGS as f64).floor() as isize).clamp(0, RINGS as isize - 1)
            as usize
    }

    /// The sector holding sweep angle `psi` (in [0, 2 pi)).
    pub fn sector_of(psi: f64) -> usize {
        ((psi / TAU * SECTORS as f64).floor() as usize).min(SECTORS - 1)
    }
}

/// The grid's cells (canonical): centres, areas, outward unit normals.
pub fn cells(shape: &Shape) -> (Vec<DVec3>, Vec<f64>, Vec<DVec3>) {
    let (lo, hi, _) = section_range(shape);
    let section: Vec<(f64, f64)> = (0..=RINGS)
        .map(|i| {
            let (c, w, _, _) =
                unit_superellipse(lo + (hi - lo) * i as f64 / RINGS as f64, shape.eps1);
            (c, w)
        })
        .collect();
    let top: Vec<(f64, f64)> = (0..=SECTORS)
        .map(|j| {
            let (x, y, _, _) = unit_superellipse(TAU * j as f64 / SECTORS as f64, shape.eps2);
            (x, y)
        })
        .collect();
    let corner = |i: usize, j: usize| {
        let (c, z) = section[i];
        let (x, y) = top[j];
        let r = (shape.a4 + c).max(0.0);
        DVec3::new(shape.a1 * r * x, shape.a2 * r * y, shape.a3 * z)
    };
    let mut centres = Vec::with_capacity(RINGS * SECTORS);
    let mut areas = Vec::with_capacity(RINGS * SECTORS);
    let mut normals = Vec::with_capacity(RINGS * SECTORS);
    for i in 0..RINGS {
        for j in 0..SECTORS {
            let (c00, c10) = (corner(i, j), corner(i + 1, j));
            let (c01, c11) = (corner(i, j + 1), corner(i + 1, j + 1));
            centres.push((c00 + c10 + c01 + c11) * 0.25);
            // (the section runs anticlockwise in (radius, z), the sweep anticlockwise
            // about z: this cross product points outwards)
            let normal = (c11 - c00).cross(c10 - c01);
            areas.push(0.5 * normal.length());
            normals.push(normal.normalize_or_zero());
        }
    }
    (centres, areas, normals)
}

/// The normaliser at a shape and pose, seen from `sensor` (viewpoint, reference squared
/// range) if any; derivatives with `with_gradient`.
pub fn normaliser(
    shape: &Shape,
    rotation: DQuat,
    translation: DVec3,
    sensor: Option<(DVec3, f64)>,
    with_gradient: bool,
) -> Normaliser {
    let (lo, hi, _) = section_range(shape);
    let (cells, areas, normals) = cells(shape);
    let moved_shape = |k: usize| {
        let mut moved = shape.to_array();
        let step = 1e-6 * moved[k].abs().max(1e-2);
        moved[k] += step;
        (Shape::from_array(moved), step)
    };
    let Some((viewpoint, reference)) = sensor else {
        let area: f64 = areas.iter().sum();
        let mut d_log_area = [0.0; 12];
        if with_gradient {
            for (k, d) in d_log_area.iter_mut().enumerate().take(6) {
                let (moved, step) = moved_shape(k);
                let (_, moved_areas, _) = self::cells(&moved);
                *d = (moved_areas.iter().sum::<f64>() / area - 1.0) / step;
            }
        }
        return Normaliser {
            area,
            d_log_area,
            visible: None,
            range: (lo, hi),
        };
    };
    let world = |cells: &[DVec3], rotation: DQuat, translation: DVec3| -> Vec<DVec3> {
        cells.iter().map(|c| rotation * *c + translation).collect()
    };
    let turn = |normals: &[DVec3], rotation: DQuat| -> Vec<DVec3> {
        normals.iter().map(|n| rotation * *n).collect()
    };
    let world_cells = world(&cells, rotation, translation);
    let world_normals = turn(&normals, rotation);
    let view = View::new(
        &world_cells,
        &areas,
        &world_normals,
        (RINGS, SECTORS),
        viewpoint,
    );
    let density = |areas: &[f64], cells: &[DVec3], normals: &[DVec3]| -> f64 {
        (0..cells.len())
            .filter(|&j| view.visible[j])
            .map(|j| {
                let q = cells[j] - viewpoint;
                let range2 = q.length_squared();
                let cos = normals[j].dot(q).abs() / range2.sqrt();
                areas[j] * cos * reference / range2
            })
            .sum()
    };
    let area = density(&areas, &world_cells, &world_normals).max(1e-300);
    let mut d_log_area = [0.0; 12];
    if with_gradient {
        for (k, d) in d_log_area.iter_mut().enumerate().take(6) {
            let (moved, step) = moved_shape(k);
            let (c2, a2, n2) = self::cells(&moved);
            *d = (density(
                &a2,
                &world(&c2, rotation, translation),
                &turn(&n2, rotation),
            ) / area
                - 1.0)
                / step;
        }
        let step = 1e-6;
        for k in 0..3 {
            let mut shift = DVec3::ZERO;
            shift[k] = step;
            let shifted = world(&cells, rotation, translation + shift);
            d_log_area[6 + k] = (density(&areas, &shifted, &world_normals) / area - 1.0) / step;
            // a turn on the left about world axis k (the turn parameters' convention)
            let turned = DQuat::from_scaled_axis(shift) * rotation;
            d_log_area[9 + k] = (density(
                &areas,
                &world(&cells, turned, translation),
                &turn(&normals, turned),
            ) / area
                - 1.0)
                / step;
        }
    }
    Normaliser {
        area,
        d_log_area,
        visible: Some(view.visible),
        range: (lo, hi),
    }
}

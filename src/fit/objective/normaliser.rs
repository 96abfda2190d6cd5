//! The normaliser A of the likelihood: the surface's area, or seen from a sensor the
//! integral over the surface it sees of its density of points, cos(incidence) / range²
//! (relative to a reference range). A is a sum over a coarse grid of the surface (its
//! integrand is smooth), its derivatives in the sizes and the pose in closed form and in
//! a4 and the exponents by differences of that grid, the visibility (a
//! z-buffer of the grid's mesh, `likelihood::visibility`) found where the caller asks
//! and otherwise held: a refinement holds it through each line search, so the function
//! it minimises does not jump where a cell's visibility flips. The per-point sums look the visibility up in the same grid,
//! so the density they integrate is the one A normalises.

use super::tables::{section_range, unit_superellipse};
use crate::fit::likelihood::{Curves, d_log_view_weight, size_derivatives, visibility::View};
use crate::model::Shape;
use glam::{DQuat, DVec3};
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

/// The unit curves of a grid: the section's points (c, w) and the top view's (x, y) at
/// the rings' and sectors' polar angles.
struct UnitCurves {
    section: Vec<(f64, f64)>,
    top: Vec<(f64, f64)>,
}

impl UnitCurves {
    fn new(shape: &Shape, (rings, sectors): (usize, usize)) -> Self {
        let (lo, hi, _) = section_range(shape);
        Self {
            section: (0..=rings)
                .map(|i| {
                    let phi = lo + (hi - lo) * i as f64 / rings as f64;
                    let (c, w, _, _) = unit_superellipse(phi, shape.eps1);
                    (c, w)
                })
                .collect(),
            top: (0..=sectors)
                .map(|j| {
                    let (x, y, _, _) =
                        unit_superellipse(TAU * j as f64 / sectors as f64, shape.eps2);
                    (x, y)
                })
                .collect(),
        }
    }
}

/// A grid's cells (canonical): centres, areas, outward unit normals.
struct Cells {
    centres: Vec<DVec3>,
    areas: Vec<f64>,
    normals: Vec<DVec3>,
}

impl Cells {
    fn new(shape: &Shape, unit: &UnitCurves) -> Self {
        let (rings, sectors) = (unit.section.len() - 1, unit.top.len() - 1);
        let corner = |i: usize, j: usize| {
            let (c, z) = unit.section[i];
            let (x, y) = unit.top[j];
            let r = (shape.a4 + c).max(0.0);
            DVec3::new(shape.a1 * r * x, shape.a2 * r * y, shape.a3 * z)
        };
        let mut cells = Self {
            centres: Vec::with_capacity(rings * sectors),
            areas: Vec::with_capacity(rings * sectors),
            normals: Vec::with_capacity(rings * sectors),
        };
        let mut previous: Vec<DVec3> = (0..=sectors).map(|j| corner(0, j)).collect();
        for i in 0..rings {
            let next: Vec<DVec3> = (0..=sectors).map(|j| corner(i + 1, j)).collect();
            for j in 0..sectors {
                let (c00, c10) = (previous[j], next[j]);
                let (c01, c11) = (previous[j + 1], next[j + 1]);
                cells.centres.push((c00 + c10 + c01 + c11) * 0.25);
                // (the section runs anticlockwise in (radius, z), the sweep anticlockwise
                // about z: this cross product points outwards)
                let normal = (c11 - c00).cross(c10 - c01);
                cells.areas.push(0.5 * normal.length());
                cells.normals.push(normal.normalize_or_zero());
            }
            previous = next;
        }
        cells
    }
}

/// The normaliser at a shape and pose on a `grid`, seen from `sensor` (viewpoint,
/// reference squared range) if any; derivatives with `with_gradient`.
pub fn normaliser(
    shape: &Shape,
    rotation: DQuat,
    translation: DVec3,
    sensor: Option<(DVec3, f64)>,
    grid: (usize, usize),
    held: Option<&[bool]>,
    with_gradient: bool,
) -> Normaliser {
    let (lo, hi, _) = section_range(shape);
    let unit = UnitCurves::new(shape, grid);
    let cells = Cells::new(shape, &unit);
    // the cells with shape parameter k (a4 or an exponent) moved by a small step (a4
    // moves the end of an open section, so the unit curves are made again)
    let shape_array = shape.to_array();
    let moved = |k: usize| {
        let mut v = shape_array;
        let step = 1e-6 * v[k].abs().max(1e-2);
        v[k] += step;
        let moved = Shape::from_array(v);
        let cells = Cells::new(&moved, &UnitCurves::new(&moved, grid));
        (cells, step)
    };
    // d ln of cell j's weight (its area, or seen along q = centre - viewpoint its
    // density) in the shape parameters known in closed form: all six on a closed section
    // (a4 >= 1: the grid's corners are the grid model's, `likelihood::derivatives`), the
    // sizes alone on an open one, whose ends move with a4 and eps1 (those by differences)
    let curves =
        (with_gradient && shape.a4 >= 1.0).then(|| Curves::new(&shape_array, grid.0, grid.1));
    let analytic = if curves.is_some() { 6 } else { 3 };
    let d_log_weight = |j: usize, q: Option<DVec3>| -> [f64; 6] {
        let mut d = [0.0; 6];
        let Some(curves) = &curves else {
            for (k, d) in d.iter_mut().enumerate().take(3) {
                *d = size_derivatives(
                    &shape_array,
                    k,
                    cells.centres[j],
                    cells.normals[j],
                    rotation,
                    q,
                )
                .1;
            }
            return d;
        };
        let c = curves.cell(&shape_array, j / grid.1, j % grid.1, cells.normals[j]);
        for k in 0..6 {
            d[k] = match q {
                None => c.log_area[k],
                Some(q) => d_log_view_weight(
                    c.log_area[k],
                    rotation * c.centre[k],
                    rotation * c.normal[k],
                    rotation * cells.normals[j],
                    q,
                ),
            };
        }
        d
    };
    let Some((viewpoint, reference)) = sensor else {
        let area: f64 = cells.areas.iter().sum();
        let mut d_log_area = [0.0; 12];
        if with_gradient {
            for j in 0..cells.areas.len() {
                let d_log = d_log_weight(j, None);
                for k in 0..analytic {
                    d_log_area[k] += cells.areas[j] * d_log[k] / area;
                }
            }
            for (k, d) in d_log_area.iter_mut().enumerate().take(6).skip(analytic) {
                let (moved, step) = moved(k);
                *d = (moved.areas.iter().sum::<f64>() / area - 1.0) / step;
            }
        }
        return Normaliser {
            area,
            d_log_area,
            visible: None,
            range: (lo, hi),
            grid,
        };
    };
    let world = |cells: &Cells, rotation: DQuat, translation: DVec3| -> (Vec<DVec3>, Vec<DVec3>) {
        (
            cells
                .centres
                .iter()
                .map(|c| rotation * *c + translation)
                .collect(),
            cells.normals.iter().map(|n| rotation * *n).collect(),
        )
    };
    let (world_cells, world_normals) = world(&cells, rotation, translation);
    let visible: Vec<bool> = match held {
        Some(held) if held.len() == cells.areas.len() => held.to_vec(),
        _ => View::unoccluded(&world_cells, &cells.areas, &world_normals, grid, viewpoint),
    };
    // a cell's density: its area times cos(incidence) / range², relative to the reference
    let density_of = |area: f64, cell: DVec3, normal: DVec3| -> f64 {
        let q = cell - viewpoint;
        let range2 = q.length_squared();
        let cos = (-normal.dot(q)).max(0.0) / range2.sqrt();
        area * cos * reference / range2
    };
    let density = |areas: &[f64], cells: &[DVec3], normals: &[DVec3]| -> f64 {
        (0..cells.len())
            .filter(|&j| visible[j])
            .map(|j| density_of(areas[j], cells[j], normals[j]))
            .sum()
    };
    let area = density(&cells.areas, &world_cells, &world_normals).max(1e-300);
    let mut d_log_area = [0.0; 12];
    if with_gradient {
        // the sizes and the pose in closed form (ln density = ln area + ln(-n·q) - 3 ln|q|,
        // q = centre - viewpoint: as the grid model's view weight, `size_derivatives`)
        for j in (0..world_cells.len()).filter(|&j| visible[j]) {
            let share = density_of(cells.areas[j], world_cells[j], world_normals[j]) / area;
            if share <= 0.0 {
                continue;
            }
            let q = world_cells[j] - viewpoint;
            let d_log = d_log_weight(j, Some(q));
            for k in 0..analytic {
                d_log_area[k] += share * d_log[k];
            }
            let n = world_normals[j];
            let (nq, q2) = (n.dot(q), q.length_squared());
            let by_shift = n / nq - 3.0 * q / q2;
            let by_turn = n.cross(translation - viewpoint) / nq
                - 3.0 * (world_cells[j] - translation).cross(q) / q2;
            for k in 0..3 {
                d_log_area[6 + k] += share * by_shift[k];
                d_log_area[9 + k] += share * by_turn[k];
            }
        }
        for (k, d) in d_log_area.iter_mut().enumerate().take(6).skip(analytic) {
            let (moved, step) = moved(k);
            let (c2, n2) = world(&moved, rotation, translation);
            *d = (density(&moved.areas, &c2, &n2) / area - 1.0) / step;
        }
    }
    Normaliser {
        area,
        d_log_area,
        visible: Some(visible),
        range: (lo, hi),
        grid,
    }
}

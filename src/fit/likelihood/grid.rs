//! The noise model's surface grid: the surface of eq. (2) on a polar grid of cells (each
//! cell's centre, area and outward normal), and the grid's size for a shape and sigma.

use crate::fit::objective::tables::unit_superellipse;
use glam::DVec3;
use rayon::prelude::*;
use std::f64::consts::TAU;

/// The most surface cells; past this the cells grow wider than [`CELL_SIGMAS`] sigmas (the
/// kernel sum then ripples along the surface by 2·exp(-2 pi² / k²) at k sigmas, 22% at 3).
/// On the suite, 12,000 cells at 2 sigmas gave the successes of 20,000 at 1.5 sigmas (441
/// of 540 either way) at about 60% of the time. With the model as it is the
/// cap still binds on the finer grids of 1%-noise single views: 12,000 cells 512 of 540,
/// 24,000 515 (three such views gained, none lost; the single views' median fit time
/// about 10% longer), 48,000 the same 515, slower.
pub const MAX_CELLS: usize = 24_000;
/// The refinement keeps its grid while it is at most this much finer than sigma and the
/// shape call for, and never coarser ([`refine`](super::refine)).
const GRID_SLACK: f64 = 0.1;

/// The grid's two curves at a shape, with their derivatives in the exponents: the
/// section (c, z, dc, dz) per ring boundary (d/d eps1), the top view (x, y, dx, dy) per
/// sector boundary (d/d eps2), both at polar angles. (The polar angle, unlike the
/// eta/omega of eq. (2), spaces points evenly along flat sides and round corners alike,
/// within a factor of about sqrt 2 for eps in [0.1, 2].)
pub(crate) struct Curves {
    pub(super) section: Vec<(f64, f64, f64, f64)>,
    pub(super) top: Vec<(f64, f64, f64, f64)>,
}

/// A grid's cells (canonical, ring-major): centres, areas, outward unit normals.
pub(crate) struct Cells {
    pub centres: Vec<DVec3>,
    pub areas: Vec<f64>,
    pub normals: Vec<DVec3>,
}

impl Curves {
    /// The curves of a grid whose `rings` divide the section's polar range `(lo, hi)`
    /// and whose `sectors` divide the turn.
    pub fn new(shape: &[f64; 6], (lo, hi): (f64, f64), rings: usize, sectors: usize) -> Self {
        Self {
            section: (0..=rings)
                .map(|i| unit_superellipse(lo + (hi - lo) * i as f64 / rings as f64, shape[4]))
                .collect(),
            top: (0..=sectors)
                .map(|j| unit_superellipse(TAU * j as f64 / sectors as f64, shape[5]))
                .collect(),
        }
    }

    /// The curves of a grid closed both ways (a shape with a hole, a4 > 1): its rings
    /// divide the whole turn of the section.
    pub fn closed(shape: &[f64; 6], rings: usize, sectors: usize) -> Self {
        Self::new(shape, (0.0, TAU), rings, sectors)
    }

    /// The grid's sectors (its top view's steps).
    pub fn sectors(&self) -> usize {
        self.top.len() - 1
    }

    /// Corner (i, j) of the grid (canonical): r_t of eq. (2) at the two polar angles, an
    /// open section's ends held on the axis.
    pub(super) fn point(&self, [a1, a2, a3, a4, _, _]: &[f64; 6], i: usize, j: usize) -> DVec3 {
        let (c, z, _, _) = self.section[i];
        let (x, y, _, _) = self.top[j];
        let r = if a4 + c > 0.0 { a4 + c } else { 0.0 };
        DVec3::new(a1 * r * x, a2 * r * y, a3 * z)
    }

    /// The grid's cells: each corner found once, a cell's centre the mean of its four,
    /// its area and normal from the cross product of its diagonals (outward: the section
    /// runs anticlockwise in (radius, z), the sweep anticlockwise about z).
    pub fn cells(&self, shape: &[f64; 6]) -> Cells {
        let (rings, sectors) = (self.section.len() - 1, self.sectors());
        // (split in pieces of at least MIN_PIECE: a coarse grid is a few microseconds' work)
        const MIN_PIECE: usize = 512;
        let corners: Vec<DVec3> = (0..(rings + 1) * (sectors + 1))
            .into_par_iter()
            .with_min_len(MIN_PIECE)
            .map(|k| self.point(shape, k / (sectors + 1), k % (sectors + 1)))
            .collect();
        let at = |i: usize, j: usize| corners[i * (sectors + 1) + j];
        let (centres, (areas, normals)) = (0..rings * sectors)
            .into_par_iter()
            .with_min_len(MIN_PIECE)
            .map(|k| {
                let (i, j) = (k / sectors, k % sectors);
                let (c00, c10, c01, c11) = (at(i, j), at(i + 1, j), at(i, j + 1), at(i + 1, j + 1));
                let normal = (c11 - c00).cross(c10 - c01);
                (
                    (c00 + c10 + c01 + c11) * 0.25,
                    (0.5 * normal.length(), normal.normalize_or_zero()),
                )
            })
            .unzip();
        Cells {
            centres,
            areas,
            normals,
        }
    }
}

/// The surface of eq. (2) on a `rings` x `sectors` polar grid closed both ways (a
/// shape with a hole, a4 > 1): each cell's centre, area and outward unit normal.
pub(super) fn surface_cells(
    shape: &[f64; 6],
    rings: usize,
    sectors: usize,
) -> (Vec<DVec3>, Vec<f64>, Vec<DVec3>) {
    let cells = Curves::closed(shape, rings, sectors).cells(shape);
    (cells.centres, cells.areas, cells.normals)
}

/// Perimeter of the superellipse with half-axes (a, b), from a 64-gon.
fn perimeter(a: f64, b: f64, eps: f64) -> f64 {
    let point = |k: usize| {
        let (u, v, _, _) = unit_superellipse(TAU * k as f64 / 64.0, eps);
        DVec3::new(a * u, b * v, 0.0)
    };
    (0..64).map(|k| (point(k + 1) - point(k)).length()).sum()
}

/// Cells are at most this many sigmas across: the kernel sum on such a grid matches the
/// integral to 2·exp(-2 pi² / 2²), 1.4% (Poisson summation).
pub const CELL_SIGMAS: f64 = 2.0;

/// The rings of [`refine_finely`] are at most this many sigmas apart along the section
/// (half of [`CELL_SIGMAS`]). On a section only a few sigmas thick, rings
/// [`CELL_SIGMAS`] apart bias the model's optimum: refined from the true parameters on
/// 16,000 points of three full clouds at 2% noise (three samples each),
/// eps1 came out +0.01 to +0.11 high (mean +0.04) and a3 up to 3% long; with rings one
/// sigma apart, -0.06 to +0.07 (mean 0.00) and a3 within 2%. Finer sectors changed
/// nothing.
pub const FINE_SECTION_CELL_SIGMAS: f64 = 1.0;

/// Grid size for cells about `section_cell_sigmas` sigmas along the section and
/// [`CELL_SIGMAS`] around the hole, capped at [`MAX_CELLS`].
pub(super) fn grid_for(shape: &[f64; 6], sigma: f64, section_cell_sigmas: f64) -> (usize, usize) {
    let [a1, a2, a3, a4, eps1, eps2] = *shape;
    let section = perimeter(a1.max(a2), a3, eps1);
    let outer = perimeter(a1 * (a4 + 1.0), a2 * (a4 + 1.0), eps2);
    let mut rings = (section / (section_cell_sigmas * sigma))
        .ceil()
        .clamp(16.0, 400.0);
    let mut sectors = (outer / (CELL_SIGMAS * sigma)).ceil().clamp(32.0, 2000.0);
    let cells = rings * sectors;
    if cells > MAX_CELLS as f64 {
        let shrink = (MAX_CELLS as f64 / cells).sqrt();
        rings = (rings * shrink).ceil().max(16.0);
        sectors = (sectors * shrink).ceil().max(32.0);
    }
    (rings as usize, sectors as usize)
}

/// The grid for the refinement's next step, from its grid `now` and the one sigma and the
/// shape call for ([`grid_for`]): that one where `now` is coarser in either direction or
/// more than [`GRID_SLACK`] finer, else `now`. Why keep it: the objective steps a little
/// between grids, and a grid remade on every step let the iterations cycle between two
/// grids to the iteration cap (on the suite's single views the refinement then ended
/// where the cap fell; with the slack 517 of 540 against 518, the full clouds' mean fit
/// time 31 -> 21 ms).
pub(super) fn regrid(now: (usize, usize), ideal: (usize, usize)) -> (usize, usize) {
    let off =
        |now: usize, ideal: usize| now < ideal || now as f64 > (1.0 + GRID_SLACK) * ideal as f64;
    if off(now.0, ideal.0) || off(now.1, ideal.1) {
        ideal
    } else {
        now
    }
}

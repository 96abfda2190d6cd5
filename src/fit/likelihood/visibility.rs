//! What a depth sensor sees of the noise model's surface grid: which cells no other part
//! of the surface hides, and the sensor's density of points over the cells it sees.

use crate::fit::sight::Sight;
use glam::{DQuat, DVec3};
use rayon::prelude::*;

/// What a sensor at `viewpoint` sees of the surface at one parameter vector: which cells
/// (held for that vector's shape differences) and the squared range of the cells' centre
/// (the reference of [`View::weights`]).
pub(crate) struct View {
    pub(crate) viewpoint: DVec3,
    pub(crate) visible: Vec<bool>,
    pub(crate) reference: f64,
}

impl View {
    pub(crate) fn new(
        cells: &[DVec3],
        areas: &[f64],
        normals: &[DVec3],
        grid: (usize, usize),
        sight: Sight,
    ) -> Self {
        let centre = cells.iter().copied().sum::<DVec3>() / cells.len().max(1) as f64;
        let visible = visibility(cells, areas, normals, grid, centre, sight, true);
        let viewpoint = sight.viewpoint;
        Self {
            viewpoint,
            visible,
            reference: (centre - viewpoint).length_squared(),
        }
    }

    /// Which cells no other part of the surface hides from a sensor at `viewpoint`,
    /// whether they face it or not: a cell across a sharp edge (the rim of a pinched
    /// section) faces away at its centre while half of it faces the sensor, so a caller
    /// that weighs the parts of each cell by their own incidence asks this.
    pub(crate) fn unoccluded(
        cells: &[DVec3],
        areas: &[f64],
        normals: &[DVec3],
        grid: (usize, usize),
        sight: Sight,
    ) -> Vec<bool> {
        let centre = cells.iter().copied().sum::<DVec3>() / cells.len().max(1) as f64;
        visibility(cells, areas, normals, grid, centre, sight, false)
    }

    /// A depth sensor's points per unit area of a surface it sees: cos(incidence) /
    /// range² (a pixel's footprint grows with range² and 1/cos), relative to the range of
    /// the cells' centre; zero where it does not see. (A common scale of all the weights
    /// cancels in the likelihood, so the reference need not follow the differences.)
    pub(super) fn weights(
        &self,
        areas: &[f64],
        cells: &[DVec3],
        normals: &[DVec3],
        rotation: DQuat,
    ) -> Vec<f64> {
        (0..cells.len())
            .into_par_iter()
            .map(|j| self.weight(j, areas[j], cells[j], normals[j], rotation))
            .collect()
    }

    /// [`View::weights`] of cell `j` alone.
    pub(super) fn weight(
        &self,
        j: usize,
        area: f64,
        cell: DVec3,
        normal: DVec3,
        rotation: DQuat,
    ) -> f64 {
        if !self.visible[j] {
            return 0.0;
        }
        let q = cell - self.viewpoint;
        let range2 = q.length_squared();
        let cos = (rotation * normal).dot(q).abs() / range2.sqrt();
        area * cos * self.reference / range2
    }
}

/// Which cells a sensor at `viewpoint` sees, from a z-buffer of the surface itself: the
/// cells' centres, a `rings` x `sectors` grid closed in both directions (see
/// [`super::surface_cells`]), are the vertices of a triangle mesh of the surface; its triangles
/// with a vertex facing the sensor are rasterised at half a cell's width per pixel, and a
/// centre facing the sensor is seen where it is no deeper than the mesh in its pixel
/// (plus the depth its own surface spans across a pixel at its incidence). The occluding
/// edges then follow the surface to a fraction of a cell whatever the grid.
/// Nor does it see a cell outside its frame's edges, where they are known ([`Sight`]).
///
/// Why the mesh: the depth buffer it replaced held whole cells, two to a pixel, and hid
/// strips of seen cells along every occluding edge (6% of the seen weight in
/// `the_visible_cells_are_those_no_surface_hides`, 0.1-0.4% now), a different strip on
/// each grid: the objective jumped by 0.02-0.07 per point when sigma moved the grid by one
/// ring (0.01 now), and the refinement stalled or cycled between grids. With the mesh the
/// truth of the suite's single views is far more likely (by up to 0.1 per point) and
/// the model from the truth recovers 532 of 540 cases instead of 528
/// (`examples/model_ceiling.rs`, all points; 527 instead of 520 on the fit's sample). It
/// costs about 1.3 ms per evaluation at 19,000 cells (0.5 ms before; two threads).
pub(crate) fn visibility(
    cells: &[DVec3],
    areas: &[f64],
    normals: &[DVec3],
    (rings, sectors): (usize, usize),
    centre: DVec3,
    sight: Sight,
    facing_only: bool,
) -> Vec<bool> {
    let viewpoint = sight.viewpoint;
    let m = cells.len();
    let forward = (centre - viewpoint).normalize_or(DVec3::Z);
    let right = forward.any_orthonormal_vector();
    let up = forward.cross(right);
    let spacing = (areas.iter().sum::<f64>() / m.max(1) as f64)
        .sqrt()
        .max(1e-9);
    let distance = (centre - viewpoint).length().max(1e-9);
    // (screen u, screen w, depth along `forward`)
    let projected: Vec<Option<(f64, f64, f64)>> = cells
        .par_iter()
        .map(|s| {
            let q = *s - viewpoint;
            let depth = q.dot(forward);
            (depth > 1e-9).then(|| (q.dot(right) / depth, q.dot(up) / depth, depth))
        })
        .collect();
    // each cell's incidence cosine, positive where it faces the sensor (outward normals)
    let incidence: Vec<f64> = cells
        .par_iter()
        .zip(normals)
        .map(|(cell, normal)| {
            let q = *cell - viewpoint;
            -normal.dot(q) / q.length().max(1e-300)
        })
        .collect();
    let facing: Vec<bool> = incidence.iter().map(|&cos| cos > 0.0).collect();
    let (mut lo, mut hi) = (
        (f64::INFINITY, f64::INFINITY),
        (f64::NEG_INFINITY, f64::NEG_INFINITY),
    );
    for (u, w, _) in projected.iter().flatten() {
        lo = (lo.0.min(*u), lo.1.min(*w));
        hi = (hi.0.max(*u), hi.1.max(*w));
    }
    if !(lo.0 <= hi.0) {
        return vec![false; m];
    }
    let pixel = (0.5 * spacing / distance).max((hi.0 - lo.0).max(hi.1 - lo.1) / 2048.0);
    let width = ((hi.0 - lo.0) / pixel) as usize + 1;
    let height = ((hi.1 - lo.1) / pixel) as usize + 1;
    let screen = |(u, w, z): (f64, f64, f64)| ((u - lo.0) / pixel, (w - lo.1) / pixel, z);
    let raster = |nearest: &mut [f32], a, b, c| raster(nearest, (width, height), a, b, c);
    let on_screen: Vec<Option<(f64, f64, f64)>> = projected.iter().map(|p| p.map(screen)).collect();
    let triangles_of_ring = |nearest: &mut [f32], i: usize| {
        let next_ring = if i + 1 == rings { 0 } else { i + 1 };
        for j in 0..sectors {
            let next_sector = if j + 1 == sectors { 0 } else { j + 1 };
            let quad = [
                i * sectors + j,
                next_ring * sectors + j,
                next_ring * sectors + next_sector,
                i * sectors + next_sector,
            ];
            for [k0, k1, k2] in [[quad[0], quad[1], quad[2]], [quad[0], quad[2], quad[3]]] {
                // behind every triangle facing away from the sensor there is one facing
                // it (a closed surface): those with a vertex facing it suffice
                if !(facing[k0] || facing[k1] || facing[k2]) {
                    continue;
                }
                if let (Some(a), Some(b), Some(c)) = (on_screen[k0], on_screen[k1], on_screen[k2]) {
                    raster(nearest, a, b, c);
                }
            }
        }
    };
    // the rings in bands, one buffer per band, merged by the nearest
    let band = rings.div_ceil(rayon::current_num_threads().max(1));
    let nearest = (0..rings)
        .into_par_iter()
        .with_min_len(band)
        .fold(
            || vec![0.0f32; width * height],
            |mut nearest, i| {
                triangles_of_ring(&mut nearest, i);
                nearest
            },
        )
        .reduce_with(|mut a, b| {
            for (x, y) in a.iter_mut().zip(&b) {
                *x = x.max(*y);
            }
            a
        })
        .unwrap_or_default();
    (0..m)
        .into_par_iter()
        .map(|j| {
            let Some(p) = projected[j] else { return false };
            if facing_only && !facing[j] {
                return false;
            }
            // past the frame's edges the sensor saw nothing
            if !sight.frames(cells[j]) {
                return false;
            }
            let (x, y, depth) = screen(p);
            let k = (y as usize).min(height - 1) * width + (x as usize).min(width - 1);
            if nearest[k] <= 0.0 {
                return true;
            }
            // the depth the cell's own surface spans from its centre to a pixel's
            // centre: a pixel's diagonal times tan(incidence), the cosine floored at 0.1
            let cos = incidence[j].abs().max(0.1);
            let slope = std::f64::consts::SQRT_2 * pixel * depth * (1.0 - cos * cos).sqrt() / cos;
            depth <= 1.0 / nearest[k] as f64 + 0.25 * spacing + slope
        })
        .collect()
}

/// Draws the triangle a b c (screen x, y in pixels, depth) into `nearest`, the nearest
/// surface per pixel of a `width` x `height` screen as 1/depth (affine across a triangle
/// on the screen; 0: nothing there).
fn raster(
    nearest: &mut [f32],
    (width, height): (usize, usize),
    a: (f64, f64, f64),
    b: (f64, f64, f64),
    c: (f64, f64, f64),
) {
    let x0 = (a.0.min(b.0).min(c.0) - 0.5).ceil().max(0.0);
    let x1 = (a.0.max(b.0).max(c.0) - 0.5)
        .floor()
        .min(width as f64 - 1.0);
    let y0 = (a.1.min(b.1).min(c.1) - 0.5).ceil().max(0.0);
    let y1 = (a.1.max(b.1).max(c.1) - 0.5)
        .floor()
        .min(height as f64 - 1.0);
    // (most triangles are about a pixel wide; many hold no pixel's centre)
    if x1 < x0 || y1 < y0 {
        return;
    }
    let area = (b.0 - a.0) * (c.1 - a.1) - (c.0 - a.0) * (b.1 - a.1);
    if area.abs() < 1e-12 {
        return;
    }
    let scale = 1.0 / area;
    let (ia, ib, ic) = (1.0 / a.2, 1.0 / b.2, 1.0 / c.2);
    for py in y0 as usize..=y1 as usize {
        let y = py as f64 + 0.5;
        for px in x0 as usize..=x1 as usize {
            let x = px as f64 + 0.5;
            let wa = ((b.0 - x) * (c.1 - y) - (c.0 - x) * (b.1 - y)) * scale;
            let wb = ((c.0 - x) * (a.1 - y) - (a.0 - x) * (c.1 - y)) * scale;
            let wc = 1.0 - wa - wb;
            if wa < -1e-9 || wb < -1e-9 || wc < -1e-9 {
                continue;
            }
            let inverse = (wa * ia + wb * ib + wc * ic) as f32;
            let k = py * width + px;
            if inverse > nearest[k] {
                nearest[k] = inverse;
            }
        }
    }
}

//! The surface grid's cells differentiated in the shape in closed form: each corner of
//! the grid is r_t of eq. (2) at polar angles ([`Curves::point`]), so its derivative
//! in a size is its own coordinate over that size, and in a4 or in an exponent a product
//! of the two curves' points and their derivatives; a cell's centre is the mean of its
//! corners, its area and normal come from the cross product of its diagonals.

use super::grid::Curves;
use glam::DVec3;

impl Curves {
    /// Corner (i, j) of the grid (canonical) and its derivatives in a4, eps1 and eps2 (the
    /// sizes' are the corner's own coordinates, [`Curves::cell`]).
    fn corner(&self, shape: &[f64; 6], i: usize, j: usize) -> (DVec3, [DVec3; 3]) {
        let [a1, a2, a3, a4, _, _] = *shape;
        let (c, _, dc, dz) = self.section[i];
        let (x, y, dx, dy) = self.top[j];
        // (an open section's ends lie on the axis: r held at zero there)
        let (r, dr_da4, dr_deps1) = if a4 + c > 0.0 {
            (a4 + c, 1.0, dc)
        } else {
            (0.0, 0.0, 0.0)
        };
        (
            self.point(shape, i, j),
            [
                DVec3::new(a1 * dr_da4 * x, a2 * dr_da4 * y, 0.0),
                DVec3::new(a1 * dr_deps1 * x, a2 * dr_deps1 * y, a3 * dz),
                DVec3::new(a1 * r * dx, a2 * r * dy, 0.0),
            ],
        )
    }

    /// Cell (i, j)'s derivatives in the six shape parameters: d centre (canonical), and
    /// d ln area and d normal (unit, canonical) per parameter; `normal` is the cell's
    /// outward unit normal, which orients the diagonals' cross product.
    pub fn cell(&self, shape: &[f64; 6], i: usize, j: usize, normal: DVec3) -> CellDerivatives {
        let [a1, a2, a3, _, _, _] = *shape;
        let (c00, d00) = self.corner(shape, i, j);
        let (c10, d10) = self.corner(shape, i + 1, j);
        let (c01, d01) = self.corner(shape, i, j + 1);
        let (c11, d11) = self.corner(shape, i + 1, j + 1);
        let (u, v) = (c11 - c00, c10 - c01);
        let outward = if u.cross(v).dot(normal) < 0.0 {
            -1.0
        } else {
            1.0
        };
        let normal = outward * u.cross(v);
        let length = normal.length();
        let unit = if length > 0.0 {
            normal / length
        } else {
            DVec3::ZERO
        };
        let centre = (c00 + c10 + c01 + c11) * 0.25;
        let mut out = CellDerivatives {
            centre: [
                DVec3::new(centre.x / a1, 0.0, 0.0),
                DVec3::new(0.0, centre.y / a2, 0.0),
                DVec3::new(0.0, 0.0, centre.z / a3),
                DVec3::ZERO,
                DVec3::ZERO,
                DVec3::ZERO,
            ],
            log_area: [0.0; 6],
            normal: [DVec3::ZERO; 6],
        };
        // a size stretches the grid along its own axis, each corner P by (P.x / a1, 0, 0)
        // for a1: so d(u x v) = (0, N.y, N.z) / a1 (and likewise for a2, a3), N = u x v
        let mut d_normals = [
            DVec3::new(0.0, normal.y, normal.z) / a1,
            DVec3::new(normal.x, 0.0, normal.z) / a2,
            DVec3::new(normal.x, normal.y, 0.0) / a3,
            DVec3::ZERO,
            DVec3::ZERO,
            DVec3::ZERO,
        ];
        for k in 0..3 {
            out.centre[3 + k] = (d00[k] + d10[k] + d01[k] + d11[k]) * 0.25;
            d_normals[3 + k] = outward * ((d11[k] - d00[k]).cross(v) + u.cross(d10[k] - d01[k]));
        }
        if length > 0.0 {
            for k in 0..6 {
                let d_normal = d_normals[k] / length;
                out.log_area[k] = unit.dot(d_normal);
                out.normal[k] = d_normal - unit * out.log_area[k];
            }
        }
        out
    }
}

/// What [`Curves::cell`] gives.
pub(crate) struct CellDerivatives {
    pub centre: [DVec3; 6],
    pub log_area: [f64; 6],
    pub normal: [DVec3; 6],
}

/// d ln of a cell's view weight, area · |n·q| / |q|³ ([`super::View::weight`]), from d ln
/// area, the derivatives of its centre and unit normal, its unit normal and q = centre -
/// viewpoint, all in one frame (the world's or the body's: only dot products are taken).
pub(crate) fn d_log_view_weight(
    d_log_area: f64,
    d_centre: DVec3,
    d_normal: DVec3,
    normal: DVec3,
    q: DVec3,
) -> f64 {
    d_log_area + (d_normal.dot(q) + normal.dot(d_centre)) / normal.dot(q)
        - 3.0 * q.dot(d_centre) / q.length_squared()
}

/// d ln of a cell's view weight, area · |n·q| / |q|³, in the pose: moving the body by dt
/// moves q = centre - viewpoint by dt; turning it by a left rotation vector dr moves q by
/// dr x (centre - t) and n by dr x n, so n·q by dr·(n x (t - v)). The shift's three
/// partials, then the turn's; `normal` the world unit normal, `centre` the world centre.
pub(crate) fn d_log_view_weight_pose(
    normal: DVec3,
    centre: DVec3,
    translation: DVec3,
    viewpoint: DVec3,
) -> [f64; 6] {
    let q = centre - viewpoint;
    let (nq, q2) = (normal.dot(q), q.length_squared());
    let by_shift = normal / nq - 3.0 * q / q2;
    let by_turn =
        normal.cross(translation - viewpoint) / nq - 3.0 * (centre - translation).cross(q) / q2;
    [
        by_shift.x, by_shift.y, by_shift.z, by_turn.x, by_turn.y, by_turn.z,
    ]
}

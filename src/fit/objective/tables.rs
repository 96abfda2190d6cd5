//! The quadrature of the surface integral: the supertoroid is its section curve swept
//! about the hole axis (paper eq. 2), so a surface point is
//!
//!   S(phi, psi) = ((a4 + c(phi)) · C(psi), a3 · w(phi)),
//!
//! (c, w) on the unit section superellipse (exponent eps1) and C = (a1 x, a2 y) on the
//! top view's (exponent eps2), both taken at polar angles (which space points evenly along
//! flat sides and round corners alike, within a factor of about sqrt 2). The integral is
//! a tensor-product sum over section nodes and sweep samples; each table here holds one
//! direction at the current shape, with the derivatives in the shape parameters it
//! depends on. The nodes themselves (their polar angles) are held for a run of
//! evaluations ([`Grid`]), so the line search sees one function.

use crate::model::Shape;
use std::f64::consts::{PI, TAU};

/// Section nodes are at most this many sigmas apart along the section.
pub const NODE_SIGMAS: f64 = 1.0;
/// Sweep samples are at most this many sigmas apart on the outermost sweep. (A Gaussian
/// summed at spacing h sigmas misses its integral by 2·exp(-2 pi² / h²): 1e-8 at 1,
/// 3e-4 at 1.5.)
pub const SWEEP_SIGMAS: f64 = 1.5;
/// The fewest and the most section nodes.
const MIN_NODES: usize = 24;
const MAX_NODES: usize = 720;
/// The fewest and the most sweep samples.
const MIN_SWEEP: usize = 48;
const MAX_SWEEP: usize = 4096;

/// The unit superellipse |x|^(2/e) + |y|^(2/e) = 1 at polar angle phi, with the
/// derivatives of (x, y) in e.
pub fn unit_superellipse(phi: f64, e: f64) -> (f64, f64, f64, f64) {
    let (sin, cos) = phi.sin_cos();
    let k = 2.0 / e;
    let (ac, aw) = (cos.abs(), sin.abs());
    let m = ac.max(aw);
    // S = t_x^k + t_y^k with t = |.|/m; r = S^(-e/2) / m
    let part = |a: f64| {
        if a == 0.0 {
            (0.0, 0.0)
        } else {
            let ln = (a / m).ln();
            ((k * ln).exp(), ln)
        }
    };
    let (px, lx) = part(ac);
    let (py, ly) = part(aw);
    let sum = px + py;
    let r = (-(e / 2.0) * sum.ln()).exp() / m;
    // d ln r / de = -ln(S)/2 - (e/2)(dS/de)/S, dS/de = sum p·ln t·(-2/e²)
    let ds = -(2.0 / (e * e)) * (px * lx + py * ly);
    let dlnr = -0.5 * sum.ln() - 0.5 * e * ds / sum;
    (r * cos, r * sin, r * cos * dlnr, r * sin * dlnr)
}

/// The polar range of the section on the implicit surface: the whole turn where a4 >= 1
/// (closed), else the arc with a4 + c >= 0, from one pole on the axis to the other.
pub fn section_range(shape: &Shape) -> (f64, f64, bool) {
    if shape.a4 >= 1.0 {
        return (0.0, TAU, true);
    }
    // c falls from 1 to -1 on [0, pi]: bisect a4 + c = 0
    let (mut lo, mut hi) = (0.0, PI);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if shape.a4 + unit_superellipse(mid, shape.eps1).0 > 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    (-lo, lo, false)
}

/// Where the quadrature samples the surface: the section nodes' polar angles (at equal
/// arclength steps of at most [`NODE_SIGMAS`] sigmas) and the number of sweep samples
/// (uniform in polar angle, the steps on the outermost sweep at most [`SWEEP_SIGMAS`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Grid {
    pub section: Vec<f64>,
    /// the section closes on itself (a4 >= 1); otherwise it runs from pole to pole
    pub closed: bool,
    /// the open section's end angles (its poles on the axis)
    pub range: (f64, f64),
    pub sweep: usize,
}

impl Grid {
    pub fn for_shape(shape: &Shape, sigma: f64) -> Self {
        const FINE: usize = 512;
        let (lo, hi, closed) = section_range(shape);
        let across = (shape.a1 * shape.a2).sqrt();
        let at = |i: usize| lo + (hi - lo) * i as f64 / FINE as f64;
        let polyline: Vec<(f64, f64)> = (0..=FINE)
            .map(|i| {
                let (c, w, _, _) = unit_superellipse(at(i), shape.eps1);
                (across * c, shape.a3 * w)
            })
            .collect();
        let mut cumulative = vec![0.0; FINE + 1];
        for i in 1..=FINE {
            let (a, b) = (polyline[i - 1], polyline[i]);
            cumulative[i] = cumulative[i - 1] + (b.0 - a.0).hypot(b.1 - a.1);
        }
        let length = cumulative[FINE];
        let count = ((length / (NODE_SIGMAS * sigma)).ceil() as usize).clamp(MIN_NODES, MAX_NODES);
        let section = (0..count)
            .map(|k| {
                // closed: whole steps; open: half steps, clear of the poles
                let offset = if closed { 0.0 } else { 0.5 };
                let target = length * (k as f64 + offset) / count as f64;
                let i = cumulative.partition_point(|&c| c < target).clamp(1, FINE);
                let (c0, c1) = (cumulative[i - 1], cumulative[i]);
                let f = if c1 > c0 {
                    (target - c0) / (c1 - c0)
                } else {
                    0.0
                };
                at(i - 1) + f * (at(i) - at(i - 1))
            })
            .collect();
        // the longest step of the top view's polar samples, per sample, on the outermost
        // sweep (radius 1 + a4 in units of the top view)
        const PROBE: usize = 256;
        let top: Vec<(f64, f64)> = (0..=PROBE)
            .map(|j| {
                let (x, y, _, _) = unit_superellipse(TAU * j as f64 / PROBE as f64, shape.eps2);
                (shape.a1 * x, shape.a2 * y)
            })
            .collect();
        let longest = top
            .windows(2)
            .map(|w| (w[1].0 - w[0].0).hypot(w[1].1 - w[0].1))
            .fold(0.0, f64::max);
        let outer = 1.0 + shape.a4;
        let sweep = ((longest * PROBE as f64 * outer / (SWEEP_SIGMAS * sigma)).ceil() as usize)
            .clamp(MIN_SWEEP, MAX_SWEEP);
        Self {
            section,
            closed,
            range: (lo, hi),
            sweep,
        }
    }
}

/// The section nodes at the current eps1: unit-section points (c, w), their
/// eps1-derivatives, and the tangent step t = (P_next - P_prev) / 2 (the trapezoid rule's
/// share of the curve at each node) with its eps1-derivative.
pub struct SectionTable {
    pub point: Vec<[f64; 2]>,
    pub d_point: Vec<[f64; 2]>,
    pub tangent: Vec<[f64; 2]>,
    pub d_tangent: Vec<[f64; 2]>,
    /// the tangent step's two halves, towards the previous node and the next (each a
    /// straight piece of the curve: their lengths add up to the arc where the tangent
    /// step's own cuts a corner), and their eps1-derivatives
    pub halves: Vec<[[f64; 2]; 2]>,
    pub d_halves: Vec<[[f64; 2]; 2]>,
    pub closed: bool,
}

impl SectionTable {
    pub fn new(grid: &Grid, eps1: f64) -> Self {
        let n = grid.section.len();
        let eval = |phi: f64| {
            let (c, w, dc, dw) = unit_superellipse(phi, eps1);
            ([c, w], [dc, dw])
        };
        let (point, d_point): (Vec<[f64; 2]>, Vec<[f64; 2]>) =
            grid.section.iter().map(|&phi| eval(phi)).unzip();
        // an open section's neighbours beyond its end nodes are its poles
        let (first_pole, last_pole) = (eval(grid.range.0), eval(grid.range.1));
        let neighbour = |k: isize| -> ([f64; 2], [f64; 2]) {
            if k < 0 {
                if grid.closed {
                    (point[n - 1], d_point[n - 1])
                } else {
                    first_pole
                }
            } else if k as usize >= n {
                if grid.closed {
                    (point[0], d_point[0])
                } else {
                    last_pole
                }
            } else {
                (point[k as usize], d_point[k as usize])
            }
        };
        let mut halves = Vec::with_capacity(n);
        let mut d_halves = Vec::with_capacity(n);
        for k in 0..n as isize {
            let (prev, d_prev) = neighbour(k - 1);
            let (next, d_next) = neighbour(k + 1);
            let (own, d_own) = (point[k as usize], d_point[k as usize]);
            // each node stands for one step of the curve: its two chords span two, but
            // at an open end (half a step from its pole) one and a half
            let scale = if !grid.closed && (k == 0 || k as usize == n - 1) {
                1.0 / 1.5
            } else {
                0.5
            };
            let half = |a: [f64; 2], b: [f64; 2]| [scale * (b[0] - a[0]), scale * (b[1] - a[1])];
            halves.push([half(prev, own), half(own, next)]);
            d_halves.push([half(d_prev, d_own), half(d_own, d_next)]);
        }
        let sum = |h: &[[f64; 2]; 2]| [h[0][0] + h[1][0], h[0][1] + h[1][1]];
        let tangent = halves.iter().map(sum).collect();
        let d_tangent = d_halves.iter().map(sum).collect();
        Self {
            point,
            d_point,
            tangent,
            d_tangent,
            halves,
            d_halves,
            closed: grid.closed,
        }
    }
}

/// The sweep samples at the current a1, a2, eps2: C_m = (a1 x, a2 y) at polar angle
/// psi_m = m · step, its eps2-derivative, and the step D_m = (C_next - C_prev) / 2 with its
/// eps2-derivative. (C and D scale with a1 along x and a2 along y.)
pub struct SweepTable {
    pub point: Vec<[f64; 2]>,
    pub d_point: Vec<[f64; 2]>,
    pub tangent: Vec<[f64; 2]>,
    pub d_tangent: Vec<[f64; 2]>,
    /// the polar step between samples
    pub step: f64,
}

impl SweepTable {
    pub fn new(grid: &Grid, a1: f64, a2: f64, eps2: f64) -> Self {
        let m = grid.sweep;
        let step = TAU / m as f64;
        let (point, d_point): (Vec<[f64; 2]>, Vec<[f64; 2]>) = (0..m)
            .map(|j| {
                let (x, y, dx, dy) = unit_superellipse(step * j as f64, eps2);
                ([a1 * x, a2 * y], [a1 * dx, a2 * dy])
            })
            .unzip();
        let (tangent, d_tangent) = (0..m)
            .map(|j| {
                let (prev, next) = ((j + m - 1) % m, (j + 1) % m);
                (
                    [
                        0.5 * (point[next][0] - point[prev][0]),
                        0.5 * (point[next][1] - point[prev][1]),
                    ],
                    [
                        0.5 * (d_point[next][0] - d_point[prev][0]),
                        0.5 * (d_point[next][1] - d_point[prev][1]),
                    ],
                )
            })
            .unzip();
        Self {
            point,
            d_point,
            tangent,
            d_tangent,
            step,
        }
    }

    /// The sample nearest the ray from the axis through canonical (x, y).
    pub fn nearest(&self, x: f64, y: f64, a1: f64, a2: f64) -> usize {
        let psi = (y / a2).atan2(x / a1).rem_euclid(TAU);
        ((psi / self.step).round() as usize) % self.point.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_unit_superellipse_derivative_matches_differences() {
        for phi in [0.1, 0.7, 1.5, 2.9, 4.0] {
            for e in [0.2, 0.7, 1.0, 1.6] {
                let (x, y, dx, dy) = unit_superellipse(phi, e);
                let h = 1e-6;
                let (x2, y2, _, _) = unit_superellipse(phi, e + h);
                let (x1, y1, _, _) = unit_superellipse(phi, e - h);
                assert!((dx - (x2 - x1) / (2.0 * h)).abs() < 1e-6, "dx at {phi} {e}");
                assert!((dy - (y2 - y1) / (2.0 * h)).abs() < 1e-6, "dy at {phi} {e}");
                let f = x.abs().powf(2.0 / e) + y.abs().powf(2.0 / e);
                assert!((f - 1.0).abs() < 1e-9);
            }
        }
    }

    /// The section's tangent steps add up to its perimeter (a closed circle and an open
    /// half circle).
    #[test]
    fn the_section_steps_add_up_to_the_curve() {
        let sigma = 0.01;
        let ring = Shape::new(0.3, 0.3, 1.0, 2.0, 1.0, 1.0);
        let grid = Grid::for_shape(&ring, sigma);
        let table = SectionTable::new(&grid, 1.0);
        let perimeter: f64 = table.tangent.iter().map(|t| t[0].hypot(t[1])).sum::<f64>();
        // unit circle
        assert!((perimeter / TAU - 1.0).abs() < 1e-3, "{perimeter}");
        let ball = Shape::new(1.0, 1.0, 1.0, 0.0, 1.0, 1.0);
        let grid = Grid::for_shape(&ball, sigma);
        assert!(!grid.closed);
        let table = SectionTable::new(&grid, 1.0);
        let half: f64 = table.tangent.iter().map(|t| t[0].hypot(t[1])).sum::<f64>();
        assert!((half / PI - 1.0).abs() < 1e-3, "{half}");
    }
}

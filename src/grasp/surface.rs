//! Surface queries on a fitted object (paper §IV): points of the surface with their unit
//! normals, principal curvatures and principal directions, in the world frame, on a grid
//! of the parameters, at given parameters, or nearest to given points.
//!
//! Limits, by design rather than NaN:
//! * The seams (a cosine or sine of eta or omega zero) are singular for eps != 1: the
//!   parametrisation's derivatives vanish or blow up there. A parameter within
//!   [`SEAM_OFFSET`] of a seam is moved that far beside it and the answer says `seam:
//!   true`: the normal is then the one-sided limit (at eps = 2 the seam is a corner of
//!   the section, above 2 a cusp, so there is no two-sided normal at all) and a
//!   curvature can be large (eps between 1 and 2 has infinite curvature at the seam).
//! * Without a through hole (a4 < 1) only |eta| <= [`Shape::eta_range`] lies on the
//!   surface; eta beyond it is refused, and the end points on the axis are seams.
//! * A point at a section centre, where the meridian ray is undefined, is projected along
//!   the section's x' direction (as [`meridian_distance`] does).

use crate::model::{
    Pose, PrincipalFrame, Shape, meridian_distance, principal_frame, signed_pow, surface_jet,
};
use glam::DVec3;
use serde::Serialize;
use std::f64::consts::{FRAC_PI_2, PI, TAU};

/// How far (radians) a parameter is moved off a seam.
pub const SEAM_OFFSET: f64 = 1e-3;

/// One point of the surface, in the world frame.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, utoipa::ToSchema)]
pub struct SurfacePoint {
    /// the parameters the quantities were taken at (moved off a seam where `seam`)
    pub eta: f64,
    pub omega: f64,
    #[schema(value_type = Vec<f64>)]
    pub point: [f64; 3],
    /// unit outward normal
    #[schema(value_type = Vec<f64>)]
    pub normal: [f64; 3],
    /// principal curvatures k1 >= k2 (1/length; positive where convex: 1/R on a sphere)
    #[schema(value_type = Vec<f64>)]
    pub curvatures: [f64; 2],
    /// unit principal directions, tangent to the surface, for k1 and k2
    #[schema(value_type = Vec<Vec<f64>>)]
    pub directions: [[f64; 3]; 2],
    /// true where a parameter lay on a seam and was moved [`SEAM_OFFSET`] beside it
    pub seam: bool,
}

impl SurfacePoint {
    /// Whether every quantity is a finite number.
    pub fn is_finite(&self) -> bool {
        [self.eta, self.omega]
            .iter()
            .chain(&self.point)
            .chain(&self.normal)
            .chain(&self.curvatures)
            .chain(self.directions.iter().flatten())
            .all(|v| v.is_finite())
    }
}

/// Moves an angle off the nearest multiple of pi/2 when within [`SEAM_OFFSET`] of it.
fn off_seam(angle: f64) -> (f64, bool) {
    let quarter = (angle / FRAC_PI_2).round() * FRAC_PI_2;
    let d = angle - quarter;
    if d.abs() >= SEAM_OFFSET {
        (angle, false)
    } else if d >= 0.0 {
        (quarter + SEAM_OFFSET, true)
    } else {
        (quarter - SEAM_OFFSET, true)
    }
}

/// [`off_seam`] where the exponent makes the seam singular (eps != 1).
fn off_seam_for(angle: f64, eps: f64) -> (f64, bool) {
    if eps == 1.0 {
        (angle, false)
    } else {
        off_seam(angle)
    }
}

/// The query at parameters (eta, omega): `Err` where eta is not on the surface.
pub fn at_parameters(
    shape: &Shape,
    pose: &Pose,
    eta: f64,
    omega: f64,
) -> Result<SurfacePoint, String> {
    if !eta.is_finite() || !omega.is_finite() {
        return Err(format!("parameters must be finite, got ({eta}, {omega})"));
    }
    let eta_max = shape.eta_range();
    if shape.a4 < 1.0 && eta.abs() > eta_max + 1e-12 {
        return Err(format!(
            "eta {eta} is off the surface: without a through hole (a4 = {} < 1) eta lies in [-{eta_max}, {eta_max}]",
            shape.a4
        ));
    }
    Ok(canonical_query(shape, eta, omega).to_world(pose))
}

/// A canonical-frame answer before the pose is applied.
struct Canonical {
    eta: f64,
    omega: f64,
    point: DVec3,
    frame: PrincipalFrame,
    seam: bool,
}

impl Canonical {
    fn to_world(&self, pose: &Pose) -> SurfacePoint {
        let r = pose.rotation;
        SurfacePoint {
            eta: self.eta,
            omega: self.omega,
            point: pose.to_world(self.point).to_array(),
            normal: (r * self.frame.normal).to_array(),
            curvatures: self.frame.curvatures,
            directions: self.frame.directions.map(|d| (r * d).to_array()),
            seam: self.seam,
        }
    }
}

/// sin and cos with the rounding of pi/2's multiples undone, so that a point asked for
/// on a seam is exactly there (cos(pi/2) is 6e-17 in floating point, and its eps-th power
/// for small eps is not small).
fn exact_sin_cos(angle: f64) -> (f64, f64) {
    let (s, c) = angle.sin_cos();
    let snap = |v: f64| if v.abs() < 1e-14 { 0.0 } else { v };
    (snap(s), snap(c))
}

/// r_t(eta, omega) of eq. (2) with [`exact_sin_cos`].
pub fn surface_point(shape: &Shape, eta: f64, omega: f64) -> DVec3 {
    let (se, ce) = exact_sin_cos(eta);
    let (so, co) = exact_sin_cos(omega);
    let c = shape.a4 + signed_pow(ce, shape.eps1);
    DVec3::new(
        shape.a1 * c * signed_pow(co, shape.eps2),
        shape.a2 * c * signed_pow(so, shape.eps2),
        shape.a3 * signed_pow(se, shape.eps1),
    )
}

fn canonical_query(shape: &Shape, eta: f64, omega: f64) -> Canonical {
    // the point itself is exact at any parameters; only the derivatives move off a seam
    let point = surface_point(shape, eta, omega);
    let (mut eta_d, seam_eta) = off_seam_for(eta, shape.eps1);
    let (omega_d, seam_omega) = off_seam_for(omega, shape.eps2);
    let mut seam = seam_eta || seam_omega;
    let eta_max = shape.eta_range();
    if shape.a4 < 1.0 && eta_d.abs() > eta_max - SEAM_OFFSET {
        // the ends on the axis: r_omega vanishes there
        eta_d = eta_d.signum() * (eta_max - SEAM_OFFSET);
        seam = true;
    }
    let mut frame = principal_frame(&surface_jet(shape, eta_d, omega_d));
    if (seam || !frame.normal.is_finite())
        && let Some(n) = implicit_normal(shape, point)
    {
        // the seam's own normal where the surface has one (eps < 2): beside the seam
        // it turns as cos^(2 - eps), too slowly for an offset to stand in for it
        let d1 = frame.directions[0]
            .reject_from_normalized(n)
            .normalize_or(frame.directions[0]);
        frame.normal = n;
        frame.directions = [d1, n.cross(d1)];
    }
    Canonical {
        eta: eta_d,
        omega: omega_d,
        point,
        frame,
        seam,
    }
}

/// The unit outward normal as the gradient of the inside-outside function (eq. 3) at a
/// canonical surface point, its two superellipse factors each scaled to a largest
/// component of 1 (the direction is unchanged and no power under- or overflows). None
/// where it has no direction: on the axis, at a section centre, at a corner (eps >= 2).
pub fn implicit_normal(shape: &Shape, p: DVec3) -> Option<DVec3> {
    let factor = |u: f64, v: f64, eps: f64| -> Option<[f64; 2]> {
        let m = u.abs().max(v.abs());
        if m == 0.0 {
            return None;
        }
        let e = 2.0 / eps - 1.0;
        Some([signed_pow(u / m, e), signed_pow(v / m, e)])
    };
    // ∇G's direction in x-y (G is the top-view norm), then the section's (X, Z)
    let [gx, gy] = factor(p.x / shape.a1, p.y / shape.a2, shape.eps2)?;
    let (gx, gy) = (gx / shape.a1, gy / shape.a2);
    let g = shape.top_view_norm(p.x, p.y);
    let [cx, cz] = factor(g - shape.a4, p.z / shape.a3, shape.eps1)?;
    // ∂G/∂x = S^(eps2/2 - 1)·(scaled x factor)/a1 with S the scaled sum; put it back
    let (ux, uy) = (p.x / shape.a1, p.y / shape.a2);
    let m = ux.abs().max(uy.abs());
    let s = (ux / m).abs().powf(2.0 / shape.eps2) + (uy / m).abs().powf(2.0 / shape.eps2);
    let scale = s.powf(shape.eps2 / 2.0 - 1.0);
    let n = DVec3::new(cx * scale * gx, cx * scale * gy, cz / shape.a3);
    let n = n.normalize();
    n.is_finite().then_some(n)
}

/// An `n_eta` x `n_omega` grid at the cells' centres: omega around the hole axis, eta
/// round the section (a4 >= 1) or between the two axis points (otherwise).
pub fn grid(shape: &Shape, pose: &Pose, n_eta: usize, n_omega: usize) -> Vec<SurfacePoint> {
    let eta_max = shape.eta_range();
    let mut out = Vec::with_capacity(n_eta * n_omega);
    for i in 0..n_eta {
        let eta = -eta_max + 2.0 * eta_max * (i as f64 + 0.5) / n_eta as f64;
        for j in 0..n_omega {
            let omega = -PI + TAU * (j as f64 + 0.5) / n_omega as f64;
            out.push(canonical_query(shape, eta, omega).to_world(pose));
        }
    }
    out
}

/// The parameters (eta, omega) of a canonical point on the surface (inverse of eq. 2).
pub fn parameters_of(shape: &Shape, p: DVec3) -> (f64, f64) {
    let radius = shape.top_view_norm(p.x, p.y);
    let omega = if radius > 0.0 {
        signed_pow(p.y / shape.a2, 1.0 / shape.eps2)
            .atan2(signed_pow(p.x / shape.a1, 1.0 / shape.eps2))
    } else {
        0.0
    };
    let eta = signed_pow(p.z / shape.a3, 1.0 / shape.eps1)
        .atan2(signed_pow(radius - shape.a4, 1.0 / shape.eps1));
    (eta, omega)
}

/// The surface point nearest to a world point: Gauss-Newton steps in (eta, omega) on the
/// Euclidean distance, from its meridian projection (eq. 15's p_s) and from the nearest
/// node of a coarse grid, the closer kept: a foot point is only a local answer, small eps
/// make the parametrisation steep, and an apple's projection can land beyond its axis.
pub fn nearest(shape: &Shape, pose: &Pose, world: DVec3) -> Result<SurfacePoint, String> {
    if !world.is_finite() {
        return Err(format!("point must be finite, got {world:?}"));
    }
    let q = pose.to_canonical(world);
    let projected = meridian_distance(shape, q).surface_point;
    let (eta, omega) = parameters_of(shape, projected);
    let mut foot = descend(shape, q, clamp_eta(shape, eta), omega);
    // a foot point is only a local answer: the grid's nearest node seeds a second descent
    {
        let (n_eta, n_omega) = NEAREST_GRID;
        let eta_max = shape.eta_range();
        let mut start = (f64::INFINITY, 0.0, 0.0);
        for i in 0..n_eta {
            let e = -eta_max + 2.0 * eta_max * (i as f64 + 0.5) / n_eta as f64;
            for j in 0..n_omega {
                let o = -PI + TAU * (j as f64 + 0.5) / n_omega as f64;
                let d = (surface_point(shape, e, o) - q).length_squared();
                if d < start.0 {
                    start = (d, e, o);
                }
            }
        }
        let other = descend(shape, q, start.1, start.2);
        if other.distance_sq < foot.distance_sq {
            foot = other;
        }
    }
    Ok(canonical_query(shape, foot.eta, foot.omega).to_world(pose))
}

/// The coarse grid (eta x omega) [`nearest`] falls back on.
pub const NEAREST_GRID: (usize, usize) = (16, 32);

fn clamp_eta(shape: &Shape, eta: f64) -> f64 {
    if shape.a4 < 1.0 {
        let m = shape.eta_range();
        eta.clamp(-m, m)
    } else {
        eta
    }
}

struct Foot {
    eta: f64,
    omega: f64,
    distance_sq: f64,
}

fn descend(shape: &Shape, q: DVec3, mut eta: f64, mut omega: f64) -> Foot {
    let mut best = (surface_point(shape, eta, omega) - q).length_squared();
    let tolerance = 1e-9 * shape.size();
    for _ in 0..16 {
        let (e_d, _) = off_seam(eta);
        let (o_d, _) = off_seam(omega);
        let jet = surface_jet(shape, clamp_eta(shape, e_d), o_d);
        let r = surface_point(shape, eta, omega) - q;
        let (a, b) = (jet.r_eta, jet.r_omega);
        let normal = b.cross(a).normalize_or_zero();
        if (r - normal * r.dot(normal)).length() < tolerance || r.length() < tolerance {
            break;
        }
        // normal equations of [r_eta r_omega]·(d_eta, d_omega) = -r, lightly damped
        let (aa, ab, bb) = (a.dot(a), a.dot(b), b.dot(b));
        let damp = 1e-9 * (aa + bb);
        let (aa, bb) = (aa + damp, bb + damp);
        let det = aa * bb - ab * ab;
        if !(det.is_finite() && det > 0.0) {
            break;
        }
        let (ga, gb) = (-a.dot(r), -b.dot(r));
        let d_eta = (bb * ga - ab * gb) / det;
        let d_omega = (aa * gb - ab * ga) / det;
        let mut step = 1.0;
        let mut improved = false;
        while step > 1e-4 {
            let (e2, o2) = (clamp_eta(shape, eta + step * d_eta), omega + step * d_omega);
            let cost = (surface_point(shape, e2, o2) - q).length_squared();
            if cost.is_finite() && cost < best {
                (eta, omega, best) = (e2, o2, cost);
                improved = true;
                break;
            }
            step *= 0.5;
        }
        if !improved {
            break;
        }
    }
    Foot {
        eta,
        omega,
        distance_sq: best,
    }
}

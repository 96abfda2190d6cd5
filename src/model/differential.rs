//! Differential geometry of the supertoroid (paper §IV): coordinate-curve tangents
//! (eqs. 16-17), the unit normal (Gauss map, eq. 18) and the curvatures of eq. (19).
//! Valid in the open parameter quadrants (the seams cos = 0 or sin = 0 are singular for
//! eps != 1), extended to all quadrants by the signed-power symmetry.

use super::shape::{Shape, signed_pow};
use glam::DVec3;

/// d/dt [sign(c)|c|^e] = e·|c|^(e-1)·dc/dt.
fn dspow(c: f64, dc: f64, e: f64) -> f64 {
    e * c.abs().powf(e - 1.0) * dc
}

/// (t_omega, t_eta): non-unit tangents along the coordinate curves (eqs. 16, 17).
pub fn tangents(shape: &Shape, eta: f64, omega: f64) -> (DVec3, DVec3) {
    let Shape {
        a1,
        a2,
        a3,
        a4,
        eps1,
        eps2,
    } = *shape;
    let (se, ce) = eta.sin_cos();
    let (so, co) = omega.sin_cos();
    let radius = a4 + signed_pow(ce, eps1);
    let t_omega = DVec3::new(
        a1 * radius * dspow(co, -so, eps2),
        a2 * radius * dspow(so, co, eps2),
        0.0,
    );
    let d_radius = dspow(ce, -se, eps1);
    let t_eta = DVec3::new(
        a1 * d_radius * signed_pow(co, eps2),
        a2 * d_radius * signed_pow(so, eps2),
        a3 * dspow(se, ce, eps1),
    );
    (t_omega, t_eta)
}

/// Unit outward normal n_p = t_omega × t_eta / |·| (eq. 18: the paper's n_p is this
/// cross product with the common factor eps1·eps2 removed).
pub fn unit_normal(shape: &Shape, eta: f64, omega: f64) -> DVec3 {
    let (t_omega, t_eta) = tangents(shape, eta, omega);
    t_omega.cross(t_eta).normalize()
}

/// The curvatures of eq. (19): k_omega, k_eta. They are the curvatures of the (planar)
/// coordinate curves, which the paper uses as approximations of the principal
/// curvatures; `normal_omega`, `normal_eta` are the true normal curvatures along the same
/// directions, k·cos(angle between the curve's principal normal and the surface normal).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NormalCurvatures {
    pub k_omega: f64,
    pub k_eta: f64,
    pub normal_omega: f64,
    pub normal_eta: f64,
}

pub fn normal_curvatures(shape: &Shape, eta: f64, omega: f64) -> NormalCurvatures {
    let Shape {
        a1,
        a2,
        a3,
        a4,
        eps1,
        eps2,
    } = *shape;
    let (se, ce) = eta.sin_cos();
    let (so, co) = omega.sin_cos();
    let (ce, se, co, so) = (ce.abs(), se.abs(), co.abs(), so.abs());
    let radius = (a4 + signed_pow(eta.cos(), eps1)).abs();
    // eq. (19), k_omega
    let k_omega = a1 * a2 * (eps2 - 2.0).abs() * radius * radius * (co * so).powf(eps2 - 1.0)
        / (eps2
            * (radius
                * radius
                * co
                * co
                * so
                * so
                * (a1 * a1 * co.powf(2.0 * eps2 - 4.0) + a2 * a2 * so.powf(2.0 * eps2 - 4.0)))
            .powf(1.5));
    // eq. (19), k_eta, with a_omega^2 = a1^2 cos^(2eps2) + a2^2 sin^(2eps2) (eq. 13)
    let a_omega_sq = a1 * a1 * co.powf(2.0 * eps2) + a2 * a2 * so.powf(2.0 * eps2);
    let k_eta = a3 * (eps1 - 2.0).abs() * (ce * se).powf(eps1 - 1.0) * a_omega_sq.sqrt()
        / (eps1
            * (ce
                * ce
                * se
                * se
                * (a3 * a3 * se.powf(2.0 * eps1 - 4.0) + ce.powf(2.0 * eps1 - 4.0) * a_omega_sq))
                .powf(1.5));
    // Normal curvatures by the second fundamental form, II(t,t)/I(t,t), with second
    // derivatives by central differences of the analytic tangents.
    let n = unit_normal(shape, eta, omega);
    let h = 1e-6;
    let (t_o, t_e) = tangents(shape, eta, omega);
    let (t_o_plus, _) = tangents(shape, eta, omega + h);
    let (t_o_minus, _) = tangents(shape, eta, omega - h);
    let (_, t_e_plus) = tangents(shape, eta + h, omega);
    let (_, t_e_minus) = tangents(shape, eta - h, omega);
    let r_oo = (t_o_plus - t_o_minus) / (2.0 * h);
    let r_ee = (t_e_plus - t_e_minus) / (2.0 * h);
    NormalCurvatures {
        k_omega,
        k_eta,
        normal_omega: r_oo.dot(n) / t_o.length_squared(),
        normal_eta: r_ee.dot(n) / t_e.length_squared(),
    }
}

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

/// sign(u)|u|^e with its first two derivatives along a parameter, given u, u', u''.
/// d/dt = e|u|^(e-1)u', d²/dt² = e(e-1)|u|^(e-2)sign(u)u'^2 + e|u|^(e-1)u''.
fn spow_jet(u: f64, du: f64, ddu: f64, e: f64) -> [f64; 3] {
    let a = u.abs();
    let p1 = a.powf(e - 1.0);
    // the |u|^(e-2) term vanishes identically at e = 1 (and is 0·inf at u = 0)
    let bend = if e == 1.0 {
        0.0
    } else {
        e * (e - 1.0) * (p1 / a) * u.signum() * du * du
    };
    [u.signum() * a * p1, e * p1 * du, bend + e * p1 * ddu]
}

/// The surface r_t(eta, omega) of eq. (2) with its first and second partial derivatives,
/// in closed form (four powers per point). Finite wherever no cosine or sine of eta or
/// omega is zero (the seams; see [`crate::grasp::surface`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceJet {
    pub point: DVec3,
    /// ∂r/∂omega, ∂r/∂eta (eqs. 16, 17)
    pub r_omega: DVec3,
    pub r_eta: DVec3,
    pub r_omega_omega: DVec3,
    pub r_eta_eta: DVec3,
    pub r_eta_omega: DVec3,
}

pub fn surface_jet(shape: &Shape, eta: f64, omega: f64) -> SurfaceJet {
    let (se, ce) = eta.sin_cos();
    let (so, co) = omega.sin_cos();
    let [c_eta, dc_eta, ddc_eta] = spow_jet(ce, -se, -ce, shape.eps1);
    let [s_eta, ds_eta, dds_eta] = spow_jet(se, ce, -se, shape.eps1);
    let [c_om, dc_om, ddc_om] = spow_jet(co, -so, -co, shape.eps2);
    let [s_om, ds_om, dds_om] = spow_jet(so, co, -so, shape.eps2);
    let (a1, a2, a3) = (shape.a1, shape.a2, shape.a3);
    let radius = shape.a4 + c_eta;
    SurfaceJet {
        point: DVec3::new(a1 * radius * c_om, a2 * radius * s_om, a3 * s_eta),
        r_omega: DVec3::new(a1 * radius * dc_om, a2 * radius * ds_om, 0.0),
        r_eta: DVec3::new(a1 * dc_eta * c_om, a2 * dc_eta * s_om, a3 * ds_eta),
        r_omega_omega: DVec3::new(a1 * radius * ddc_om, a2 * radius * dds_om, 0.0),
        r_eta_eta: DVec3::new(a1 * ddc_eta * c_om, a2 * ddc_eta * s_om, a3 * dds_eta),
        r_eta_omega: DVec3::new(a1 * dc_eta * dc_om, a2 * dc_eta * ds_om, 0.0),
    }
}

/// The unit outward normal, the principal curvatures (k1 >= k2; positive where the
/// surface bends away from its outward normal, 1/R on a sphere of radius R) and their
/// unit directions, from the first and second fundamental forms of a jet: k solves
/// det(II - k·I) = 0.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PrincipalFrame {
    pub normal: DVec3,
    pub curvatures: [f64; 2],
    pub directions: [DVec3; 2],
}

pub fn principal_frame(jet: &SurfaceJet) -> PrincipalFrame {
    let (ro, re) = (jet.r_omega, jet.r_eta);
    let normal = ro.cross(re).normalize();
    let (e, f, g) = (ro.dot(ro), ro.dot(re), re.dot(re));
    // convex-positive: II with the inward normal
    let (l, m, n) = (
        -jet.r_omega_omega.dot(normal),
        -jet.r_eta_omega.dot(normal),
        -jet.r_eta_eta.dot(normal),
    );
    let det_i = e * g - f * f;
    let mean = (e * n + g * l - 2.0 * f * m) / (2.0 * det_i);
    let gauss = (l * n - m * m) / det_i;
    let spread = (mean * mean - gauss).max(0.0).sqrt();
    let k1 = mean + spread;
    // (du, dv) with (II - k1·I)(du, dv) = 0, from the better-conditioned row
    let row1 = (m - k1 * f, -(l - k1 * e));
    let row2 = (n - k1 * g, -(m - k1 * f));
    let pick = |r: (f64, f64)| r.0 * r.0 + r.1 * r.1;
    let (du, dv) = if pick(row1) >= pick(row2) { row1 } else { row2 };
    let d1 = (ro * du + re * dv).reject_from_normalized(normal);
    let d1 = if d1.length_squared() > 1e-300 && spread > 1e-12 * mean.abs().max(1e-300) {
        d1.normalize()
    } else {
        // umbilic: every direction is principal
        ro.normalize()
    };
    PrincipalFrame {
        normal,
        curvatures: [k1, mean - spread],
        directions: [d1, normal.cross(d1)],
    }
}

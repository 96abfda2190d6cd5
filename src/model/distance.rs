//! The meridian radial distance of paper §III.
//!
//! Two routes to the same number:
//! * [`meridian_distance_stepwise`] follows the paper step by step (omega_pi, the section
//!   angle omega_s, beta2 from the mean superellipse, the local section frame of eq. (14),
//!   beta1 from the section superellipse (12), p_s and eq. (15)). The paper writes
//!   tan^(1/eps2)(omega_s) = (a2/a1)·tan(omega_pi); the correct relation, used here, is
//!   tan^eps2(omega_s) = (a1/a2)·tan(omega_pi).
//! * [`meridian_distance`] is the closed form that the solver and the GPU kernels use.
//!   With rho = |p_xy|, G = (|x/a1|^(2/eps2) + |y/a2|^(2/eps2))^(eps2/2) (degree one in
//!   p_xy), s = rho/G (= a_omega_s, the section's size in this direction):
//!   beta2 = a4/G, R_pi = beta2·p_xy, the section offset is x' = s·(G - a4), the section
//!   inside-outside value equals F_t(p) (eq. 3), beta1 = F_t^(-eps1/2) = 1/N, and
//!   d = |p_R|·|1 - beta1| with |p_R| = L = sqrt(x'^2 + z^2).
//!   No trigonometry and no branch but the two guards below.
//!
//! Guards: on the z axis (rho = 0) the meridian plane is undefined; the x-z plane is
//! used (s = a1). At a section centre (p on the mean superellipse, L = N = 0) the ray is
//! undefined; the x' direction is used (the distance there is s). Both are the singular
//! sets of the distance: it is continuous but not differentiable across them.
//!
//! Apple shapes (0 < a4 < 1): a meridian ray from the section centre towards the axis can
//! cross the axis before it meets the section curve; p_s then lies on the section
//! superellipse's continuation beyond the axis, not on the implicit surface. The distance
//! is still the paper's and still finite.

use super::shape::{Shape, superellipse_norm};
use glam::DVec3;

/// Meridian radial distance of a canonical point, with the surface point it measures to.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeridianPoint {
    /// d = |p - p_s| (eq. 15), always >= 0.
    pub distance: f64,
    /// Signed version: > 0 outside (F_t > 1), < 0 inside. The solver's residual.
    pub signed: f64,
    /// p_s = beta2·p_pi + beta1·p_R, the surface point on the meridian ray.
    pub surface_point: DVec3,
    /// beta1 = F_t^(-eps1/2) (infinite at the section centre).
    pub beta1: f64,
    /// beta2 = a4/G (infinite on the z axis when a4 > 0).
    pub beta2: f64,
}

/// The meridian-plane quantities shared by the distance and its derivatives.
struct Meridian {
    /// unit direction of p_xy (x axis when p is on the z axis)
    dir: [f64; 2],
    /// s = rho / G = 1 / G(dir)
    s: f64,
    g: f64,
    /// section coordinates (G - a4, z/a3)
    big_x: f64,
    big_z: f64,
    /// N = F_t^(eps1/2)
    n: f64,
    /// L = |p_R| = sqrt((s·X)^2 + z^2)
    l: f64,
}

/// Signed residual L - L/N and the unit section direction (X, Z)/N it uses. L/N, the
/// section-centre-to-surface length along the ray, is |(s·X, a3·Z)|/N, taken in the x'
/// direction at the centre itself.
fn signed_residual(shape: &Shape, m: &Meridian) -> (f64, f64, f64) {
    let (ux, uz) = if m.n > 0.0 {
        (m.big_x / m.n, m.big_z / m.n)
    } else {
        (1.0, 0.0)
    };
    let reach = len2(m.s * ux, shape.a3 * uz);
    (m.l - reach, ux, uz)
}

/// sqrt(a^2 + b^2). libm's `hypot` guards against overflow at several times the cost;
/// the evaluators work on normalised clouds (RMS radius 1), far from overflow.
#[inline]
fn len2(a: f64, b: f64) -> f64 {
    (a * a + b * b).sqrt()
}

/// The meridian-plane quantities of a canonical point, given G(p) and a way to take the
/// section norm N(X, Z) (plain, or with its partials captured by the gradient).
fn meridian_with(
    shape: &Shape,
    p: DVec3,
    g_of_p: f64,
    section_norm: impl FnOnce(f64, f64) -> f64,
) -> Meridian {
    let rho = len2(p.x, p.y);
    let (dir, s, g) = if rho > 0.0 && g_of_p > 0.0 {
        ([p.x / rho, p.y / rho], rho / g_of_p, g_of_p)
    } else {
        // on the z axis: the x-z plane (see the module docs), s = 1/G(1, 0) = a1
        ([1.0, 0.0], shape.a1, 0.0)
    };
    let big_x = g - shape.a4;
    let big_z = p.z / shape.a3;
    let n = section_norm(big_x, big_z);
    Meridian {
        dir,
        s,
        g,
        big_x,
        big_z,
        n,
        l: len2(s * big_x, p.z),
    }
}

fn meridian(shape: &Shape, p: DVec3) -> Meridian {
    meridian_with(shape, p, shape.top_view_norm(p.x, p.y), |x, z| {
        superellipse_norm(x, z, shape.eps1)
    })
}

/// Closed-form meridian radial distance (see the module docs) of a point given in the
/// supertoroid's canonical frame. Valid for every a4 >= 0 (a4 = 0 gives the
/// superellipsoid radial distance |p|·|1 - F^(-eps1/2)|).
pub fn meridian_distance(shape: &Shape, p: DVec3) -> MeridianPoint {
    let m = meridian(shape, p);
    let (signed, ux, uz) = signed_residual(shape, &m);
    let centre = DVec3::new(shape.a4 * m.s * m.dir[0], shape.a4 * m.s * m.dir[1], 0.0);
    let section_dir = DVec3::new(m.s * ux * m.dir[0], m.s * ux * m.dir[1], shape.a3 * uz);
    MeridianPoint {
        distance: signed.abs(),
        signed,
        surface_point: centre + section_dir,
        beta1: 1.0 / m.n,
        beta2: if shape.a4 == 0.0 { 0.0 } else { shape.a4 / m.g },
    }
}

/// The paper's step-by-step construction (§III), kept as an independent check of the
/// closed form. Loses precision for eps below about 0.3 (large powers of tan).
pub fn meridian_distance_stepwise(shape: &Shape, p: DVec3) -> MeridianPoint {
    let Shape {
        a1,
        a2,
        a3,
        a4,
        eps1,
        eps2,
    } = *shape;
    let spow = super::shape::signed_pow;
    // Angle of the vertical projection plane (eq. 8).
    let omega_pi = if p.x == 0.0 && p.y == 0.0 {
        0.0
    } else {
        p.y.atan2(p.x)
    };
    // Section angle: tan^eps2(omega_s) = (a1/a2)·tan(omega_pi), quadrant-safe.
    let omega_s =
        spow(omega_pi.sin() / a2, 1.0 / eps2).atan2(spow(omega_pi.cos() / a1, 1.0 / eps2));
    let (cs, ss) = (spow(omega_s.cos(), eps2), spow(omega_s.sin(), eps2));
    // Size of the cross-section superellipse (eq. 13).
    let a_omega = (a1 * a1 * cs * cs + a2 * a2 * ss * ss).sqrt();
    // Major ratio from the mean superellipse's inside-outside function (eqs. 9-10).
    let p_pi = DVec3::new(p.x, p.y, 0.0);
    let beta2 = if a4 == 0.0 {
        0.0
    } else {
        let e = 2.0 / eps2;
        let f_m = (p.x / (a1 * a4)).abs().powf(e) + (p.y / (a2 * a4)).abs().powf(e);
        f_m.powf(-eps2 / 2.0)
    };
    let r_pi = beta2 * p_pi;
    // Local section coordinates (eq. 14).
    let x_local = (a1 * cs * (p.x - a1 * a4 * cs) + a2 * ss * (p.y - a2 * a4 * ss)) / a_omega;
    let z_local = p.z;
    // Minor ratio from the section superellipse (eqs. 12, 16).
    let e1 = 2.0 / eps1;
    let f_c = (x_local / a_omega).abs().powf(e1) + (z_local / a3).abs().powf(e1);
    let beta1 = f_c.powf(-eps1 / 2.0);
    let p_r = p - r_pi;
    let p_s = r_pi + beta1 * p_r;
    let distance = ((1.0 - beta1) * p_r).length();
    MeridianPoint {
        distance,
        signed: if f_c >= 1.0 { distance } else { -distance },
        surface_point: p_s,
        beta1,
        beta2,
    }
}

/// The signed meridian residual r (see [`MeridianPoint::signed`]) and its analytic
/// derivatives with respect to the canonical point and the six shape parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ResidualGradient {
    pub residual: f64,
    /// dr/dp, p in the canonical frame
    pub d_point: DVec3,
    /// dr/d(a1, a2, a3, a4, eps1, eps2)
    pub d_shape: [f64; 6],
}

/// A superellipse norm M = (|u|^(2/e) + |v|^(2/e))^(e/2) with its partial derivatives
/// (M, dM/du, dM/dv, dM/de), sharing one logarithm per component: with t_i = |u_i|/m
/// (m the larger component, for range), p_i = t_i^(2/e), S = p_u + p_v, M = m·S^(e/2),
/// weights w_i = p_i/S = (|u_i|/M)^(2/e):
/// dM/du_i = sign(u_i)·w_i·M/|u_i| (bounded for e <= 2) and
/// dM/de = -(M/e)·sum_i w_i·ln(|u_i|/M). Four transcendental calls instead of twelve.
#[inline]
fn norm_with_partials(u: f64, v: f64, e: f64) -> [f64; 4] {
    let (au, av) = (u.abs(), v.abs());
    let m = au.max(av);
    if m == 0.0 || !m.is_finite() {
        return [m, 0.0, 0.0, 0.0];
    }
    let k = 2.0 / e;
    // ln t and t^k of one component; the larger one has t = 1
    let part = |a: f64| {
        if a == m {
            (0.0, 1.0)
        } else if a == 0.0 {
            (f64::NEG_INFINITY, 0.0)
        } else {
            let ln_t = (a / m).ln();
            (ln_t, (k * ln_t).exp())
        }
    };
    let (ln_tu, pu) = part(au);
    let (ln_tv, pv) = part(av);
    let sum = pu + pv;
    let ln_s = sum.ln();
    let norm = m * (ln_s / k).exp();
    let (wu, wv) = (pu / sum, pv / sum);
    let d = |a: f64, c: f64, w: f64| {
        if a == 0.0 {
            0.0
        } else {
            c.signum() * w * norm / a
        }
    };
    // ln(|u_i|/M) = ln t_i - ln(S)/k; a zero component has weight zero
    let log_term = |w: f64, ln_t: f64| if w == 0.0 { 0.0 } else { w * (ln_t - ln_s / k) };
    [
        norm,
        d(au, u, wu),
        d(av, v, wv),
        -(norm / e) * (log_term(wu, ln_tu) + log_term(wv, ln_tv)),
    ]
}

/// Residual and gradient by the chain rule through r = L·(1 - 1/N),
/// L = |(s·X, z)|, N = N(X, z/a3; eps1), X = G - a4, s = rho/G, G = G(x, y; a1, a2, eps2).
/// Not differentiable on the z axis and at section centres (see the module docs): there
/// the derivatives returned are those of the guarded branch.
pub fn meridian_residual_with_gradient(shape: &Shape, p: DVec3) -> ResidualGradient {
    let Shape {
        a1,
        a2,
        a3,
        eps1,
        eps2,
        ..
    } = *shape;
    // G and N with their partials in one pass each (see `norm_with_partials`)
    let (ux, vy) = (p.x / a1, p.y / a2);
    let [g, g_u, g_v, g_e2] = norm_with_partials(ux, vy, eps2);
    let mut section = [0.0; 4];
    let m = meridian_with(shape, p, g, |x, z| {
        section = norm_with_partials(x, z, eps1);
        section[0]
    });
    let [_, n_x, n_z, n_e1] = section;
    let residual = signed_residual(shape, &m).0;
    // At (within 1e-12 of) a section centre the ray direction is undefined: no gradient.
    if m.n < 1e-12 || m.l == 0.0 {
        return ResidualGradient {
            residual,
            d_point: DVec3::ZERO,
            d_shape: [0.0; 6],
        };
    }
    // r as a function of L and N.
    let r_l = 1.0 - 1.0 / m.n;
    let r_n = m.l / (m.n * m.n);
    // L = sqrt((sX)^2 + z^2)
    let l_s = m.s * m.big_x * m.big_x / m.l;
    let l_x = m.s * m.s * m.big_x / m.l;
    let l_z = p.z / m.l;
    // G(x/a1, y/a2; eps2): derivatives with respect to its scaled arguments u = x/a1, v = y/a2.
    let (g_u, g_v, g_e2) = if m.g > 0.0 {
        (g_u, g_v, g_e2)
    } else {
        (0.0, 0.0, 0.0)
    };
    let (g_x, g_y) = (g_u / a1, g_v / a2);
    let (g_a1, g_a2) = (-g_u * ux / a1, -g_v * vy / a2);
    // s = rho / G; ds/dx = (x/rho - s·G_x)/G; ds/dtheta = -s·G_theta/G for shape params.
    // On (or within 1e-9 of) the z axis ds/dx ~ 1/G blows up: the meridian plane turns
    // with the point. Treat the plane as fixed there (the guarded branch).
    let (s_x, s_y) = if m.g > 1e-9 {
        ((m.dir[0] - m.s * g_x) / m.g, (m.dir[1] - m.s * g_y) / m.g)
    } else {
        (0.0, 0.0)
    };
    let s_of = |g_theta: f64| if m.g > 0.0 { -m.s * g_theta / m.g } else { 0.0 };
    // Through G (which moves X, and s) and the section norm.
    let via_g =
        |g_theta: f64, s_theta: f64| r_l * (l_s * s_theta + l_x * g_theta) + r_n * n_x * g_theta;
    let d_point = DVec3::new(via_g(g_x, s_x), via_g(g_y, s_y), r_l * l_z + r_n * n_z / a3);
    let d_shape = [
        via_g(g_a1, s_of(g_a1)),
        via_g(g_a2, s_of(g_a2)),
        r_n * n_z * (-m.big_z / a3),
        -(r_l * l_x + r_n * n_x),
        r_n * n_e1,
        via_g(g_e2, s_of(g_e2)),
    ];
    ResidualGradient {
        residual,
        d_point,
        d_shape,
    }
}

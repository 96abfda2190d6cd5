//! The surface model of paper §II-IV against exact results and against itself.

use glam::{DQuat, DVec3};
use proptest::prelude::*;
use rand::Rng;
use supertoroid::model::*;
use supertoroid::synth;

const EPS_GRID: [f64; 6] = [0.1, 0.3, 0.6, 1.0, 1.5, 2.0];
const A4_GRID: [f64; 4] = [0.0, 0.5, 1.5, 3.0];

fn random_shape(rng: &mut impl Rng, eps_min: f64) -> Shape {
    Shape::new(
        rng.random_range(0.5..2.0),
        rng.random_range(0.5..2.0),
        rng.random_range(0.3..1.5),
        if rng.random_bool(0.15) {
            0.0
        } else {
            rng.random_range(0.2..3.0)
        },
        rng.random_range(eps_min..2.0),
        rng.random_range(eps_min..2.0),
    )
}

fn random_rotation(rng: &mut impl Rng) -> DQuat {
    let axis = DVec3::new(
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
    )
    .normalize_or(DVec3::X);
    DQuat::from_axis_angle(axis, rng.random_range(-3.1..3.1))
}

#[test]
fn parametric_points_satisfy_the_implicit_equation() {
    let mut worst: f64 = 0.0;
    for &e1 in &EPS_GRID {
        for &e2 in &EPS_GRID {
            for &a4 in &A4_GRID {
                let shape = Shape::new(1.3, 0.7, 0.9, a4, e1, e2);
                let eta_max = shape.eta_range();
                for i in 0..=24 {
                    for j in 0..24 {
                        let eta = -eta_max + 2.0 * eta_max * i as f64 / 24.0;
                        let omega = std::f64::consts::TAU * j as f64 / 24.0 + 0.01;
                        let f = shape.inside_outside(shape.surface_point(eta, omega));
                        worst = worst.max((f - 1.0).abs());
                    }
                }
            }
        }
    }
    assert!(
        worst < 1e-9,
        "max |F_t - 1| on parametric samples = {worst:e}"
    );
}

#[test]
fn eta_range_is_where_the_parametrisation_stays_on_the_surface() {
    // Just beyond the range the parametric point folds through the axis and leaves F_t = 1.
    let shape = Shape::new(1.0, 1.0, 1.0, 0.5, 1.0, 1.0);
    let beyond = shape.eta_range() + 0.3;
    assert!((shape.inside_outside(shape.surface_point(beyond, 0.4)) - 1.0).abs() > 1e-3);
    assert_eq!(
        Shape::new(1.0, 1.0, 1.0, 0.0, 0.7, 1.0).eta_range(),
        std::f64::consts::FRAC_PI_2
    );
}

#[test]
fn distance_is_zero_on_the_surface_and_delta_along_the_meridian_ray() {
    let mut rng = synth::rng(11);
    for _ in 0..300 {
        let shape = random_shape(&mut rng, 0.2);
        let eta_max = shape.eta_range() * 0.98;
        let p = shape.surface_point(
            rng.random_range(-eta_max..eta_max),
            rng.random_range(-3.1..3.1),
        );
        let on = meridian_distance(&shape, p);
        assert!(
            on.distance < 1e-9 * shape.size(),
            "d on surface = {:e} for {shape:?}",
            on.distance
        );
        assert!((on.surface_point - p).length() < 1e-9 * shape.size());
        // The meridian ray: from the section centre R_pi through p.
        let rho = p.x.hypot(p.y);
        if rho < 1e-3 {
            continue;
        }
        let centre = DVec3::new(p.x, p.y, 0.0) * (shape.a4 / shape.top_view_norm(p.x, p.y));
        let ray = p - centre;
        let reach = ray.length();
        let dir = ray / reach;
        for frac in [-0.5, -0.1, 0.05, 0.4, 1.0] {
            let delta = frac * reach;
            let q = p + delta * dir;
            // stay in the same meridian half-plane
            if DVec3::new(q.x, q.y, 0.0).dot(DVec3::new(p.x, p.y, 0.0)) <= 0.0 {
                continue;
            }
            let d = meridian_distance(&shape, q).distance;
            assert!(
                (d - delta.abs()).abs() < 1e-9 * shape.size(),
                "moved {delta}, got {d} ({shape:?})"
            );
        }
    }
}

#[test]
fn circular_torus_distance_is_the_euclidean_distance() {
    let mut rng = synth::rng(5);
    for _ in 0..500 {
        let a = rng.random_range(0.2..2.0);
        let a4 = rng.random_range(1.0..4.0);
        let shape = Shape::new(a, a, a, a4, 1.0, 1.0);
        let p = DVec3::new(
            rng.random_range(-6.0..6.0),
            rng.random_range(-6.0..6.0),
            rng.random_range(-3.0..3.0),
        ) * a;
        let rho = p.x.hypot(p.y);
        let exact = (((rho - a * a4).powi(2) + p.z * p.z).sqrt() - a).abs();
        let d = meridian_distance(&shape, p).distance;
        assert!((d - exact).abs() < 1e-10 * a, "{d} vs {exact} at {p}");
    }
}

#[test]
fn superellipsoid_distance_is_the_radial_distance() {
    let mut rng = synth::rng(6);
    for _ in 0..500 {
        let mut shape = random_shape(&mut rng, 0.1);
        shape.a4 = 0.0;
        let p = DVec3::new(
            rng.random_range(-3.0..3.0),
            rng.random_range(-3.0..3.0),
            rng.random_range(-3.0..3.0),
        );
        let f = shape.inside_outside(p);
        let radial = p.length() * (1.0 - f.powf(-shape.eps1 / 2.0)).abs();
        let d = meridian_distance(&shape, p).distance;
        assert!(
            (d - radial).abs() <= 1e-9 * (1.0 + radial),
            "{d} vs {radial} for {shape:?} at {p}"
        );
    }
}

#[test]
fn stepwise_construction_agrees_with_the_closed_form() {
    let mut rng = synth::rng(7);
    let mut worst: f64 = 0.0;
    for _ in 0..2000 {
        let shape = random_shape(&mut rng, 0.3);
        let p = DVec3::new(
            rng.random_range(-5.0..5.0),
            rng.random_range(-5.0..5.0),
            rng.random_range(-2.0..2.0),
        );
        let closed = meridian_distance(&shape, p);
        let steps = meridian_distance_stepwise(&shape, p);
        let rel = (closed.distance - steps.distance).abs() / closed.distance.max(1e-3);
        let rel_ps = (closed.surface_point - steps.surface_point).length() / shape.size();
        worst = worst.max(rel).max(rel_ps);
        assert!(
            rel < 1e-9 && rel_ps < 1e-9,
            "closed {closed:?} vs stepwise {steps:?} for {shape:?} at {p}"
        );
        assert!((closed.beta1 - steps.beta1).abs() <= 1e-9 * closed.beta1.abs().max(1.0));
        if shape.a4 > 0.0 {
            assert!((closed.beta2 - steps.beta2).abs() <= 1e-9 * closed.beta2.abs().max(1.0));
        }
    }
    eprintln!("worst relative disagreement {worst:e}");
}

#[test]
fn distance_is_pose_invariant() {
    let mut rng = synth::rng(8);
    for _ in 0..500 {
        let shape = random_shape(&mut rng, 0.1);
        let pose = Pose::new(
            random_rotation(&mut rng),
            DVec3::new(rng.random_range(-9.0..9.0), 3.0, -2.0),
        );
        let p = DVec3::new(
            rng.random_range(-4.0..4.0),
            rng.random_range(-4.0..4.0),
            rng.random_range(-2.0..2.0),
        );
        let world = pose.to_world(p);
        let d_world = meridian_distance(&shape, pose.to_canonical(world)).distance;
        let d = meridian_distance(&shape, p).distance;
        assert!((d_world - d).abs() < 1e-9 * (1.0 + d));
    }
}

#[test]
fn finite_near_the_axis_and_at_section_centres() {
    for a4 in [0.0, 0.5, 1.0, 2.5] {
        let shape = Shape::new(1.0, 0.6, 0.8, a4, 0.4, 1.7);
        for p in [
            DVec3::ZERO,
            DVec3::new(0.0, 0.0, 0.3),
            DVec3::new(1e-300, 0.0, 0.0),
            DVec3::new(1e-12, -1e-12, 0.2),
            DVec3::new(a4, 0.0, 0.0),       // section centre on the x axis
            DVec3::new(0.0, 0.6 * a4, 0.0), // section centre on the y axis
            DVec3::new(a4 + 1e-13, 0.0, 1e-13), // next to it
        ] {
            let m = meridian_distance(&shape, p);
            assert!(
                m.distance.is_finite() && m.distance >= 0.0,
                "{m:?} at {p}, a4 = {a4}"
            );
            assert!(m.surface_point.is_finite(), "{m:?} at {p}, a4 = {a4}");
            // For apple shapes (a4 < 1) a ray that crosses the axis ends on the section
            // curve's continuation, not on the implicit surface (see model::distance).
            let crosses_axis =
                a4 < 1.0 && m.surface_point.x * p.x.max(1e-300) + m.surface_point.y * p.y < 0.0;
            if !crosses_axis {
                assert!(
                    (shape.inside_outside(m.surface_point) - 1.0).abs() < 1e-9,
                    "{m:?} at {p}, a4 = {a4}"
                );
            }
            let g = meridian_residual_with_gradient(&shape, p);
            assert!(
                g.residual.is_finite()
                    && g.d_point.is_finite()
                    && g.d_shape.iter().all(|x| x.is_finite()),
                "{g:?} at {p}, a4 = {a4}"
            );
        }
    }
}

#[test]
fn analytic_gradient_matches_central_differences() {
    let mut rng = synth::rng(9);
    let mut checked = 0;
    for _ in 0..400 {
        let shape = random_shape(&mut rng, 0.3);
        let p = DVec3::new(
            rng.random_range(-4.0..4.0),
            rng.random_range(-4.0..4.0),
            rng.random_range(-1.5..1.5),
        );
        let m = meridian_distance(&shape, p);
        // away from the singular sets (axis, section centre) where r is not differentiable
        if p.x.hypot(p.y) < 0.05 || m.beta1 > 20.0 {
            continue;
        }
        let g = meridian_residual_with_gradient(&shape, p);
        let r = |s: &Shape, q: DVec3| meridian_distance(s, q).signed;
        let h = 1e-6;
        for k in 0..3 {
            let mut e = DVec3::ZERO;
            e[k] = h;
            let fd = (r(&shape, p + e) - r(&shape, p - e)) / (2.0 * h);
            assert!(
                (fd - g.d_point[k]).abs() < 1e-5 * (1.0 + fd.abs()),
                "d/dp{k}: {} vs fd {fd}",
                g.d_point[k]
            );
        }
        for k in 0..6 {
            let (mut plus, mut minus) = (shape.to_array(), shape.to_array());
            plus[k] += h;
            minus[k] -= h;
            let fd = (r(&Shape::from_array(plus), p) - r(&Shape::from_array(minus), p)) / (2.0 * h);
            assert!(
                (fd - g.d_shape[k]).abs() < 1e-5 * (1.0 + fd.abs()),
                "d/dshape{k}: {} vs fd {fd} for {shape:?} at {p}",
                g.d_shape[k]
            );
        }
        checked += 1;
    }
    assert!(checked > 200);
}

#[test]
fn normals_are_orthogonal_to_tangents_and_parallel_to_the_gradient() {
    let mut rng = synth::rng(10);
    for _ in 0..300 {
        let shape = Shape::new(
            rng.random_range(0.5..2.0),
            rng.random_range(0.5..2.0),
            rng.random_range(0.3..1.5),
            rng.random_range(1.1..3.0),
            rng.random_range(0.3..1.9),
            rng.random_range(0.3..1.9),
        );
        // interior of a random quadrant, away from the seams
        let quadrant = |rng: &mut synth::SeededRng| {
            let q = rng.random_range(0..4) as f64 * std::f64::consts::FRAC_PI_2;
            q + rng.random_range(0.15..1.42)
        };
        let (eta, omega) = (
            quadrant(&mut rng) - std::f64::consts::PI,
            quadrant(&mut rng),
        );
        let (t_o, t_e) = tangents(&shape, eta, omega);
        let n = unit_normal(&shape, eta, omega);
        assert!((n.length() - 1.0).abs() < 1e-12);
        assert!(n.dot(t_o).abs() < 1e-9 * t_o.length() && n.dot(t_e).abs() < 1e-9 * t_e.length());
        let p = shape.surface_point(eta, omega);
        let h = 1e-6;
        let grad = DVec3::new(
            shape.inside_outside(p + DVec3::X * h) - shape.inside_outside(p - DVec3::X * h),
            shape.inside_outside(p + DVec3::Y * h) - shape.inside_outside(p - DVec3::Y * h),
            shape.inside_outside(p + DVec3::Z * h) - shape.inside_outside(p - DVec3::Z * h),
        )
        .normalize();
        assert!(
            grad.dot(n) > 1.0 - 1e-6,
            "normal {n} vs gradient {grad} for {shape:?} at ({eta}, {omega})"
        );
    }
}

#[test]
fn curvatures_of_eq19_are_the_curvatures_of_the_coordinate_curves() {
    // Curvature of a space curve |r' x r''| / |r'|^3, by finite differences of the
    // parametric surface, against the paper's closed forms; and the normal curvatures
    // (second fundamental form) never exceed them in magnitude.
    let shapes = [
        Shape::new(1.0, 0.7, 0.5, 2.0, 0.6, 1.4),
        Shape::new(0.8, 1.2, 0.4, 1.5, 1.3, 0.5),
    ];
    for shape in shapes {
        for (eta, omega) in [(0.3, 0.4), (1.1, 0.9), (0.7, 1.3)] {
            let h = 1e-4;
            let curve = |f: &dyn Fn(f64) -> DVec3| {
                let (a, b, c) = (f(-h), f(0.0), f(h));
                let d1 = (c - a) / (2.0 * h);
                let d2 = (c - 2.0 * b + a) / (h * h);
                d1.cross(d2).length() / d1.length().powi(3)
            };
            let k_omega = curve(&|dt| shape.surface_point(eta, omega + dt));
            let k_eta = curve(&|dt| shape.surface_point(eta + dt, omega));
            let k = normal_curvatures(&shape, eta, omega);
            assert!(
                (k.k_omega - k_omega).abs() < 1e-4 * k_omega.max(1.0),
                "k_omega {} vs {k_omega}",
                k.k_omega
            );
            assert!(
                (k.k_eta - k_eta).abs() < 1e-4 * k_eta.max(1.0),
                "k_eta {} vs {k_eta}",
                k.k_eta
            );
            assert!(k.normal_omega.abs() <= k.k_omega * (1.0 + 1e-4));
            assert!(k.normal_eta.abs() <= k.k_eta * (1.0 + 1e-4));
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, ..ProptestConfig::default() })]
    #[test]
    fn distance_is_finite_and_projects_onto_the_surface(
        a1 in 0.05f64..3.0, a2 in 0.05f64..3.0, a3 in 0.05f64..3.0, a4 in 0.0f64..4.0,
        e1 in 0.1f64..2.0, e2 in 0.1f64..2.0,
        x in -10.0f64..10.0, y in -10.0f64..10.0, z in -10.0f64..10.0,
    ) {
        let shape = Shape::new(a1, a2, a3, a4, e1, e2);
        let m = meridian_distance(&shape, DVec3::new(x, y, z));
        prop_assert!(m.distance.is_finite() && m.distance >= 0.0);
        prop_assert!(m.surface_point.is_finite());
        // Apple shapes (a4 < 1): a ray that crosses the axis ends on the section curve's
        // continuation beyond it, not on the implicit surface (see `model::distance`).
        let dir = if x == 0.0 && y == 0.0 { (1.0, 0.0) } else { (x, y) };
        let crosses_axis = m.surface_point.x * dir.0 + m.surface_point.y * dir.1 < 0.0;
        if !(a4 < 1.0 && crosses_axis) {
            let f = shape.inside_outside(m.surface_point);
            prop_assert!((f - 1.0).abs() < 1e-8, "F_t(p_s) = {}", f);
        }
    }
}

//! Surface queries and grasps (paper §IV) against exact geometry and against the
//! surface they are planned on.

use glam::{DQuat, DVec3};
use supertoroid::grasp::{self, GraspKind, GraspRequest, Gripper, surface};
use supertoroid::model::*;

const SHAPES: [Shape; 6] = [
    Shape::new(0.015, 0.015, 0.008, 2.5, 1.0, 1.0), // a ring (tape, bearing)
    Shape::new(0.03, 0.02, 0.01, 3.0, 0.3, 0.6),    // a squarish oval ring
    Shape::new(0.012, 0.012, 0.05, 2.0, 0.2, 1.0),  // a tall tube
    Shape::new(0.03, 0.02, 0.03, 0.0, 0.5, 0.2),    // a box
    Shape::new(0.03, 0.03, 0.05, 0.0, 0.1, 1.0),    // a can
    Shape::new(0.03, 0.03, 0.03, 0.5, 1.0, 1.0),    // an apple
];

fn pose() -> Pose {
    Pose::new(
        DQuat::from_axis_angle(DVec3::new(1.0, 0.3, -0.2).normalize(), 0.7),
        DVec3::new(0.1, -0.05, 0.6),
    )
}

#[test]
fn the_jet_matches_finite_differences_of_the_surface() {
    let shape = Shape::new(1.0, 0.7, 0.5, 2.0, 0.6, 1.4);
    let h = 1e-5;
    for (eta, omega) in [(0.3, 0.4), (2.0, -1.1), (-0.7, 2.9), (-2.6, -0.2)] {
        let jet = surface_jet(&shape, eta, omega);
        let r = |e: f64, o: f64| shape.surface_point(e, o);
        let d_o = (r(eta, omega + h) - r(eta, omega - h)) / (2.0 * h);
        let d_e = (r(eta + h, omega) - r(eta - h, omega)) / (2.0 * h);
        let dd_o = (r(eta, omega + h) - 2.0 * r(eta, omega) + r(eta, omega - h)) / (h * h);
        let dd_e = (r(eta + h, omega) - 2.0 * r(eta, omega) + r(eta - h, omega)) / (h * h);
        let tangents_e = tangents(&shape, eta, omega).1;
        assert!((jet.point - r(eta, omega)).length() < 1e-14);
        assert!(
            (jet.r_omega - d_o).length() < 1e-8,
            "{:?} {:?}",
            jet.r_omega,
            d_o
        );
        assert!((jet.r_eta - d_e).length() < 1e-8);
        assert!((jet.r_eta - tangents_e).length() < 1e-12);
        assert!(
            (jet.r_omega_omega - dd_o).length() < 1e-3,
            "{:?} {dd_o:?}",
            jet.r_omega_omega
        );
        assert!((jet.r_eta_eta - dd_e).length() < 1e-3);
        let mixed = ((r(eta + h, omega + h) - r(eta + h, omega - h))
            - (r(eta - h, omega + h) - r(eta - h, omega - h)))
            / (4.0 * h * h);
        assert!((jet.r_eta_omega - mixed).length() < 1e-3);
    }
}

#[test]
fn principal_curvatures_of_a_sphere_and_a_torus_are_exact() {
    let sphere = Shape::new(2.0, 2.0, 2.0, 0.0, 1.0, 1.0);
    for p in surface::grid(&sphere, &Pose::IDENTITY, 7, 9) {
        for k in p.curvatures {
            // an umbilic: the two roots split by the rounding of sqrt(H^2 - K)
            assert!((k - 0.5).abs() < 1e-7, "sphere curvature {k}");
        }
        let n = DVec3::from_array(p.normal);
        assert!((n - DVec3::from_array(p.point) / 2.0).length() < 1e-9);
    }
    // torus: tube radius r = a, centre radius R = a4·a; k_tube = 1/r,
    // k_around = cos(eta)/(R + r cos(eta))
    let (r, big_r) = (1.0, 3.0);
    let torus = Shape::new(r, r, r, big_r / r, 1.0, 1.0);
    for p in surface::grid(&torus, &Pose::IDENTITY, 11, 5) {
        let c = p.eta.cos();
        let mut expected = [1.0 / r, c / (big_r + r * c)];
        expected.sort_by(|a, b| b.total_cmp(a));
        for (k, e) in p.curvatures.iter().zip(expected) {
            assert!(
                (k - e).abs() < 1e-9,
                "torus at eta {}: {:?} vs {expected:?}",
                p.eta,
                p.curvatures
            );
        }
        // the principal directions are tangent and orthonormal
        let n = DVec3::from_array(p.normal);
        let [d1, d2] = p.directions.map(DVec3::from_array);
        assert!(d1.dot(n).abs() < 1e-9 && d2.dot(n).abs() < 1e-9 && d1.dot(d2).abs() < 1e-9);
    }
}

#[test]
fn normals_follow_the_implicit_gradient_and_every_answer_is_finite() {
    let pose = pose();
    for shape in SHAPES.iter().copied().chain([
        Shape::new(1.0, 1.0, 1.0, 2.0, 2.0, 2.0),
        Shape::new(1.0, 2.0, 1.0, 0.0, 4.0, 0.1),
    ]) {
        let mut seams = 0;
        // 8 x 16 puts parameters exactly on the seams (multiples of pi/2 offset by the cells)
        for n in [(8, 16), (7, 13)] {
            for p in surface::grid(&shape, &pose, n.0, n.1) {
                let all = p.point.iter().chain(&p.normal).chain(&p.curvatures);
                assert!(all.clone().all(|v| v.is_finite()), "{shape:?}: {p:?}");
                seams += p.seam as usize;
                // outward: the inside-outside function grows along the normal
                let q = pose.to_canonical(DVec3::from_array(p.point));
                let n = pose.rotation.inverse() * DVec3::from_array(p.normal);
                let step = 1e-4 * shape.size();
                let (out, inn) = (
                    shape.inside_outside(q + n * step),
                    shape.inside_outside(q - n * step),
                );
                assert!(
                    out > inn || p.seam,
                    "{shape:?} at {:?}: not outward",
                    (p.eta, p.omega)
                );
            }
        }
        let _ = seams;
    }
    // exactly on a seam: moved beside it and said so
    let p = surface::at_parameters(&SHAPES[1], &pose, 0.0, 0.0).unwrap();
    assert!(p.seam && p.normal.iter().all(|v| v.is_finite()));
    assert!((p.eta - surface::SEAM_OFFSET).abs() < 1e-15);
}

#[test]
fn parameters_off_the_surface_are_refused() {
    let apple = SHAPES[5];
    let max = apple.eta_range();
    assert!(surface::at_parameters(&apple, &Pose::IDENTITY, max * 0.99, 0.3).is_ok());
    let err = surface::at_parameters(&apple, &Pose::IDENTITY, max + 0.1, 0.3).unwrap_err();
    assert!(err.contains("off the surface"), "{err}");
    assert!(surface::at_parameters(&apple, &Pose::IDENTITY, f64::NAN, 0.3).is_err());
}

#[test]
fn nearest_points_lie_on_the_surface_and_are_no_farther_than_any_point_of_a_dense_grid() {
    let pose = pose();
    let mut rng = supertoroid::synth::rng(7);
    use rand::Rng;
    for shape in SHAPES {
        let dense = dense_surface(&shape, &pose);
        for _ in 0..50 {
            let q = DVec3::new(
                rng.random_range(-1.5..1.5),
                rng.random_range(-1.5..1.5),
                rng.random_range(-1.5..1.5),
            ) * shape.half_extents();
            let world = pose.to_world(q);
            let near = surface::nearest(&shape, &pose, world).unwrap();
            let on = pose.to_canonical(DVec3::from_array(near.point));
            let residual = meridian_distance(&shape, on).distance;
            assert!(
                residual < 1e-9 * shape.size(),
                "{shape:?}: off the surface by {residual}"
            );
            let d_near = world.distance(DVec3::from_array(near.point));
            let d_grid = dense
                .iter()
                .map(|p| p.distance(world))
                .fold(f64::INFINITY, f64::min);
            assert!(
                d_near <= d_grid + 1e-6 * shape.size(),
                "{shape:?}: {d_near} > {d_grid}"
            );
        }
    }
    // on a sphere the nearest point is the radial one
    let sphere = Shape::new(1.0, 1.0, 1.0, 0.0, 1.0, 1.0);
    let near = surface::nearest(&sphere, &Pose::IDENTITY, DVec3::new(1.0, 2.0, 2.0)).unwrap();
    assert!((DVec3::from_array(near.point) - DVec3::new(1.0, 2.0, 2.0) / 3.0).length() < 1e-9);
}

fn request(shape: Shape, pose: Pose) -> GraspRequest {
    GraspRequest {
        shape,
        pose,
        gripper: Gripper::FRANKA_LIKE,
        friction: 0.5,
        plane: None,
        viewpoint: None,
        max_grasps: 1000,
    }
}

/// Points of the surface far denser than the planner's own collision samples.
fn dense_surface(shape: &Shape, pose: &Pose) -> Vec<DVec3> {
    surface::grid(shape, pose, 96, 192)
        .iter()
        .map(|p| DVec3::from_array(p.point))
        .collect()
}

#[test]
fn every_grasp_is_on_the_surface_antipodal_within_the_opening_and_collision_free() {
    let pose = pose();
    let gripper = Gripper::FRANKA_LIKE;
    let cone = 1.0 / (1.0f64 + 0.25).sqrt();
    for shape in SHAPES {
        let plan = grasp::plan::plan(&request(shape, pose)).unwrap();
        assert!(
            !plan.grasps.is_empty(),
            "{shape:?}: no grasp of {}",
            plan.candidates
        );
        let dense = dense_surface(&shape, &pose);
        for g in &plan.grasps {
            let closing = DVec3::from_array(g.closing);
            for (i, side) in [-1.0, 1.0].into_iter().enumerate() {
                let c = pose.to_canonical(DVec3::from_array(g.contacts[i]));
                let d = meridian_distance(&shape, c).distance;
                assert!(d < 1e-6 * shape.size(), "contact off the surface by {d}");
                let n = DVec3::from_array(g.normals[i]);
                assert!(
                    n.dot(closing * side) >= cone - 1e-12,
                    "{:?}: outside the cone",
                    g.kind
                );
            }
            assert!(g.width <= gripper.max_opening && g.width >= gripper.min_opening);
            let frame = grasp::gripper::GraspFrame {
                position: DVec3::from_array(g.position),
                approach: DVec3::from_array(g.approach),
                closing,
                binormal: DVec3::from_array(g.binormal),
            };
            let boxes = grasp::gripper::hand_boxes(&gripper, g.pregrasp_opening, g.tip_reach, 0.0);
            let hit = dense
                .iter()
                .any(|&s| boxes.iter().any(|b| b.contains(frame.local(s))));
            assert!(!hit, "{shape:?} {:?}: a finger meets the surface", g.kind);
            assert!(g.score >= 0.0 && g.score <= 1.0);
            assert!(g.depth <= gripper.finger_depth);
        }
        for w in plan.grasps.windows(2) {
            assert!(w[0].score >= w[1].score);
        }
        // deterministic
        assert_eq!(plan, grasp::plan::plan(&request(shape, pose)).unwrap());
    }
}

#[test]
fn a_ring_on_a_table_seen_from_above_is_grasped_from_above_or_the_side_never_through_the_table() {
    // a ring lying flat on the table z = 0, hole up, the camera above and to the side
    let shape = SHAPES[0];
    let pose = Pose::new(DQuat::IDENTITY, DVec3::new(0.0, 0.0, shape.a3));
    let plane = Plane::through(DVec3::ZERO, DVec3::Z);
    let camera = DVec3::new(0.0, -0.4, 0.5);
    let mut r = request(shape, pose);
    r.plane = Some(plane);
    r.viewpoint = Some(camera);
    let plan = grasp::plan::plan(&r).unwrap();
    assert!(
        plan.rejected.plane > 0 && plan.rejected.behind > 0,
        "{:?}",
        plan.rejected
    );
    let best = &plan.grasps[0];
    // the pinch across the section from above, one finger in the hole (the section is
    // thinner in height, but the bottom finger would go through the table)
    assert_eq!(best.kind, GraspKind::SectionWidth, "{best:?}");
    for g in &plan.grasps {
        let frame = grasp::gripper::GraspFrame {
            position: DVec3::from_array(g.position),
            approach: DVec3::from_array(g.approach),
            closing: DVec3::from_array(g.closing),
            binormal: DVec3::from_array(g.binormal),
        };
        for b in grasp::gripper::hand_boxes(&r.gripper, g.pregrasp_opening, g.tip_reach, 0.0) {
            for c in b.corners() {
                assert!(plane.signed_distance(frame.world(c)) >= 0.0);
            }
        }
        let towards = (camera - frame.position).normalize();
        assert!(frame.approach.dot(towards) <= grasp::plan::BEHIND_COSINE);
    }
    // the pinch from top to bottom needs a finger below the ring: only without the table
    assert!(
        plan.grasps
            .iter()
            .all(|g| g.kind != GraspKind::SectionHeight)
    );
    let free = grasp::plan::plan(&request(shape, pose)).unwrap();
    assert!(
        free.grasps
            .iter()
            .any(|g| g.kind == GraspKind::SectionHeight)
    );
}

#[test]
fn a_box_is_grasped_across_its_principal_axes() {
    let shape = SHAPES[3];
    let plan = grasp::plan::plan(&request(shape, Pose::IDENTITY)).unwrap();
    let kinds: Vec<_> = plan.grasps.iter().map(|g| g.kind).collect();
    assert!(kinds.contains(&GraspKind::AcrossBody) && kinds.contains(&GraspKind::AlongAxis));
    // the best is across the thinnest side (a2 = 2 cm: width 4 cm)
    let best = &plan.grasps[0];
    assert!((best.width - 0.04).abs() < 1e-9, "{best:?}");
    assert!(DVec3::from_array(best.closing).dot(DVec3::Y).abs() > 1.0 - 1e-9);
    // a box wider than the opening in every direction has no grasp, and says why
    let big = Shape::new(0.1, 0.1, 0.1, 0.0, 0.5, 0.5);
    let none = grasp::plan::plan(&request(big, Pose::IDENTITY)).unwrap();
    assert!(none.grasps.is_empty() && none.rejected.opening == none.candidates);
}

#[test]
fn a_ring_with_a_pinched_section_is_grasped_across_its_faces_not_its_tips() {
    // rings whose section is nearly a diamond (eps1 = 1.8): at the section's top, bottom
    // and sides the normal turns within a pad's reach, so only the pinches across its
    // opposite faces hold
    let round = Shape::new(0.02, 0.02, 0.012, 2.0, 1.8, 1.0);
    let oval = Shape { a2: 0.015, ..round };
    for shape in [round, oval] {
        let plan = grasp::plan::plan(&request(shape, pose())).unwrap();
        let diagonal: Vec<_> = plan
            .grasps
            .iter()
            .filter(|g| g.kind == GraspKind::SectionDiagonal)
            .collect();
        assert!(!diagonal.is_empty(), "{:?}", plan.rejected);
        for g in &diagonal {
            // opposite normals; on a ring round in top view also along the closing line
            let closing = DVec3::from_array(g.closing);
            let [n1, n2] = g.normals.map(DVec3::from_array);
            assert!(n1.dot(-n2) > 1.0 - 1e-9, "{g:?}");
            if shape == round {
                assert!(n2.dot(closing) > 1.0 - 1e-6, "{g:?}");
            }
        }
        let pinches: Vec<_> = plan
            .grasps
            .iter()
            .filter(|g| matches!(g.kind, GraspKind::SectionHeight | GraspKind::SectionWidth))
            .collect();
        assert!(pinches.is_empty(), "{pinches:?}");
    }
    // a round section (eps1 = 1) has no faces and gets no such candidates
    let plan = grasp::plan::plan(&request(Shape { eps1: 1.0, ..round }, pose())).unwrap();
    assert!(
        plan.grasps
            .iter()
            .all(|g| g.kind != GraspKind::SectionDiagonal)
    );
}

#[test]
fn bad_grippers_and_frictions_are_refused() {
    let mut r = request(SHAPES[0], Pose::IDENTITY);
    r.gripper.max_opening = -1.0;
    assert!(grasp::plan::plan(&r).unwrap_err().contains("max_opening"));
    let mut r = request(SHAPES[0], Pose::IDENTITY);
    r.gripper.min_opening = 0.1;
    assert!(grasp::plan::plan(&r).unwrap_err().contains("min_opening"));
    let mut r = request(SHAPES[0], Pose::IDENTITY);
    r.friction = f64::NAN;
    assert!(grasp::plan::plan(&r).unwrap_err().contains("friction"));
}

#[test]
fn graspnet_rows_carry_the_grasp() {
    let plan = grasp::plan::plan(&request(SHAPES[0], pose())).unwrap();
    let g = &plan.grasps[0];
    let row = grasp::graspnet_row(g, &Gripper::FRANKA_LIKE, 3);
    assert_eq!(row[0], g.score);
    assert_eq!(row[1], g.width);
    assert_eq!(&row[13..16], &g.position);
    assert_eq!(row[16], 3.0);
    // the rotation's first column is the approach
    assert_eq!([row[4], row[7], row[10]], g.approach);
}

#[test]
fn the_implicit_normal_agrees_with_the_jet_off_the_seams_and_holds_on_them() {
    let shapes = [
        Shape::new(1.0, 0.7, 0.5, 2.0, 0.6, 1.4),
        Shape::new(1.0, 1.3, 0.8, 0.0, 1.8, 0.3),
    ];
    for shape in shapes {
        for (eta, omega) in [(0.3, 0.4), (1.0, -1.1), (-0.7, 2.9), (-1.2, -0.2)] {
            let jet = surface::at_parameters(&shape, &Pose::IDENTITY, eta, omega).unwrap();
            let p = DVec3::from_array(jet.point);
            let n = surface::implicit_normal(&shape, p).unwrap();
            assert!(
                n.dot(DVec3::from_array(jet.normal)) > 1.0 - 1e-9,
                "{shape:?} at {eta}, {omega}"
            );
        }
    }
    // the top of a section with eps1 = 1.8 (smooth there, but its normal turns slowly
    // beside the seam): exactly vertical
    let shape = Shape::new(0.02, 0.02, 0.01, 2.5, 1.8, 1.0);
    let top =
        surface::at_parameters(&shape, &Pose::IDENTITY, std::f64::consts::FRAC_PI_2, 0.3).unwrap();
    assert!(
        top.seam && DVec3::from_array(top.normal).dot(DVec3::Z) > 1.0 - 1e-12,
        "{top:?}"
    );
}

#[test]
fn grasps_planned_on_fits_hold_on_the_true_surface() {
    // a small slice of `bench grasps` (which reports the whole suite): fits of full and
    // single-view clouds, noise-free and noisy
    let report =
        supertoroid::bench::grasps::run(12, 260_000, supertoroid::eval::Backend::Cpu).unwrap();
    let (valid, grasped) = report.valid_among_right_fits(|_| true);
    assert!(grasped >= 10, "{grasped} of 12 fits have a grasp");
    assert!(
        valid + 1 >= grasped,
        "{valid} of {grasped} grasps hold on the truth"
    );
}

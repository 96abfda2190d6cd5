use super::*;
use crate::solve::Bounds;
use crate::synth;

fn cloud(shape: Shape, pose: Pose, count: usize, noise: f64, seed: u64) -> Vec<DVec3> {
    let mut rng = synth::rng(seed);
    let mut points = synth::sample_surface(&shape, &pose, count, &mut rng);
    synth::add_noise(&mut points, noise, &mut rng);
    points
}

/// The density integrates to one over space (the model is normalised): a Monte-Carlo
/// integral over a box around a ring, and around a superellipsoid (an open section),
/// without a sensor and seen by one (its density over the surface it sees).
fn density_integral(shape: Shape, viewpoint: Option<DVec3>) -> f64 {
    use rand::Rng;
    let sigma = 0.04;
    let half = shape.half_extents() + DVec3::splat(5.0 * sigma);
    let mut rng = synth::rng(5);
    let candidate = Candidate {
        shape,
        pose: Pose::default(),
    };
    let x = parameters(&candidate, sigma);
    let grid = Grid::for_shape(&shape, sigma);
    let reference = viewpoint.map_or(1.0, |v| v.length_squared());
    let visible = viewpoint.map(|v| {
        normaliser::normaliser(
            &shape,
            DQuat::IDENTITY,
            DVec3::ZERO,
            Some((crate::fit::sight::Sight::at(v), reference)),
            normaliser::FINE,
            None,
            false,
        )
        .visible
        .expect("seen")
    });
    let count = 100_000;
    let mut total = 0.0;
    for _ in 0..count {
        let p = DVec3::new(
            rng.random_range(-half.x..half.x),
            rng.random_range(-half.y..half.y),
            rng.random_range(-half.z..half.z),
        );
        let one = [p];
        let sensor = viewpoint.map(|v| Sensor {
            sight: crate::fit::sight::Sight::at(v),
            point_weights: vec![reference / (p - v).length_squared()],
            reference,
        });
        let data = Data {
            points: &one,
            outlier_weight: 0.0,
            outlier_density: 1e-300,
            sensor: sensor.as_ref(),
            device: None,
        };
        let objective = Objective {
            data: &data,
            rotation0: DQuat::IDENTITY,
            grid: grid.clone(),
            area_grid: normaliser::FINE,
            visible: visible.clone(),
        };
        total += (-objective.evaluate(&x, false).0).exp();
    }
    let volume = (2.0 * half).element_product();
    total / count as f64 * volume
}

#[test]
fn the_density_integrates_to_one() {
    for shape in [
        Shape::new(0.3, 0.25, 0.12, 1.8, 0.7, 1.3),
        Shape::new(0.3, 0.25, 0.2, 0.0, 0.6, 1.2),
        Shape::new(0.3, 0.15, 0.06, 2.3, 1.5, 0.3),
    ] {
        for viewpoint in [None, Some(DVec3::new(0.8, -1.5, 2.0))] {
            let integral = density_integral(shape, viewpoint);
            eprintln!("{shape:?} {viewpoint:?}: {integral}");
            assert!(
                (integral - 1.0).abs() < 0.03,
                "{shape:?}, viewpoint {viewpoint:?}: integral {integral}"
            );
        }
    }
}

/// The normaliser of a shape at the origin, without a sensor.
fn plain_normaliser(shape: &Shape) -> normaliser::Normaliser {
    normaliser::normaliser(
        shape,
        DQuat::IDENTITY,
        DVec3::ZERO,
        None,
        normaliser::FINE,
        None,
        false,
    )
}

fn gradient_matches_differences(shape: Shape, sensor: bool) {
    let pose = Pose::new(
        DQuat::from_scaled_axis(DVec3::new(0.3, -0.2, 0.5)),
        DVec3::new(0.05, -0.02, 0.1),
    );
    let points = cloud(shape, pose, 300, 0.03, 7);
    let viewpoint = DVec3::new(0.9, -1.4, 1.1);
    let sensor_model = Sensor::new(&points, crate::fit::sight::Sight::at(viewpoint));
    let data = Data {
        points: &points,
        outlier_weight: 0.05,
        outlier_density: 0.05 / 8.0,
        sensor: sensor.then_some(&sensor_model),
        device: None,
    };
    let mut start_shape = shape.to_array();
    for (k, v) in start_shape.iter_mut().enumerate() {
        *v *= 1.0 + 0.03 * (k as f64 - 2.5) / 2.5;
    }
    let start = Candidate {
        shape: Shape::from_array(start_shape),
        pose: Pose::new(pose.rotation, DVec3::new(0.06, -0.03, 0.1)),
    };
    let objective = Objective::new(&data, &start, 0.035);
    let x = parameters(&start, 0.035);
    let (value, gradient, _) = objective.evaluate(&x, true);
    for k in 0..PARAMETERS {
        // the objective is smooth by pieces (the incidence is clipped at grazing elements):
        // at a kink the gradient is one of the two one-sided derivatives
        let h = 1e-7;
        let (mut up, mut down) = (x, x);
        up[k] += h;
        down[k] -= h;
        let forward = (objective.evaluate(&up, false).0 - value) / h;
        let backward = (value - objective.evaluate(&down, false).0) / h;
        let close = |numeric: f64| (numeric - gradient[k]).abs() < 2e-4 * (1.0 + numeric.abs());
        assert!(
            close(0.5 * (forward + backward)) || close(forward) || close(backward),
            "{shape:?}, sensor {sensor}: parameter {k}: analytic {} forward {forward} backward {backward}",
            gradient[k]
        );
    }
}

#[test]
fn the_gradient_matches_differences() {
    gradient_matches_differences(Shape::new(0.3, 0.2, 0.12, 2.0, 0.7, 1.3), false);
    gradient_matches_differences(Shape::new(0.3, 0.25, 0.2, 0.0, 0.6, 1.4), false);
    gradient_matches_differences(Shape::new(0.3, 0.15, 0.06, 2.3, 1.5, 0.3), false);
}

#[test]
fn the_gradient_seen_by_a_sensor_matches_differences() {
    gradient_matches_differences(Shape::new(0.3, 0.2, 0.12, 2.0, 0.7, 1.3), true);
    gradient_matches_differences(Shape::new(0.3, 0.25, 0.2, 0.0, 0.6, 1.4), true);
    gradient_matches_differences(Shape::new(0.3, 0.15, 0.06, 2.3, 1.5, 0.3), true);
}

/// From a start with a biased section, the model moves a3 and eps1 back to the truth.
#[test]
fn refinement_recovers_a_noisy_section() {
    let shape = Shape::new(0.3, 0.3, 0.08, 2.0, 0.6, 1.0);
    let pose = Pose::new(
        DQuat::from_scaled_axis(DVec3::new(0.4, 0.1, -0.3)),
        DVec3::new(0.1, 0.0, -0.05),
    );
    let points = cloud(shape, pose, 1500, 0.02, 11);
    let data = Data {
        points: &points,
        outlier_weight: 0.05,
        outlier_density: 0.05 / 8.0,
        sensor: None,
        device: None,
    };
    let start = Candidate {
        shape: Shape::new(0.3, 0.3, 0.095, 2.0, 0.8, 1.0),
        pose,
    };
    let limits = Limits {
        bounds: Bounds::new(1e-3, 5.0, 10.0, 0.1, 2.0),
        fixed_shape: [false; 6],
        fixed_axis: false,
        deadline: None,
    };
    let r = refine(&data, &start, 0.02, &limits, 40);
    let s = r.candidate.shape;
    assert!((s.a3 - 0.08).abs() < 0.004, "a3 {}", s.a3);
    assert!((s.eps1 - 0.6).abs() < 0.08, "eps1 {}", s.eps1);
    assert!((r.sigma / 0.02 - 1.0).abs() < 0.15, "sigma {}", r.sigma);
}

/// The per-point quadrature and the normaliser's grid sum one surface area.
#[test]
fn the_tables_and_the_normaliser_agree_on_the_area() {
    for shape in [
        Shape::new(0.3, 0.25, 0.12, 1.8, 0.7, 1.3),
        Shape::new(0.3, 0.15, 0.06, 2.3, 1.5, 0.3),
        Shape::new(0.3, 0.25, 0.2, 0.0, 0.6, 1.2),
    ] {
        let table_area = |sigma: f64| {
            let grid = Grid::for_shape(&shape, sigma);
            let section = SectionTable::new(&grid, shape.eps1);
            let sweep = SweepTable::new(&grid, shape.a1, shape.a2, shape.eps2);
            let mut area = 0.0;
            for k in 0..section.point.len() {
                let lambda = shape.a4 + section.point[k][0];
                for m in 0..sweep.point.len() {
                    let [cx, cy] = sweep.point[m];
                    let [dx, dy] = sweep.tangent[m];
                    let cross = cx * dy - cy * dx;
                    for [tc, tw] in section.halves[k] {
                        area += lambda.max(0.0)
                            * (shape.a3 * shape.a3 * tw * tw * (dx * dx + dy * dy)
                                + tc * tc * cross * cross)
                                .sqrt();
                    }
                }
            }
            area
        };
        let area = table_area(0.01);
        let n = plain_normaliser(&shape);
        assert!(
            (area / n.area - 1.0).abs() < 0.01,
            "{shape:?}: tables {area}, grid {}",
            n.area
        );
    }
}

/// A point's window holds every surface element within the cutoff: its sum is the sum
/// over the whole surface.
#[test]
fn the_window_misses_nothing() {
    use rand::Rng;
    let mut rng = synth::rng(3);
    for shape in [
        Shape::new(0.3, 0.25, 0.12, 1.8, 0.7, 1.3),
        Shape::new(0.3, 0.15, 0.06, 2.3, 1.5, 0.3),
        Shape::new(0.3, 0.1, 0.05, 1.3, 0.3, 1.7),
        Shape::new(0.3, 0.25, 0.2, 0.0, 0.6, 1.2),
    ] {
        let sigma = 0.03;
        let grid = Grid::for_shape(&shape, sigma);
        let n = plain_normaliser(&shape);
        let window = Window::new(&grid, &shape, sigma, &n);
        let points = cloud(shape, Pose::default(), 300, 1.5 * sigma, rng.random());
        let mut worst: f64 = 0.0;
        for q in points {
            let windowed = window.sums(q, None, false).sum;
            let mut full = 0.0;
            for k in 0..window.section.point.len() {
                let [c, w] = window.section.point[k];
                let lambda = shape.a4 + c;
                if lambda <= 0.0 {
                    continue;
                }
                for sample in &window.samples {
                    let [cx, cy] = sample.point;
                    let [dx, dy] = sample.tangent;
                    let s = DVec3::new(lambda * cx, lambda * cy, shape.a3 * w);
                    let d2 = (q - s).length_squared();
                    if d2 >= window.cut * window.cut {
                        continue;
                    }
                    let cross = cx * dy - cy * dx;
                    let weight = lambda * window.half_areas(k, dx, dy, cross).iter().sum::<f64>();
                    full += weight * ((-0.5 * d2 / window.var).exp() - window.floor);
                }
            }
            if full > 0.0 {
                worst = worst.max((windowed / full - 1.0).abs());
            }
        }
        assert!(
            worst < 1e-9,
            "{shape:?}: a window missed {worst} of a point's sum"
        );
    }
}

/// Past the edges of its frame the sensor sees nothing: a frame over the right half of a
/// ring leaves the normaliser the cells of that half, about half the weight.
#[test]
fn the_frames_edges_hide_the_surface_past_them() {
    use crate::fit::sight::{FieldOfView, Sight};
    let shape = Shape::new(0.5, 0.5, 0.2, 2.0, 1.0, 1.0);
    let viewpoint = DVec3::new(0.0, 0.0, -4.0);
    let seen = |field: Option<FieldOfView>| {
        normaliser::normaliser(
            &shape,
            DQuat::IDENTITY,
            DVec3::ZERO,
            Some((Sight { viewpoint, field }, 16.0)),
            normaliser::FINE,
            None,
            false,
        )
    };
    // x / z from 0 to 1 and y / z from -1 to 1, seen from the viewpoint
    let right_half = FieldOfView::of_pixels(1.0, 1.0, -0.5, 0.5, [0, 0, 1, 2]);
    let (all, half) = (seen(None), seen(Some(right_half)));
    let share = half.area / all.area;
    assert!((0.4..0.6).contains(&share), "{share}");
    let curves = crate::fit::likelihood::Curves::new(
        &shape.to_array(),
        half.range,
        half.grid.0,
        half.grid.1,
    );
    let cells = curves.cells(&shape.to_array());
    let visible = half.visible.as_ref().expect("seen");
    for (centre, seen) in cells.centres.iter().zip(visible) {
        assert!(
            !seen || centre.x >= -1e-9,
            "{centre:?} is left of the frame"
        );
    }
}

//! The objective's per-point sums on the GPU ([`GpuObjective`], `shaders/objective.wgsl`):
//! the quadrature [`Window`] holds at the candidate, packed for the kernel, and its sums
//! finished as [`Objective::evaluate`] returns them. The kernel runs the f64 loop of
//! [`Window::sums`] term for term in f32; the tests hold the two together.

use super::{Data, Matrix, Vector, Window};
use crate::eval::{
    FLAG_GRADIENT, FLAG_SENSOR, FLAG_VISIBILITY, GpuObjective, ObjectiveJob, ObjectiveParams,
};
use crate::model::Pose;
use glam::DMat3;

// (the kernel's parameters are the objective's)
const _: () = assert!(crate::eval::OBJECTIVE_PARAMETERS == super::PARAMETERS);

/// The negative mean log-likelihood, its gradient and the BHHH Hessian of `data` at the
/// window's candidate (at `pose`, inliers weighted by `inlier`) from the device; none
/// where the device failed.
pub(super) fn sums(
    device: &GpuObjective,
    data: &Data,
    window: &Window,
    pose: &Pose,
    inlier: f64,
    with_gradient: bool,
) -> Option<(f64, Vector, Matrix)> {
    let mut points: Vec<[f32; 4]> = data
        .points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let weight = data.sensor.map_or(1.0, |s| s.point_weights[i]);
            [p.x as f32, p.y as f32, p.z as f32, weight as f32]
        })
        .collect();
    // (neighbours in space side by side: a subgroup's points then walk the same
    // quadrature cells, and the kernel's loops diverge less; the sums are the same; each
    // key computed once, and equal keys keep their order)
    points.sort_by_cached_key(|p| morton_key([p[0], p[1], p[2]]));
    let (nodes, sweep, cells) = packed(window);
    let job = ObjectiveJob {
        points: &points,
        nodes: &nodes,
        sweep: &sweep,
        cells: &cells,
        params: params(data, window, pose, inlier, with_gradient),
    };
    let sums = device.sums(&job).ok()?;
    let n = data.points.len() as f64;
    let gradient = Vector::from_column_slice(&sums.gradient);
    let outer = Matrix::from_fn(|a, b| sums.outer[a][b]);
    Some((-sums.log_likelihood / n, -gradient / n, outer / n))
}

/// The cells of a Z-order curve over the normalised cloud's box, [-4, 4]³ (the cloud's
/// RMS radius is 1), in 10 bits a coordinate.
const MORTON_HALF_WIDTH: f32 = 4.0;

/// A point's place along the Z-order curve: the bits of its three cell indices
/// interleaved, so that points near in the key are near in space.
fn morton_key(p: [f32; 3]) -> u32 {
    let cell = |v: f32| {
        let unit = ((v + MORTON_HALF_WIDTH) / (2.0 * MORTON_HALF_WIDTH)).clamp(0.0, 1.0);
        (unit * 1023.0) as u32
    };
    // each 10-bit index spread to every third bit
    let spread = |v: u32| {
        let mut x = v & 0x3ff;
        x = (x | (x << 16)) & 0x0300_00ff;
        x = (x | (x << 8)) & 0x0300_f00f;
        x = (x | (x << 4)) & 0x030c_30c3;
        (x | (x << 2)) & 0x0924_9249
    };
    spread(cell(p[0])) | (spread(cell(p[1])) << 1) | (spread(cell(p[2])) << 2)
}

/// The kernel's constants at the window's candidate.
fn params(
    data: &Data,
    window: &Window,
    pose: &Pose,
    inlier: f64,
    with_gradient: bool,
) -> ObjectiveParams {
    let f = |v: f64| v as f32;
    let column = |v: glam::DVec3| [f(v.x), f(v.y), f(v.z), 0.0];
    let rotation = DMat3::from_quat(pose.rotation);
    let viewpoint = data.sensor.map_or(glam::DVec3::ZERO, |s| s.sight.viewpoint);
    let s = window.shape;
    let d = &window.normaliser.d_log_area;
    let mut flags = 0;
    if with_gradient {
        flags |= FLAG_GRADIENT;
    }
    if data.sensor.is_some() {
        flags |= FLAG_SENSOR;
    }
    if window.normaliser.visible.is_some() {
        flags |= FLAG_VISIBILITY;
    }
    ObjectiveParams {
        flags,
        sectors: window.normaliser.grid.1 as u32,
        columns: [
            column(rotation.x_axis),
            column(rotation.y_axis),
            column(rotation.z_axis),
        ],
        translation: column(pose.translation),
        viewpoint: column(viewpoint),
        sizes: [f(s.a1), f(s.a2), f(s.a3), f(s.a4)],
        kernel: [f(window.var), f(window.cut), f(window.floor), f(inlier)],
        outlier: [f(data.outlier_density), 0.0, 0.0, 0.0],
        d_log_area: [
            [f(d[0]), f(d[1]), f(d[2]), f(d[3])],
            [f(d[4]), f(d[5]), f(d[6]), f(d[7])],
            [f(d[8]), f(d[9]), f(d[10]), f(d[11])],
        ],
        ..Default::default()
    }
}

/// The quadrature as the kernel reads it: three vec4 per section node, three per sweep
/// sample, and the cells (rings of the nodes, sectors of the samples, then the
/// visibility of each normaliser cell where it is held).
fn packed(window: &Window) -> (Vec<[f32; 4]>, Vec<[f32; 4]>, Vec<u32>) {
    let f = |v: f64| v as f32;
    let section = &window.section;
    let nodes = (0..section.point.len())
        .flat_map(|k| {
            let ([c, w], [dc, dw]) = (section.point[k], section.d_point[k]);
            let [[tc0, tw0], [tc1, tw1]] = section.halves[k];
            let [[dtc0, dtw0], [dtc1, dtw1]] = section.d_halves[k];
            [
                [f(c), f(w), f(dc), f(dw)],
                [f(tc0), f(tw0), f(tc1), f(tw1)],
                [f(dtc0), f(dtw0), f(dtc1), f(dtw1)],
            ]
        })
        .collect();
    let sweep = (window.samples.iter().zip(&window.polar).zip(&window.radius))
        .flat_map(|((s, &polar), &radius)| {
            let ([cx, cy], [dx, dy]) = (s.point, s.tangent);
            let ([dcx, dcy], [ddx, ddy]) = (s.d_point, s.d_tangent);
            [
                [f(cx), f(cy), f(dx), f(dy)],
                [f(dcx), f(dcy), f(ddx), f(ddy)],
                [f(s.cross), f(polar), f(radius), 0.0],
            ]
        })
        .collect();
    let mut cells: Vec<u32> = window.rings.iter().map(|&r| r as u32).collect();
    cells.extend(window.samples.iter().map(|s| s.sector as u32));
    if let Some(visible) = &window.normaliser.visible {
        cells.extend(visible.iter().map(|&v| u32::from(v)));
    }
    (nodes, sweep, cells)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_z_order_key_interleaves_the_cells_bits() {
        let cell = 2.0 * MORTON_HALF_WIDTH / 1023.0;
        let at = |x: f32, y: f32, z: f32| {
            let c = |k: f32| -MORTON_HALF_WIDTH + (k + 0.5) * cell;
            morton_key([c(x), c(y), c(z)])
        };
        assert_eq!(at(0.0, 0.0, 0.0), 0);
        assert_eq!(at(1.0, 0.0, 0.0), 0b001);
        assert_eq!(at(0.0, 1.0, 0.0), 0b010);
        assert_eq!(at(0.0, 0.0, 1.0), 0b100);
        assert_eq!(at(2.0, 0.0, 0.0), 0b001_000);
        assert_eq!(morton_key([9.0, 9.0, 9.0]), (1 << 30) - 1);
        assert_eq!(morton_key([-9.0, -9.0, -9.0]), 0);
    }
}

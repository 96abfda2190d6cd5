//! Initial hole axes and shapes for stage 1.
//!
//! The paper starts from the cloud's x, y and z axes at the centroid. On a single-view
//! cloud the centroid lies on the visible skin, not on the axis, and the principal axes
//! follow the visible patch, so those starts are often in the wrong basin. A better
//! estimate comes from the normals: every normal line of a surface of revolution meets
//! its axis (a supertoroid with a1 ≈ a2 and eps2 ≈ 1 is one, and others are close). A
//! line (p, n) meets the axis (direction d, moment m = c × d) when
//! d·(p × n) + n·m = 0 (Plücker coordinates), which is linear in (d, m): the axis is the
//! smallest generalised eigenvector of a 6×6 moment matrix (Pottmann's linear-complex
//! fit), made robust by reweighting. Its distances give the radii: the outer and inner
//! radius of the points around the axis are a(1 + a4) and a(a4 - 1).

use crate::eval::Candidate;
use crate::model::{Pose, Shape};
use glam::{DMat3, DQuat, DVec3};
use nalgebra::{Matrix3, Matrix6, Vector3, Vector6};
use rayon::prelude::*;

/// Unit normals by local PCA over the k nearest neighbours (brute force: the stage-1
/// sample is a few hundred points; in parallel over points, which on the paper's clouds
/// was half of a fit's work before stage 1). Orientation is arbitrary, which the line fit
/// ignores.
pub fn estimate_normals(points: &[DVec3], k: usize) -> Vec<DVec3> {
    let k = k.min(points.len().saturating_sub(1)).max(3);
    points
        .par_iter()
        .map_init(Vec::new, |dist: &mut Vec<(f64, usize)>, p| {
            let neighbours = nearest(points, *p, k, dist);
            let mean =
                neighbours.iter().map(|&(_, j)| points[j]).sum::<DVec3>() / neighbours.len() as f64;
            let mut cov = Matrix3::<f64>::zeros();
            for &(_, j) in neighbours {
                let d = points[j] - mean;
                let v = Vector3::new(d.x, d.y, d.z);
                cov += v * v.transpose();
            }
            let eig = cov.symmetric_eigen();
            let i = eig.eigenvalues.imin();
            let n = eig.eigenvectors.column(i);
            DVec3::new(n[0], n[1], n[2]).normalize_or(DVec3::Z)
        })
        .collect()
}

/// The point `p` and its `k` nearest neighbours among `points` (fewer where there are
/// not so many), as (squared distance, index) in no particular order, by brute force in
/// `dist` (kept between calls to save its allocation).
pub(crate) fn nearest<'a>(
    points: &[DVec3],
    p: DVec3,
    k: usize,
    dist: &'a mut Vec<(f64, usize)>,
) -> &'a [(f64, usize)] {
    dist.clear();
    dist.extend(
        points
            .iter()
            .enumerate()
            .map(|(j, q)| ((*q - p).length_squared(), j)),
    );
    let k = k.min(dist.len() - 1);
    dist.select_nth_unstable_by(k, |a, b| a.0.total_cmp(&b.0));
    &dist[..=k]
}

/// The axis that the normal lines meet best: (unit direction, a point on it), or None
/// when the normals do not determine one (a plane, a sphere-like patch).
pub fn axis_from_normal_lines(points: &[DVec3], normals: &[DVec3]) -> Option<(DVec3, DVec3)> {
    let mut weights = vec![1.0; points.len()];
    let mut axis = None;
    for _ in 0..4 {
        let mut m = Matrix6::<f64>::zeros();
        for ((p, n), w) in points.iter().zip(normals).zip(&weights) {
            let pn = p.cross(*n);
            let v = Vector6::new(pn.x, pn.y, pn.z, n.x, n.y, n.z);
            m += *w * v * v.transpose();
        }
        // minimise d'Ad + 2d'Bm + m'Cm with |d| = 1: m = -C⁻¹B'd, then the Schur complement
        let a = m.fixed_view::<3, 3>(0, 0).into_owned();
        let b = m.fixed_view::<3, 3>(0, 3).into_owned();
        let c = m.fixed_view::<3, 3>(3, 3).into_owned();
        let c_inv = c.try_inverse()?;
        let schur = a - b * c_inv * b.transpose();
        let eig = schur.symmetric_eigen();
        let i = eig.eigenvalues.imin();
        let d = eig.eigenvectors.column(i).into_owned();
        let moment = -c_inv * b.transpose() * d;
        let dir = DVec3::new(d[0], d[1], d[2]).normalize();
        let moment = DVec3::new(moment[0], moment[1], moment[2]);
        let on_axis = dir.cross(moment); // closest point of the axis to the origin
        if !dir.is_finite() || !on_axis.is_finite() {
            return None;
        }
        // reweight by how far each normal line passes from the axis (Cauchy-like)
        let gaps: Vec<f64> = points
            .iter()
            .zip(normals)
            .map(|(p, n)| line_gap(*p, *n, on_axis, dir))
            .collect();
        let mut sorted = gaps.clone();
        sorted.sort_by(f64::total_cmp);
        let scale = sorted[sorted.len() / 2].max(1e-9) * 2.0;
        for (w, g) in weights.iter_mut().zip(&gaps) {
            *w = 1.0 / (1.0 + (g / scale).powi(2));
        }
        axis = Some((dir, on_axis));
    }
    axis
}

/// Distance between the line (p, n) and the line (c, d).
fn line_gap(p: DVec3, n: DVec3, c: DVec3, d: DVec3) -> f64 {
    let cross = n.cross(d);
    let len = cross.length();
    if len < 1e-9 {
        // parallel: distance of p from the axis line
        let v = p - c;
        return (v - d * v.dot(d)).length();
    }
    ((p - c).dot(cross) / len).abs()
}

/// A rotation whose z axis is `axis` (the hole axis) and whose x axis is as close to
/// `hint` as possible.
pub fn frame_with_z(axis: DVec3, hint: DVec3) -> DQuat {
    let z = axis.normalize();
    let x = (hint - z * hint.dot(z))
        .try_normalize()
        .unwrap_or_else(|| z.any_orthonormal_vector());
    let y = z.cross(x);
    DQuat::from_mat3(&DMat3::from_cols(x, y, z))
}

fn percentile(values: &mut [f64], f: f64) -> f64 {
    values.sort_by(f64::total_cmp);
    values[((values.len() - 1) as f64 * f).round() as usize]
}

/// A start for a known axis line: centre on the line at the middle of the points' span
/// along it, radii from the distances to it (outer a(1 + a4), inner a(a4 - 1)), a3 from
/// the span. `a4_override` replaces the estimated hole ratio.
pub fn start_on_axis_line(
    points: &[DVec3],
    axis: DVec3,
    on_axis: DVec3,
    hint: DVec3,
    a4_override: Option<f64>,
) -> Candidate {
    let rotation = frame_with_z(axis, hint);
    let axis = rotation * DVec3::Z;
    let mut along: Vec<f64> = points.iter().map(|p| (*p - on_axis).dot(axis)).collect();
    let mut radial: Vec<f64> = points
        .iter()
        .map(|p| {
            let v = *p - on_axis;
            (v - axis * v.dot(axis)).length()
        })
        .collect();
    let lo = percentile(&mut along, 0.02);
    let hi = percentile(&mut along, 0.98);
    let outer = percentile(&mut radial, 0.98).max(1e-3);
    let inner = percentile(&mut radial, 0.02).min(0.95 * outer);
    let centre = on_axis + axis * 0.5 * (lo + hi);
    let half_height = (0.5 * (hi - lo)).max(0.02 * outer);
    let (a, a4) = match a4_override {
        Some(a4) => (outer / (1.0 + a4), a4),
        None => {
            // outer = a(1 + a4), inner = a(a4 - 1)
            let a4 = ((outer + inner) / (outer - inner)).clamp(1.05, 6.0);
            (outer / (1.0 + a4), a4)
        }
    };
    Candidate {
        shape: Shape::new(a, a, half_height, a4, 1.0, 1.0),
        pose: Pose::new(rotation, centre),
    }
}

/// The point of the axis with direction `d` that the normal lines meet best (for a
/// caller's known axis direction).
pub fn axis_point_for_direction(points: &[DVec3], normals: &[DVec3], d: DVec3) -> Option<DVec3> {
    let mut b = Matrix3::<f64>::zeros();
    let mut c = Matrix3::<f64>::zeros();
    let dv = Vector3::new(d.x, d.y, d.z);
    for (p, n) in points.iter().zip(normals) {
        let pn = p.cross(*n);
        let pn = Vector3::new(pn.x, pn.y, pn.z);
        let nv = Vector3::new(n.x, n.y, n.z);
        b += pn * nv.transpose();
        c += nv * nv.transpose();
    }
    let m = -c.try_inverse()? * b.transpose() * dv;
    let on_axis = d.cross(DVec3::new(m[0], m[1], m[2]));
    on_axis.is_finite().then_some(on_axis)
}

/// A second hole axis for a ring seen edge-on: the direction across both the normal
/// lines' axis (`axis`) and the line of sight from `viewpoint` to the cloud's centroid,
/// the origin of the normalised frame. Seen edge-on, the visible band of a ring is
/// locally a cylinder about the tube's tangent, whose normal lines meet that tangent
/// about as well as the hole axis, so [`axis_from_normal_lines`] often returns the
/// tangent; the hole axis is then across the tangent and the line of sight. None without
/// a viewpoint, or where the axis is within [`ALONG_SIGHT_DEGREES`] of the line of sight
/// (a view into the hole; across it no direction stands out).
pub fn across_line_of_sight(axis: DVec3, viewpoint: Option<DVec3>) -> Option<DVec3> {
    let sight = (-viewpoint?).try_normalize()?;
    (axis.dot(sight).abs() < ALONG_SIGHT_DEGREES.to_radians().cos())
        .then(|| axis.cross(sight).try_normalize())
        .flatten()
}

/// A normal lines' axis within this angle of the line of sight gets no second axis across
/// it ([`across_line_of_sight`]): a view seen far off its hole axis (75 degrees, say)
/// can have its normal lines' axis as near as 44 degrees to the line of sight, and still
/// needs the axis across it.
pub const ALONG_SIGHT_DEGREES: f64 = 25.0;

/// The other reading of a top view: a superellipse with exponent eps2 turned 45 degrees
/// about the hole axis looks like one with exponent 2 - eps2 (a diamond,
/// eps2 = 2, is a square, eps2 -> 0, turned 45 degrees; a circle, eps2 = 1, is itself).
/// The sizes keep the radius along the new x axis: a superellipse of radius a and
/// exponent e reaches √2·a·2^(-e/2) at 45 degrees. A one-sided view often fits both
/// readings about equally well by least squares (the eps2 of the suite's noisy single
/// views that failed that way: 1.45-1.55 true, 0.3-0.7 fitted).
pub fn turned_dual(candidate: &Candidate) -> Candidate {
    let s = candidate.shape;
    let radius = std::f64::consts::SQRT_2 * 2f64.powf(-s.eps2 / 2.0) * (s.a1 * s.a2).sqrt();
    Candidate {
        shape: Shape::new(radius, radius, s.a3, s.a4, s.eps1, 2.0 - s.eps2),
        pose: Pose::new(
            candidate.pose.rotation * DQuat::from_rotation_z(std::f64::consts::FRAC_PI_4),
            candidate.pose.translation,
        ),
    }
}

/// The two readings of a superellipsoid (a4 = 0) with its axes cycled: its x, y, z
/// taken as the new z, x, y, and as the new y, z, x, its sizes with them and its two
/// exponents exchanged. With eps1 = eps2 each is the same surface; otherwise the nearest
/// with another axis as its z (Liu et al.'s similarity switch, EMS, CVPR 2022). A view of
/// a box or a bar often fits a body with the wrong axis as its z about as well by least
/// squares, a basin the search's starts along the normals' axis do not leave.
pub fn axes_cycled(candidate: &Candidate) -> [Candidate; 2] {
    let s = candidate.shape;
    let r = candidate.pose.rotation;
    let cycled = |sizes: [f64; 3], columns: [DVec3; 3]| Candidate {
        shape: Shape::new(sizes[0], sizes[1], sizes[2], s.a4, s.eps2, s.eps1),
        pose: Pose::new(
            (r * DQuat::from_mat3(&DMat3::from_cols(columns[0], columns[1], columns[2])))
                .normalize(),
            candidate.pose.translation,
        ),
    };
    [
        // new x, y, z along the old y, z, x
        cycled([s.a2, s.a3, s.a1], [DVec3::Y, DVec3::Z, DVec3::X]),
        // new x, y, z along the old z, x, y
        cycled([s.a3, s.a1, s.a2], [DVec3::Z, DVec3::X, DVec3::Y]),
    ]
}

/// The hollow reading of `closed`, a body without a through hole (a4 < 1: an apple, or
/// none at all): the same outer radii a1·(1 + a4) and a2·(1 + a4), height, exponents and
/// pose around a hole of a4 = `a4`. A tube seen from the side shows its outside only,
/// which least squares fits as well closed as open; whether the sensor should have seen
/// into a hole is for the likelihood to weigh, given both readings.
pub fn hollowed(closed: &Candidate, a4: f64) -> Candidate {
    let s = closed.shape;
    let shrink = (1.0 + s.a4.max(0.0)) / (1.0 + a4);
    Candidate {
        shape: Shape::new(s.a1 * shrink, s.a2 * shrink, s.a3, a4, s.eps1, s.eps2),
        pose: closed.pose,
    }
}

/// The rings a closed body (a4 < 1) may be lying across: its outline
/// ([`superellipsoid_outline`]) with its axes cycled ([`axes_cycled`]), each around a hole
/// of a4 = `a4` ([`hollowed`]), so that each ring's extents along the world's directions
/// are the body's. A view of an elongated or pinched ring often fits a closed slab lying
/// across its hole (the hole axis 90 degrees off) as well by least squares, where no
/// start near the ring's own axis survives round 1; whether the points show a hole is for
/// the likelihood to weigh, given both readings.
pub fn rings_across(closed: &Candidate, a4: f64) -> [Candidate; 2] {
    axes_cycled(&superellipsoid_outline(closed)).map(|c| hollowed(&c, a4))
}

/// The superellipsoid (a4 = 0) with the outline of `free`, a free fit of the same
/// cloud: its radii a1·(1 + a4) and a2·(1 + a4) (an apple's or a ring's outer
/// radius), its height, exponents and pose. `model: auto`'s superellipsoid search starts
/// there too: a box's free fit is often an apple without a dimple whose surface is
/// right, and the superellipsoid's own starts need not reach that basin.
pub fn superellipsoid_outline(free: &Candidate) -> Candidate {
    let s = free.shape;
    let grown = 1.0 + s.a4.max(0.0);
    Candidate {
        shape: Shape::new(s.a1 * grown, s.a2 * grown, s.a3, 0.0, s.eps1, s.eps2),
        pose: free.pose,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The rings across a closed body have its extents along the world's directions, each
    /// with another of its axes as the hole's.
    #[test]
    fn the_rings_across_a_closed_body_keep_its_extents() {
        let pose = Pose::new(
            DQuat::from_euler(glam::EulerRot::XYZ, 0.3, -0.7, 1.1),
            DVec3::new(0.1, -0.2, 0.3),
        );
        let closed = Candidate {
            shape: Shape::new(0.4, 0.9, 0.2, 0.5, 0.7, 1.3),
            pose,
        };
        // the body's half extents along its own axes, in the world
        let extents = |c: &Candidate| {
            let s = c.shape;
            let grown = 1.0 + s.a4.max(0.0);
            [
                c.pose.rotation * DVec3::X * (s.a1 * grown),
                c.pose.rotation * DVec3::Y * (s.a2 * grown),
                c.pose.rotation * DVec3::Z * s.a3,
            ]
        };
        let body = extents(&closed);
        let rings = rings_across(&closed, 2.0);
        for ring in &rings {
            assert_eq!(ring.shape.a4, 2.0);
            assert_eq!(ring.pose.translation, pose.translation);
            for along in extents(ring) {
                let same = body
                    .iter()
                    .any(|b| (*b - along).length() < 1e-12 || (*b + along).length() < 1e-12);
                assert!(same, "{along:?} is none of the body's extents {body:?}");
            }
        }
        let axes: Vec<DVec3> = rings.iter().map(|r| r.pose.rotation * DVec3::Z).collect();
        let own = pose.rotation * DVec3::Z;
        assert!(
            axes.iter().all(|a| a.dot(own).abs() < 1e-12),
            "a ring across has another axis"
        );
        assert!(
            axes[0].dot(axes[1]).abs() < 1e-12,
            "the two rings' axes differ"
        );
    }

    /// A closed body's hollow reading keeps its outline (outer radii, height, exponents,
    /// pose) around a hole of the a4 asked for.
    #[test]
    fn a_closed_bodys_hollow_reading_keeps_its_outline() {
        let pose = Pose::new(DQuat::from_rotation_y(0.4), DVec3::new(0.0, 0.1, 0.5));
        for a4 in [0.0, 0.4, 0.9] {
            let closed = Candidate {
                shape: Shape::new(0.06, 0.05, 0.12, a4, 0.4, 0.9),
                pose,
            };
            let hollow = hollowed(&closed, 2.0);
            let s = hollow.shape;
            assert_eq!(s.a4, 2.0);
            assert!((s.a1 * 3.0 - 0.06 * (1.0 + a4)).abs() < 1e-12, "{s:?}");
            assert!((s.a2 * 3.0 - 0.05 * (1.0 + a4)).abs() < 1e-12, "{s:?}");
            assert_eq!((s.a3, s.eps1, s.eps2), (0.12, 0.4, 0.9));
            assert_eq!(hollow.pose, pose);
        }
    }

    /// An apple's and a ring's outline is their outer radius; a superellipsoid is its
    /// own outline.
    #[test]
    fn a_free_fits_outline_keeps_its_outer_radii_height_and_pose() {
        let pose = Pose::new(DQuat::from_rotation_x(0.3), DVec3::new(0.1, 0.2, 0.3));
        for (a4, grown) in [(0.5, 1.5), (2.0, 3.0), (0.0, 1.0)] {
            let free = Candidate {
                shape: Shape::new(0.02, 0.03, 0.04, a4, 0.3, 1.2),
                pose,
            };
            let outline = superellipsoid_outline(&free);
            assert_eq!(
                outline.shape.to_array(),
                [0.02 * grown, 0.03 * grown, 0.04, 0.0, 0.3, 1.2]
            );
            assert_eq!(outline.pose, pose);
        }
    }

    /// A candidate's inside-outside function at world point `q` (1 on its surface).
    fn inside_outside(c: &Candidate, q: DVec3) -> f64 {
        c.shape
            .inside_outside(c.pose.rotation.inverse() * (q - c.pose.translation))
    }

    /// With equal exponents a superellipsoid with its axes cycled is the same surface;
    /// with any, the tips of its three axes stay where they were.
    #[test]
    fn a_superellipsoid_with_its_axes_cycled_keeps_its_surface_or_its_tips() {
        let pose = Pose::new(
            DQuat::from_euler(glam::EulerRot::XYZ, 0.3, -0.5, 1.1),
            DVec3::new(0.1, -0.2, 0.6),
        );
        let mut rng = crate::synth::rng(3);
        for (eps1, eps2) in [(0.7, 0.7), (0.4, 1.3)] {
            let c = Candidate {
                shape: Shape::new(0.03, 0.05, 0.08, 0.0, eps1, eps2),
                pose,
            };
            let surface = crate::synth::sample_surface(&c.shape, &c.pose, 200, &mut rng);
            let tips: Vec<DVec3> = [DVec3::X * 0.03, DVec3::Y * 0.05, DVec3::Z * 0.08]
                .into_iter()
                .flat_map(|t| [t, -t])
                .map(|t| pose.rotation * t + pose.translation)
                .collect();
            for cycled in axes_cycled(&c) {
                assert_eq!(
                    (cycled.shape.eps1, cycled.shape.eps2, cycled.shape.a4),
                    (eps2, eps1, 0.0)
                );
                assert_ne!(cycled.shape.a3, c.shape.a3);
                let same_surface = eps1 == eps2;
                for q in tips.iter().chain(surface.iter().filter(|_| same_surface)) {
                    let f = inside_outside(&cycled, *q);
                    assert!((f - 1.0).abs() < 1e-6, "{eps1} {eps2}: {f}");
                }
            }
        }
    }

    use crate::model::superellipse_norm;

    /// The radius of a candidate's mean superellipse along a world direction in its
    /// top view (the canonical xy plane, a1 = a2 here).
    fn top_view_radius(c: &Candidate, world_angle: f64) -> f64 {
        let s = c.shape;
        // the direction in the candidate's own frame
        let local =
            c.pose.rotation.inverse() * DVec3::new(world_angle.cos(), world_angle.sin(), 0.0);
        s.a1 * s.a4 / superellipse_norm(local.x, local.y, s.eps2)
    }

    #[test]
    fn the_other_reading_passes_through_the_same_top_view() {
        for eps2 in [0.3, 0.6, 1.0, 1.5, 1.8] {
            let c = Candidate {
                shape: Shape::new(0.08, 0.08, 0.02, 2.0, 0.7, eps2),
                pose: Pose::new(DQuat::IDENTITY, DVec3::ZERO),
            };
            let dual = turned_dual(&c);
            assert!((dual.shape.eps2 - (2.0 - eps2)).abs() < 1e-12);
            // on the axes and on the diagonals the two readings meet
            for k in 0..8 {
                let angle = k as f64 * std::f64::consts::FRAC_PI_4;
                let (r, r_dual) = (top_view_radius(&c, angle), top_view_radius(&dual, angle));
                assert!(
                    (r - r_dual).abs() < 1e-9 * r,
                    "eps2 {eps2} at {angle}: {r} vs {r_dual}"
                );
            }
            // and read twice, it is itself turned a quarter (the a1/a2 symmetry)
            let twice = turned_dual(&dual);
            assert!((twice.shape.a1 - c.shape.a1).abs() < 1e-12);
            assert!((twice.shape.eps2 - eps2).abs() < 1e-12);
            let quarter = c.pose.rotation * DQuat::from_rotation_z(std::f64::consts::FRAC_PI_2);
            assert!(twice.pose.rotation.dot(quarter).abs() > 1.0 - 1e-12);
        }
        // a circle is its own other reading, up to the turn
        let circle = Shape::new(0.05, 0.05, 0.01, 1.5, 1.0, 1.0);
        let dual = turned_dual(&Candidate {
            shape: circle,
            pose: Pose::new(DQuat::IDENTITY, DVec3::ZERO),
        });
        assert!((dual.shape.a1 - circle.a1).abs() < 1e-12);
    }

    #[test]
    fn the_axis_across_the_line_of_sight_is_across_both() {
        // a ring's tube tangent along x, seen from -y: the hole axis is z (either sign)
        let across = across_line_of_sight(DVec3::X, Some(DVec3::new(0.0, -5.0, 0.0)))
            .expect("an axis across the line of sight");
        assert!((across.dot(DVec3::Z).abs() - 1.0).abs() < 1e-12, "{across}");
        // 40 degrees from the line of sight it still gives the direction across both
        let tilted = DVec3::new(40f64.to_radians().sin(), 0.0, 0.0)
            + DVec3::new(0.0, 40f64.to_radians().cos(), 0.0);
        let across = across_line_of_sight(tilted, Some(DVec3::new(0.0, -5.0, 0.0))).unwrap();
        assert!(across.dot(tilted).abs() < 1e-12 && across.dot(DVec3::Y).abs() < 1e-12);
        // an axis along the line of sight (a view into the hole) gives none, nor does a
        // cloud without a viewpoint
        let along = DVec3::new(0.1, 1.0, 0.0).normalize();
        assert_eq!(
            across_line_of_sight(along, Some(DVec3::new(0.0, -5.0, 0.0))),
            None
        );
        assert_eq!(across_line_of_sight(DVec3::X, None), None);
    }

    /// Only the top and the front of a box standing on a table are seen: the standing
    /// start still reaches from the table to the top, about the box's axis, and the
    /// lying ones have their axes in the table's plane.
    #[test]
    fn a_standing_start_reaches_down_to_the_table() {
        // the table z = 0.1 (n = z, d = -0.1); a box 0.6 x 0.4 x 0.5 tall on it
        let (normal, offset) = (DVec3::Z, -0.1);
        let mut seen = Vec::new();
        for i in 0..=20 {
            for j in 0..=20 {
                let (u, v) = (i as f64 / 20.0, j as f64 / 20.0);
                // the top face, and the front face (y = -0.2) down to the table
                seen.push(DVec3::new(-0.3 + 0.6 * u, -0.2 + 0.4 * v, 0.6));
                seen.push(DVec3::new(-0.3 + 0.6 * u, -0.2, 0.1 + 0.5 * v));
            }
        }
        let starts = resting_starts(&seen, normal, offset, None);
        assert_eq!(starts.len(), 6);
        let standing = &starts[0];
        let axis = standing.pose.rotation * DVec3::Z;
        assert!(axis.dot(normal) > 0.999, "{axis}");
        let bottom = standing.pose.translation.z - standing.shape.a3;
        assert!((bottom - 0.1).abs() < 1e-9, "bottom {bottom}");
        assert!((standing.shape.a3 - 0.25).abs() < 1e-9);
        // the footprint's long side (x) is the first axis across
        let long = standing.pose.rotation * DVec3::X;
        assert!(long.dot(DVec3::X).abs() > 0.999, "{long}");
        for lying in &starts[2..] {
            let axis = lying.pose.rotation * DVec3::Z;
            assert!(axis.dot(normal).abs() < 1e-9, "{axis}");
        }
        // with a4 known, one start per axis at it
        let held = resting_starts(&seen, normal, offset, Some(0.0));
        assert_eq!(held.len(), 3);
        assert!(held.iter().all(|s| s.shape.a4 == 0.0));
    }

    #[test]
    fn a_start_behind_the_skin_moves_away_from_the_sensor_across_the_axis() {
        let start = Candidate {
            shape: Shape::new(0.2, 0.2, 0.05, 2.0, 1.0, 1.0),
            pose: Pose::new(DQuat::IDENTITY, DVec3::ZERO),
        };
        // seen from -y and a little above: moved +y by the mean radius, not along z
        let moved = behind_the_skin(&start, DVec3::new(0.0, -5.0, 1.0)).unwrap();
        assert!((moved.pose.translation - DVec3::new(0.0, 0.4, 0.0)).length() < 1e-12);
        assert_eq!(moved.shape, start.shape);
        // seen into the hole: none
        assert!(behind_the_skin(&start, DVec3::new(0.5, 0.0, 5.0)).is_none());
    }
}

/// `start` (centred on the cloud's centroid, the origin of the normalised frame) moved
/// away from the sensor at `viewpoint`, across its hole axis, by its mean radius
/// a1·a4: a single view's centroid lies on the skin the sensor saw, and seen from the
/// side a ring's centre is that far behind it. None for a view into the hole (the axis
/// within [`ALONG_SIGHT_DEGREES`] of the line of sight), whose centroid is on
/// the axis already. Without them a thin ring seen nearly edge-on can be fitted as a
/// closed body many times its size that its points cover a small part of: every start
/// on the skin collapses there, and one moved behind it finds the ring.
pub fn behind_the_skin(start: &Candidate, viewpoint: DVec3) -> Option<Candidate> {
    let axis = start.pose.axis();
    let away = (start.pose.translation - viewpoint).try_normalize()?;
    if away.dot(axis).abs() >= ALONG_SIGHT_DEGREES.to_radians().cos() {
        return None;
    }
    let across = (away - axis * away.dot(axis)).try_normalize()?;
    let mut moved = *start;
    moved.pose.translation += across * (start.shape.a1 * start.shape.a4);
    Some(moved)
}

/// Starts for an object standing on a table (`normal`, `offset`: the plane n·x + d = 0 in
/// the points' frame, n towards the object): its axis along the table's normal (standing)
/// or along either axis of its footprint (lying), each with the box the points and their
/// shadows on the table span, so that it reaches down to the table; at hole ratios 1.5
/// and 3, or at the known a4.
pub fn resting_starts(
    points: &[DVec3],
    normal: DVec3,
    offset: f64,
    known_a4: Option<f64>,
) -> Vec<Candidate> {
    if points.is_empty() {
        return Vec::new();
    }
    let shadows: Vec<DVec3> = points
        .iter()
        .map(|p| *p - normal * (normal.dot(*p) + offset))
        .collect();
    // the footprint's longest axis: the shadows' largest spread
    let (vectors, _) = crate::fit::principal_axes(&shadows);
    let along = (vectors.x_axis - normal * vectors.x_axis.dot(normal))
        .try_normalize()
        .unwrap_or_else(|| normal.any_orthonormal_vector());
    let across = normal.cross(along);
    let spanned: Vec<DVec3> = points.iter().chain(&shadows).copied().collect();
    let a4s: Vec<f64> = known_a4.map_or_else(|| vec![1.5, 3.0], |a4| vec![a4]);
    let mut starts = Vec::new();
    for (axis, hint) in [(normal, along), (along, normal), (across, normal)] {
        let rotation = frame_with_z(axis, hint);
        let inverse = rotation.inverse();
        let local: Vec<DVec3> = spanned.iter().map(|p| inverse * *p).collect();
        let (lo, hi) = local
            .iter()
            .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), q| {
                (lo.min(*q), hi.max(*q))
            });
        let half = ((hi - lo) / 2.0).max(DVec3::splat(1e-3));
        let middle = rotation * ((lo + hi) / 2.0);
        for &a4 in &a4s {
            starts.push(Candidate {
                shape: Shape::new(
                    half.x / (1.0 + a4),
                    half.y / (1.0 + a4),
                    half.z,
                    a4,
                    1.0,
                    1.0,
                ),
                pose: Pose::new(rotation, middle),
            });
        }
    }
    starts
}

//! Parallel-jaw grasps for a fitted object, after the heuristics of paper §IV: contacts
//! on the fitted surface where the normals oppose each other, ranked by the quantities
//! the paper names (antipodality, curvature at the contacts, distance from the centre of
//! mass).
//!
//! Candidates, in the object's canonical frame (z the hole axis):
//! * with a through hole (a4 > 1), around the mean superellipse: a pinch across the
//!   section's height (contacts at its top and bottom, the hand coming in from outside
//!   the ring or along it), and a pinch across its width (one finger in the hole, the
//!   hand along the axis); the section's thinner direction scores better by its flatter
//!   contacts. A pinched section (eps1 > 1, a diamond at eps1 = 2) has sharp tips at its
//!   top, bottom and sides and flat faces between them: its pinches go across the two
//!   pairs of opposite faces, at the points where the section's radius meets the face
//!   square (below);
//! * across the whole body through its centre, in every direction of the x-y plane (the
//!   hand along the axis or across it);
//! * without a hole, also across the axis (top and bottom, the hand from the side): the
//!   three principal axes of a superellipsoid are among these.
//!
//! A candidate is dropped where it does not fit the opening, its normals leave the
//! friction cone, a finger or the palm would meet the surface on the way in, the hand
//! would go through the support plane, or it comes from behind the object as the camera
//! sees it. Everything is deterministic: the same object gives the same list.

use super::collision::SurfaceCells;
use super::gripper::{FrameBox, GraspFrame, Gripper, POSTURES, hand_boxes};
use super::surface::{SurfacePoint, at_parameters};
use crate::model::{Plane, Pose, Shape};
use glam::{DMat3, DQuat, DVec3};
use rayon::prelude::*;
use serde::Serialize;
use std::f64::consts::{FRAC_PI_2, PI, TAU};

/// Positions around the ring for the section pinches.
pub const PINCHES_AROUND: usize = 16;
/// Directions across the body (a half turn; the other half is the same grasps).
pub const BODY_DIRECTIONS: usize = 8;
/// Side approaches for the grasps across a superellipsoid's axis.
pub const SIDE_APPROACHES: usize = 8;
/// An approach pointing towards the camera by more than this cosine comes from behind.
pub const BEHIND_COSINE: f64 = 0.25;
/// The contact normals are checked over this part of the pad's width (or of the
/// thinnest half-axis, where smaller) around each contact.
pub const PAD_REACH: f64 = 0.25;
/// Weights of the score's terms: antipodality, flatness at the contacts, centring.
pub const SCORE_WEIGHTS: [f64; 3] = [0.5, 0.25, 0.25];

/// What a grasp is planned for.
#[derive(Clone, Copy, Debug)]
pub struct GraspRequest {
    pub shape: Shape,
    pub pose: Pose,
    pub gripper: Gripper,
    /// Coulomb friction coefficient at the contacts (the cone's half-angle is atan(mu))
    pub friction: f64,
    /// the table, where known: no part of the hand may go below it
    pub plane: Option<Plane>,
    /// the camera's position: no approach from behind the object
    pub viewpoint: Option<DVec3>,
    pub max_grasps: usize,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum GraspKind {
    /// across the ring's section, top to bottom
    SectionHeight,
    /// across the ring's section, one finger in the hole
    SectionWidth,
    /// across a pinched section's opposite faces, slanting between top and side
    SectionDiagonal,
    /// across the whole body through its centre, perpendicular to the axis
    AcrossBody,
    /// across the axis of a shape without a hole, top to bottom
    AlongAxis,
}

#[derive(Clone, Copy, Debug, PartialEq, Serialize, utoipa::ToSchema)]
pub struct ScoreTerms {
    /// how far inside the friction cone the worse contact normal is: 0 on its edge,
    /// 1 exactly antipodal
    pub antipodal: f64,
    /// 1/(1 + k·w/2) for the larger principal curvature k at the contacts and the pad
    /// width w: the contact area's proxy (1 flat, small on sharp edges)
    pub flatness: f64,
    /// 1 - d/size for the distance d of the closing line from the centre of mass: the
    /// moment gravity puts on the grasp
    pub centred: f64,
}

/// One grasp, in the frame of the fit (the camera's for depth frames).
#[derive(Clone, Debug, PartialEq, Serialize, utoipa::ToSchema)]
pub struct Grasp {
    pub kind: GraspKind,
    /// in [0, 1], the weighted sum of `score_terms`
    pub score: f64,
    pub score_terms: ScoreTerms,
    /// midway between the contacts
    #[schema(value_type = Vec<f64>)]
    pub position: [f64; 3],
    /// unit direction the hand moves in to grasp
    #[schema(value_type = Vec<f64>)]
    pub approach: [f64; 3],
    /// unit direction from the first contact to the second
    #[schema(value_type = Vec<f64>)]
    pub closing: [f64; 3],
    /// approach × closing
    #[schema(value_type = Vec<f64>)]
    pub binormal: [f64; 3],
    /// distance between the contacts
    pub width: f64,
    /// the jaws' opening before they close
    pub pregrasp_opening: f64,
    /// how far the fingertips reach past `position` along the approach
    pub tip_reach: f64,
    /// how far the object reaches back from the contact line towards the palm, within
    /// the jaws (at most the finger depth less its tip)
    pub depth: f64,
    /// row-major R with columns (approach, closing, binormal): the hand's frame
    #[schema(value_type = Vec<Vec<f64>>)]
    pub rotation: [[f64; 3]; 3],
    #[schema(value_type = Vec<f64>)]
    pub quaternion_wxyz: [f64; 4],
    #[schema(value_type = Vec<Vec<f64>>)]
    pub contacts: [[f64; 3]; 2],
    /// the fitted surface's outward normals at the contacts
    #[schema(value_type = Vec<Vec<f64>>)]
    pub normals: [[f64; 3]; 2],
}

/// Why candidates were dropped.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, utoipa::ToSchema)]
pub struct Rejections {
    pub opening: usize,
    pub friction: usize,
    pub collision: usize,
    pub plane: usize,
    pub behind: usize,
}

#[derive(Clone, Debug, PartialEq, Serialize, utoipa::ToSchema)]
pub struct GraspPlan {
    /// best first, at most `max_grasps`
    pub grasps: Vec<Grasp>,
    pub candidates: usize,
    pub rejected: Rejections,
}

/// A candidate before it is checked: contact parameters and the approach, canonical.
struct Candidate {
    kind: GraspKind,
    contacts: [(f64, f64); 2],
    approach: DVec3,
}

pub fn validate(request: &GraspRequest) -> Result<(), String> {
    request.shape.validate()?;
    request.gripper.validate()?;
    if !(request.friction.is_finite() && request.friction > 0.0) {
        return Err(format!(
            "friction must be positive and finite, got {}",
            request.friction
        ));
    }
    if let Some(v) = request.viewpoint
        && !v.is_finite()
    {
        return Err(format!("viewpoint must be finite, got {v:?}"));
    }
    Ok(())
}

fn candidates(shape: &Shape) -> Vec<Candidate> {
    let mut out = Vec::new();
    let horizontal = |omega: f64| DVec3::new(omega.cos(), omega.sin(), 0.0);
    if shape.has_hole() {
        for k in 0..PINCHES_AROUND {
            let omega = TAU * k as f64 / PINCHES_AROUND as f64;
            // the mean superellipse's outward direction and tangent at omega
            let m = crate::model::mean_superellipse_point(shape, omega);
            let outward = DVec3::new(m[0], m[1], 0.0).normalize();
            let along = DVec3::Z.cross(outward);
            for approach in [-outward, along, -along] {
                out.push(Candidate {
                    kind: GraspKind::SectionHeight,
                    contacts: [(-FRAC_PI_2, omega), (FRAC_PI_2, omega)],
                    approach,
                });
            }
            for approach in [-DVec3::Z, DVec3::Z] {
                out.push(Candidate {
                    kind: GraspKind::SectionWidth,
                    contacts: [(PI, omega), (0.0, omega)],
                    approach,
                });
            }
            if let Some(eta) = face_square_eta(shape, omega) {
                for eta in [eta, PI - eta] {
                    for approach in [-outward, along, -along] {
                        out.push(Candidate {
                            kind: GraspKind::SectionDiagonal,
                            contacts: [(eta - PI, omega), (eta, omega)],
                            approach,
                        });
                    }
                }
            }
        }
    }
    for k in 0..BODY_DIRECTIONS {
        let omega = PI * k as f64 / BODY_DIRECTIONS as f64;
        let across = horizontal(omega);
        let side = DVec3::Z.cross(across);
        for approach in [-DVec3::Z, DVec3::Z, side, -side] {
            out.push(Candidate {
                kind: GraspKind::AcrossBody,
                contacts: [(0.0, omega + PI), (0.0, omega)],
                approach,
            });
        }
    }
    if !shape.has_hole() {
        let top = shape.eta_range().min(FRAC_PI_2);
        for k in 0..SIDE_APPROACHES {
            let omega = TAU * k as f64 / SIDE_APPROACHES as f64;
            out.push(Candidate {
                kind: GraspKind::AlongAxis,
                contacts: [(-top, 0.0), (top, 0.0)],
                approach: horizontal(omega),
            });
        }
    }
    out
}

/// Below this eps1 the section has no faces to pinch between its tips.
const PINCHED_SECTION: f64 = 1.1;

/// The section angle in (0, pi/2) of a pinched section's face point whose radius from
/// the section's centre is along its normal, or None for a section that is not pinched.
/// The section at omega is the superellipse (r cos^e1 eta, a3 sin^e1 eta) with r the
/// mean superellipse's direction scale (eq. 2); its normal is along
/// (cos^(2-e1) eta / r, sin^(2-e1) eta / a3), parallel to the point where
/// tan^(2 e1 - 2) eta = (r / a3)^2. The points at eta and eta + pi are then antipodal.
fn face_square_eta(shape: &Shape, omega: f64) -> Option<f64> {
    if shape.eps1 < PINCHED_SECTION {
        return None;
    }
    let [x, y] = crate::model::mean_superellipse_point(shape, omega);
    let r = x.hypot(y) / shape.a4;
    Some((r / shape.a3).powf(1.0 / (shape.eps1 - 1.0)).atan())
}

enum Verdict {
    Keep(Grasp),
    Drop(fn(&mut Rejections) -> &mut usize),
}

/// Plans, checks and ranks the grasps of one object.
pub fn plan(request: &GraspRequest) -> Result<GraspPlan, String> {
    validate(request)?;
    let GraspRequest { shape, pose, .. } = *request;
    let cells = SurfaceCells::new(&shape, &pose, &request.gripper);
    let all = candidates(&shape);
    let mut rejected = Rejections::default();
    let mut kept = Vec::new();
    // candidates are independent: checked in parallel, collected in their order
    let verdicts: Vec<Result<Verdict, String>> = all
        .par_iter()
        .map(|candidate| check(request, candidate, &cells))
        .collect();
    for verdict in verdicts {
        match verdict? {
            Verdict::Keep(g) => kept.push(g),
            Verdict::Drop(field) => *field(&mut rejected) += 1,
        }
    }
    // stable: equal scores keep the candidates' order
    kept.sort_by(|a, b| b.score.total_cmp(&a.score));
    kept.truncate(request.max_grasps);
    Ok(GraspPlan {
        grasps: kept,
        candidates: all.len(),
        rejected,
    })
}

fn check(
    request: &GraspRequest,
    candidate: &Candidate,
    cells: &SurfaceCells,
) -> Result<Verdict, String> {
    let GraspRequest {
        shape,
        pose,
        gripper,
        ..
    } = *request;
    let [c1, c2]: [SurfacePoint; 2] = [
        at_parameters(
            &shape,
            &pose,
            candidate.contacts[0].0,
            candidate.contacts[0].1,
        )?,
        at_parameters(
            &shape,
            &pose,
            candidate.contacts[1].0,
            candidate.contacts[1].1,
        )?,
    ];
    let (p1, p2) = (DVec3::from_array(c1.point), DVec3::from_array(c2.point));
    let width = p1.distance(p2);
    if !gripper.fits(width) {
        return Ok(Verdict::Drop(|r| &mut r.opening));
    }
    let closing = (p2 - p1) / width;
    let cone_cos = 1.0 / (1.0 + request.friction * request.friction).sqrt();
    // the worse contact's normal over its pad, not only at its centre: a contact on a
    // rounded edge that a small error of the fit moves off is not antipodal
    let pad_reach = PAD_REACH * gripper.finger_width.min(shape.thinnest_half_axis());
    let worse = pad_alignment(&shape, &pose, candidate.contacts[0], -closing, pad_reach).min(
        pad_alignment(&shape, &pose, candidate.contacts[1], closing, pad_reach),
    );
    if !(worse >= cone_cos) {
        return Ok(Verdict::Drop(|r| &mut r.friction));
    }
    let approach = (pose.rotation * candidate.approach)
        .reject_from_normalized(closing)
        .normalize();
    let frame = GraspFrame {
        position: (p1 + p2) / 2.0,
        approach,
        closing,
        binormal: approach.cross(closing),
    };
    if let Some(camera) = request.viewpoint {
        let towards_camera = (camera - frame.position).normalize_or_zero();
        if approach.dot(towards_camera) > BEHIND_COSINE {
            return Ok(Verdict::Drop(|r| &mut r.behind));
        }
    }
    // every surface point lies within 2·size of the contacts' midpoint
    let sweep = 2.0 * shape.size();
    let mut verdict = None;
    for posture in &POSTURES {
        let opening = gripper.pregrasp_opening(width, posture);
        let tip = posture.tip * gripper.finger_depth;
        let boxes = hand_boxes(&gripper, opening, tip, sweep);
        match hand_is_free(&boxes, &frame, cells, request.plane.as_ref()) {
            Ok(()) => {
                let depth = cells.reach_behind(&frame, opening, gripper.finger_width);
                verdict = Some(Ok((opening, tip, depth)));
                break;
            }
            Err(drop) => verdict = Some(Err(drop)),
        }
    }
    let (opening, tip, depth) = match verdict.expect("at least one posture") {
        Ok(free) => free,
        Err(drop) => return Ok(Verdict::Drop(drop)),
    };
    let pad = gripper.finger_width / 2.0;
    let sharpest = |s: &SurfacePoint| s.curvatures[0].abs().max(s.curvatures[1].abs());
    let terms = ScoreTerms {
        antipodal: ((worse - cone_cos) / (1.0 - cone_cos)).clamp(0.0, 1.0),
        flatness: 1.0 / (1.0 + sharpest(&c1).max(sharpest(&c2)) * pad),
        centred: {
            let offset = (pose.translation - frame.position).reject_from_normalized(closing);
            1.0 - (offset.length() / shape.size()).min(1.0)
        },
    };
    let [wa, wf, wc] = SCORE_WEIGHTS;
    let rotation = DMat3::from_cols(frame.approach, frame.closing, frame.binormal);
    let q = DQuat::from_mat3(&rotation).normalize();
    let rows = rotation.transpose().to_cols_array_2d();
    Ok(Verdict::Keep(Grasp {
        kind: candidate.kind,
        score: wa * terms.antipodal + wf * terms.flatness + wc * terms.centred,
        score_terms: terms,
        position: frame.position.to_array(),
        approach: frame.approach.to_array(),
        closing: frame.closing.to_array(),
        binormal: frame.binormal.to_array(),
        width,
        pregrasp_opening: opening,
        tip_reach: tip,
        depth,
        rotation: rows,
        quaternion_wxyz: [q.w, q.x, q.y, q.z],
        contacts: [c1.point, c2.point],
        normals: [c1.normal, c2.normal],
    }))
}

/// The least cosine between the outward normal and `outward` at a contact and at the
/// four surface points `reach` away from it along the parameter curves; NaN-safe (a
/// normal that is not finite gives -1).
fn pad_alignment(
    shape: &Shape,
    pose: &Pose,
    (eta, omega): (f64, f64),
    outward: DVec3,
    reach: f64,
) -> f64 {
    let jet = crate::model::surface_jet(shape, eta + 1e-3, omega + 1e-3);
    let d_eta = reach / jet.r_eta.length().max(1e-300);
    let d_omega = reach / jet.r_omega.length().max(1e-300);
    let (d_eta, d_omega) = (d_eta.min(0.5), d_omega.min(0.5));
    let mut least: f64 = 1.0;
    for (de, dom) in [
        (0.0, 0.0),
        (d_eta, 0.0),
        (-d_eta, 0.0),
        (0.0, d_omega),
        (0.0, -d_omega),
    ] {
        let e = if shape.a4 < 1.0 {
            (eta + de).clamp(-shape.eta_range(), shape.eta_range())
        } else {
            eta + de
        };
        let c = match at_parameters(shape, pose, e, omega + dom) {
            Ok(p) => DVec3::from_array(p.normal).dot(outward),
            Err(_) => -1.0,
        };
        least = least.min(if c.is_finite() { c } else { -1.0 });
    }
    least
}

/// Where the hand in a posture meets the surface or goes below the plane, the
/// rejection it counts as.
fn hand_is_free(
    boxes: &[FrameBox; 3],
    frame: &GraspFrame,
    cells: &SurfaceCells,
    plane: Option<&Plane>,
) -> Result<(), fn(&mut Rejections) -> &mut usize> {
    // the plane first: 24 corners against thousands of surface nodes
    if let Some(plane) = plane {
        let below = boxes
            .iter()
            .flat_map(|b| b.corners())
            .any(|c| plane.signed_distance(frame.world(c)) < 0.0);
        if below {
            return Err(|r| &mut r.plane);
        }
    }
    if cells.meets(boxes, frame) {
        return Err(|r| &mut r.collision);
    }
    Ok(())
}

/// The 17 numbers of a GraspNet-1Billion row: score, width, height (the pad's width),
/// depth (the fingertips' reach past `position`), the rotation (row-major, columns
/// approach, closing, binormal), translation, object id.
pub fn graspnet_row(grasp: &Grasp, gripper: &Gripper, object_id: usize) -> [f64; 17] {
    let mut row = [0.0; 17];
    row[0] = grasp.score;
    row[1] = grasp.width;
    row[2] = gripper.finger_width;
    row[3] = grasp.tip_reach;
    for (i, r) in grasp.rotation.iter().enumerate() {
        row[4 + 3 * i..7 + 3 * i].copy_from_slice(r);
    }
    row[13..16].copy_from_slice(&grasp.position);
    row[16] = object_id as f64;
    row
}

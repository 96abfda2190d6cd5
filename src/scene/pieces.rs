//! Pieces of one object that the clustering split apart, joined again after the fits.
//!
//! Clustering by distance splits an object whose visible surface has a gap wider than the
//! clustering's: a ring seen at a slant shows two arcs with its hole between them, and a
//! strip of its inner wall may stand apart. Each piece is then fitted alone and answered
//! as an object of its own (or refused as a bare plane): an object made up. After the
//! fits, a segment whose points lie on another, larger object's fitted surface is a piece
//! of that object: its pixels and points join it, and its fit goes (the larger fit
//! already passes through its points).

use super::objects::Segment;
use crate::fit::FitReport;
use crate::model::meridian_distance;

/// A segment is a piece of another object when at least this share of its points lie on
/// that object's fit. On `bench scenes`' frames the pieces of a split ring show 0.94-1.00
/// on its fit, and no two distinct objects over 0.16.
pub const PIECE_SHARE: f64 = 0.8;
/// A point lies on a fit within this many of the fit's noise sigmas ...
pub const PIECE_SIGMAS: f64 = 3.0;
/// ... or within this share of the fit's size, whichever is wider (a noise-free fit).
pub const PIECE_SIZE_SHARE: f64 = 0.02;
/// The most points of a segment tested (an even stride through them).
const TESTED_POINTS: usize = 500;

/// The segments with their fits, every piece of an object joined to it (see the module
/// docs), in their order.
pub fn join_pieces<E>(
    segments: Vec<Segment>,
    fits: Vec<Result<FitReport, E>>,
) -> (Vec<Segment>, Vec<Result<FitReport, E>>) {
    // larger first: an object is known to be no piece before its own pieces are sought
    let mut order: Vec<usize> = (0..segments.len()).collect();
    order.sort_by_key(|&i| std::cmp::Reverse(segments[i].points.len()));
    let mut owner: Vec<Option<usize>> = vec![None; segments.len()];
    for (rank, &b) in order.iter().enumerate() {
        let piece = &segments[b].points;
        owner[b] = order[..rank].iter().copied().find(|&a| {
            owner[a].is_none()
                && segments[a].points.len() > piece.len()
                && fits[a]
                    .as_ref()
                    .is_ok_and(|fit| share_on(fit, piece) >= PIECE_SHARE)
        });
    }
    let mut joined: Vec<(Segment, Result<FitReport, E>)> = Vec::new();
    let mut index = vec![usize::MAX; segments.len()];
    let mut pieces: Vec<(usize, Segment)> = Vec::new();
    for (i, (segment, fit)) in segments.into_iter().zip(fits).enumerate() {
        match owner[i] {
            Some(a) => pieces.push((a, segment)),
            None => {
                index[i] = joined.len();
                joined.push((segment, fit));
            }
        }
    }
    for (a, piece) in pieces {
        let (segment, _) = &mut joined[index[a]];
        segment.points.extend(piece.points);
        segment.pixels.extend(piece.pixels);
        segment.seen_through.extend(piece.seen_through);
    }
    joined.into_iter().unzip()
}

/// The share of `points` (an even stride of at most [`TESTED_POINTS`]) on `fit`'s surface.
fn share_on(fit: &FitReport, points: &[glam::DVec3]) -> f64 {
    let (shape, pose) = &fit.fitted;
    let within = (PIECE_SIGMAS * fit.quality.noise_sigma).max(PIECE_SIZE_SHARE * shape.size());
    let tested: Vec<_> = points
        .iter()
        .step_by(points.len().div_ceil(TESTED_POINTS).max(1))
        .collect();
    let on = tested
        .iter()
        .filter(|p| meridian_distance(shape, pose.to_canonical(***p)).distance <= within)
        .count();
    on as f64 / tested.len().max(1) as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::CpuEvaluator;
    use crate::fit::{FitOptions, fit};
    use crate::model::{Pose, Shape};
    use glam::{DQuat, DVec3};

    fn segment(points: Vec<DVec3>) -> Segment {
        let pixels = (0..points.len() as u32).map(|i| (i, 0)).collect();
        Segment {
            points,
            pixels,
            seen_through: Vec::new(),
        }
    }

    /// A ring's points split in two (an arc of a third apart) and a box beside it, given
    /// smallest first: the ring's third lies on the fit of the rest and joins it, refused
    /// or not; the box, on no other fit, stays; the order stays.
    #[test]
    fn a_piece_on_a_larger_objects_fit_joins_it_and_another_object_does_not() {
        let mut rng = crate::synth::rng(4);
        let ring = Shape::new(0.04, 0.04, 0.01, 2.0, 1.0, 1.0);
        let mut points = crate::synth::sample_surface(&ring, &Pose::default(), 3000, &mut rng);
        crate::synth::add_noise(&mut points, 0.0003, &mut rng);
        // (by polar angle: the piece is one arc of the ring)
        let (piece, rest): (Vec<DVec3>, Vec<DVec3>) =
            points.into_iter().partition(|p| p.y.atan2(p.x) > 1.2);
        let box_shape = Shape::new(0.03, 0.02, 0.04, 0.0, 0.3, 0.3);
        let beside = Pose::new(DQuat::IDENTITY, DVec3::new(0.3, 0.0, 0.0));
        let boxed = crate::synth::sample_surface(&box_shape, &beside, 1500, &mut rng);
        let mut evaluator = CpuEvaluator::new();
        let mut fitted = |points: &[DVec3]| fit(&mut evaluator, points, &FitOptions::default());
        let fits = vec![
            Err(()),
            fitted(&boxed).map_err(|_| ()),
            fitted(&rest).map_err(|_| ()),
        ];
        assert!(fits[1].is_ok() && fits[2].is_ok());
        let sizes = [piece.len(), boxed.len(), rest.len()];
        assert!(sizes[0] < sizes[1] && sizes[1] < sizes[2], "{sizes:?}");
        let (joined, fits) = join_pieces(vec![segment(piece), segment(boxed), segment(rest)], fits);
        let counts: Vec<usize> = joined.iter().map(|s| s.points.len()).collect();
        assert_eq!(counts, vec![sizes[1], sizes[0] + sizes[2]]);
        assert_eq!(joined[1].pixels.len(), sizes[0] + sizes[2]);
        assert!(fits.iter().all(|f| f.is_ok()));
    }
}

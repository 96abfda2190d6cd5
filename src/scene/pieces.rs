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
    let mut owner: Vec<Option<usize>> = vec![None; segments.len()];
    for (b, piece) in segments.iter().enumerate() {
        owner[b] = (0..segments.len()).find(|&a| {
            a != b
                && owner[a].is_none()
                && segments[a].points.len() > piece.points.len()
                && fits[a]
                    .as_ref()
                    .is_ok_and(|fit| share_on(fit, &piece.points) >= PIECE_SHARE)
        });
    }
    let mut joined: Vec<(Segment, Result<FitReport, E>)> = Vec::new();
    let mut index = vec![usize::MAX; segments.len()];
    let pieces: Vec<(usize, Segment)> = segments
        .into_iter()
        .zip(fits)
        .enumerate()
        .filter_map(|(i, (segment, fit))| match owner[i] {
            Some(a) => Some((a, segment)),
            None => {
                index[i] = joined.len();
                joined.push((segment, fit));
                None
            }
        })
        .collect();
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

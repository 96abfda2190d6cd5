//! Viewpoints the fit inferred rather than was given ([`super::Viewpoint::Auto`] resolved
//! to the frame's origin), and the clouds with their resolved options.

use super::{FitOptions, Viewpoint, ViewpointSource, ViewpointUsed};
use crate::eval::Normalization;
use glam::DVec3;

/// The cloud normalised, and an even stride of about `count` of its points in that frame.
pub(super) fn normalised_stride(points: &[DVec3], count: usize) -> (Normalization, Vec<DVec3>) {
    let norm = Normalization::of(points);
    let sample = points
        .iter()
        .step_by(points.len().div_ceil(count).max(1))
        .map(|p| norm.point(*p))
        .collect();
    (norm, sample)
}

/// Whether `options` hold a viewpoint that was only inferred ([`Viewpoint::Auto`]
/// resolved to the frame's origin).
pub(super) fn inferred(options: &FitOptions) -> bool {
    matches!(
        options.viewpoint,
        Viewpoint::At(_, ViewpointSource::FrameOrigin)
    )
}

/// The clouds with their resolved options.
pub(super) fn with_resolved<'a>(
    clouds: &[(&'a [DVec3], &FitOptions)],
    resolved: &'a [(FitOptions, ViewpointUsed)],
) -> Vec<(&'a [DVec3], &'a FitOptions)> {
    clouds
        .iter()
        .zip(resolved)
        .map(|((points, _), (o, _))| (*points, o))
        .collect()
}

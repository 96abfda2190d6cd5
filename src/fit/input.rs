//! The cloud as the fit takes it in: the checks every cloud must pass (finite, enough
//! points, extent in three directions), its principal axes, and a large cloud thinned
//! and its stray points set aside ([`isolated`]) before the screen and the fit see it.

use super::*;

/// Fewest points a fit accepts.
pub const MIN_POINTS: usize = 20;

#[derive(Clone, Debug, thiserror::Error, PartialEq)]
pub enum FitError {
    #[error("too few points: {0} (at least {MIN_POINTS} needed)")]
    TooFewPoints(usize),
    #[error("point {0} has a non-finite coordinate")]
    NonFinite(usize),
    #[error("the cloud is degenerate ({0}): it has no extent in three directions")]
    Degenerate(&'static str),
    #[error("no object found: {0}")]
    NoObject(String),
    #[error("invalid option: {0}")]
    InvalidOption(String),
    #[error("evaluator failed: {0}")]
    Evaluator(String),
}

impl From<EvalError> for FitError {
    fn from(e: EvalError) -> Self {
        FitError::Evaluator(e.to_string())
    }
}

/// Rejects clouds no fit can work on. Returns the principal axes (columns, by decreasing
/// spread) and the standard deviations along them.
pub fn check_cloud(points: &[DVec3]) -> Result<(DMat3, DVec3), FitError> {
    if let Some(i) = points.iter().position(|p| !p.is_finite()) {
        return Err(FitError::NonFinite(i));
    }
    if points.len() < MIN_POINTS {
        return Err(FitError::TooFewPoints(points.len()));
    }
    let (axes, sigma) = principal_axes(points);
    if sigma.x <= 0.0 || sigma.y < 1e-6 * sigma.x {
        return Err(FitError::Degenerate("collinear"));
    }
    if sigma.z < 1e-6 * sigma.x {
        return Err(FitError::Degenerate("planar"));
    }
    Ok((axes, sigma))
}

/// PCA: eigenvectors of the covariance (columns, largest spread first) and the standard
/// deviations along them.
pub fn principal_axes(points: &[DVec3]) -> (DMat3, DVec3) {
    let n = points.len() as f64;
    let mean = points.iter().copied().sum::<DVec3>() / n;
    let mut cov = nalgebra::Matrix3::<f64>::zeros();
    for p in points {
        let d = *p - mean;
        let v = nalgebra::Vector3::new(d.x, d.y, d.z);
        cov += v * v.transpose();
    }
    cov /= n;
    let eig = cov.symmetric_eigen();
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    let col = |i: usize| {
        DVec3::new(
            eig.eigenvectors[(0, i)],
            eig.eigenvectors[(1, i)],
            eig.eigenvectors[(2, i)],
        )
    };
    let axes = DMat3::from_cols(col(order[0]), col(order[1]), col(order[2]));
    let sigma = DVec3::new(
        eig.eigenvalues[order[0]].max(0.0).sqrt(),
        eig.eigenvalues[order[1]].max(0.0).sqrt(),
        eig.eigenvalues[order[2]].max(0.0).sqrt(),
    );
    (axes, sigma)
}

/// The most points of a cloud the fit reads: a larger one (a depth mask's tens of
/// thousands) is thinned to an even stride of at most this many. The search samples a
/// few thousand of them and the report [`report::QUALITY_SAMPLE`]; the rest would cost
/// the screening, the setting aside of isolated points and the preparation their time
/// and tell the fit nothing.
pub const MAX_FIT_POINTS: usize = 16_000;

/// An even stride of at most [`MAX_FIT_POINTS`] of `points`; None where they are fewer.
pub(super) fn thinned(points: &[DVec3]) -> Option<Vec<DVec3>> {
    (points.len() > MAX_FIT_POINTS).then(|| {
        let stride = points.len().div_ceil(MAX_FIT_POINTS);
        points.iter().step_by(stride).copied().collect()
    })
}

/// A cloud as the screen and the fit see it: thinned where large ([`thinned`]), its
/// points far from every other set aside ([`isolated`]).
pub(super) struct Cleaned {
    /// the points kept; None where they are the input's
    pub kept: Option<Vec<DVec3>>,
    /// the points read: the input's, or the stride thinned to
    pub read: usize,
    /// the time the setting aside took, where it ran
    pub isolated_ms: Option<f64>,
}

/// [`Cleaned`] for one cloud.
pub(super) fn cleaned(points: &[DVec3], o: &FitOptions) -> Cleaned {
    // (the paper's procedure is the baseline as published: it keeps every point)
    if o.method == Method::Paper {
        return Cleaned {
            kept: None,
            read: points.len(),
            isolated_ms: None,
        };
    }
    let thinned = thinned(points);
    let read = thinned.as_ref().map_or(points.len(), Vec::len);
    if o.skip.contains(&Stage::SetAsideIsolatedPoints) {
        return Cleaned {
            kept: thinned,
            read,
            isolated_ms: None,
        };
    }
    let start = Instant::now();
    let kept = isolated::without_isolated(thinned.as_deref().unwrap_or(points));
    Cleaned {
        kept: kept.or(thinned),
        read,
        isolated_ms: Some(start.elapsed().as_secs_f64() * 1e3),
    }
}

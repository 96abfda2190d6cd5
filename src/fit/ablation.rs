//! The fit's optional stages by name, so that each can be left out and what it gains be
//! measured against what it costs (`supertoroid bench ablation`, `bench synthetic
//! --skip STAGE,...`; the table in `docs/fit.md`). Leaving one out changes no other
//! stage.

/// A stage of [`super::fit_batch`] that a fit may run without.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Stage {
    /// the Cauchy-loss refinement of the chosen least-squares fit (`refine_robustly`)
    RobustRefine,
    /// the noise model's second reading of the top view (`refine_both_readings`)
    DualReading,
    /// an inferred viewpoint tested against an all-round cloud (`settle_inferred_viewpoints`)
    SettleInferredView,
    /// a given viewpoint the fit contradicts refitted without it
    /// (`refit_without_inconsistent_viewpoints`)
    InconsistentViewpoint,
    /// views without an open hole refitted with axes across the line of sight
    /// (`retry_across_line_of_sight`)
    AcrossLineOfSight,
    /// other downsampling seeds for a bare, off-scatter or eps-pinned fit
    /// (`retry_unseen_surfaces`)
    UnseenSurfaceRetries,
    /// more seeds where those leave it so (`retry_lasting_misfits`)
    LastingMisfitRetries,
    /// the noise model once more on up to 4000 points (`polish_on_more_points`)
    PolishOnMorePoints,
}

/// Whether every cloud of a batch leaves `stage` out (a check of the finished fits runs
/// on the batch as a whole).
pub fn all_skip(clouds: &[(&[glam::DVec3], &super::FitOptions)], stage: Stage) -> bool {
    !clouds.is_empty() && clouds.iter().all(|(_, o)| o.skip.contains(&stage))
}

/// The stage's name (as `--skip` takes it and `timing_ms.checks` reports it).
pub fn name(stage: Stage) -> String {
    use clap::ValueEnum;
    stage
        .to_possible_value()
        .map_or_else(|| format!("{stage:?}"), |v| v.get_name().to_owned())
}

//! The fit's optional stages by name, so that each can be left out and what it gains be
//! measured against what it costs (`supertoroid bench ablation`, `bench synthetic
//! --skip STAGE,...`; the table in `docs/fit.md`). Leaving one out changes no other
//! stage.

/// A stage of [`super::fit_batch`] that a fit may run without.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Stage {
    /// the Cauchy-loss refinement of a precise cloud's least-squares candidates
    /// (`robust_least_squares` in [`super::search`])
    RobustRefine,
    /// the other reading of the top view, in the search and in the polish
    /// ([`super::prepare`]'s `turned_dual`)
    DualReading,
    /// a closed body's hollow reading (the same outline around a through hole) in the
    /// search ([`super::prepare`]'s `hollowed`)
    HollowedReading,
    /// the rings a closed fit may lie across (its outline's axes cycled around a hole) in
    /// the search ([`super::prepare`]'s `rings_across`)
    RingsAcross,
    /// a cloud whose viewpoint was only inferred searched as a view from nowhere too, the
    /// likelier reading kept ([`super::search::batch`])
    SettleInferredView,
    /// a given viewpoint the fit contradicts dropped, the cloud searched again without it
    InconsistentViewpoint,
    /// a view's least-squares fit, where its points show noise, converged by the
    /// likelihood and standing in its place (the search's finalists)
    ViewLikelihood,
    /// the noise model once more on up to 4000 points ([`super::search::polish`])
    PolishOnMorePoints,
    /// points far from every other set aside before the fit ([`super::isolated`])
    SetAsideIsolatedPoints,
}

/// The stage's name (as `--skip` takes it and `timing_ms.over_budget` reports it).
pub fn name(stage: Stage) -> String {
    use clap::ValueEnum;
    stage
        .to_possible_value()
        .map_or_else(|| format!("{stage:?}"), |v| v.get_name().to_owned())
}

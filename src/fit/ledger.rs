//! Where a fit's time went in the checks of the finished fit, and which checks its time
//! budget left out ([`super::FitOptions::time_budget_ms`]).

use super::*;

/// Each cloud's time in the checks of its finished fit, by check: what its total grew
/// by while the check ran (a check charges its time to the fits it looked at).
pub(super) struct CheckLedger {
    pub(super) totals: Vec<f64>,
    pub(super) checks: Vec<std::collections::BTreeMap<String, f64>>,
    /// per cloud, the checks its time budget left out
    pub(super) over_budget: Vec<Vec<String>>,
}

/// The fits a check does not see (over their time budget), taken out of the results.
pub(super) struct Parked(Vec<(usize, Result<FitReport, FitError>)>);

impl CheckLedger {
    pub(super) fn new(results: &[Result<FitReport, FitError>]) -> Self {
        Self {
            totals: Self::totals(results),
            checks: vec![Default::default(); results.len()],
            over_budget: vec![Vec::new(); results.len()],
        }
    }

    /// Takes the fits over their time budget out of `results` before `stage` runs (a
    /// check passes over errors), noting that it did not run for them.
    pub(super) fn park(
        &mut self,
        stage: Stage,
        clouds: &[(&[DVec3], &FitOptions)],
        results: &mut [Result<FitReport, FitError>],
    ) -> Parked {
        let mut parked = Vec::new();
        for (i, ((_, o), r)) in clouds.iter().zip(results.iter_mut()).enumerate() {
            if let (Ok(fit), Some(budget)) = (r.as_ref(), o.time_budget_ms)
                && fit.timing_ms.total >= budget
            {
                // (a placeholder the check skips; `unpark` puts the fit back)
                let fit = std::mem::replace(r, Err(FitError::InvalidOption(String::new())));
                parked.push((i, fit));
                self.over_budget[i].push(ablation::name(stage));
            }
        }
        Parked(parked)
    }

    pub(super) fn unpark(parked: Parked, results: &mut [Result<FitReport, FitError>]) {
        for (i, fit) in parked.0 {
            results[i] = fit;
        }
    }

    pub(super) fn totals(results: &[Result<FitReport, FitError>]) -> Vec<f64> {
        results
            .iter()
            .map(|r| r.as_ref().map_or(0.0, |r| r.timing_ms.total))
            .collect()
    }

    pub(super) fn record(&mut self, stage: Stage, results: &[Result<FitReport, FitError>]) {
        self.record_as(&ablation::name(stage), results);
    }

    pub(super) fn record_as(&mut self, name: &str, results: &[Result<FitReport, FitError>]) {
        let now = Self::totals(results);
        for (i, (&after, before)) in now.iter().zip(&self.totals).enumerate() {
            if after > *before {
                *self.checks[i].entry(name.to_owned()).or_default() += after - before;
            }
        }
        self.totals = now;
    }
}

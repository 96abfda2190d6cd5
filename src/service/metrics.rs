//! Prometheus metrics (text exposition at `GET /metrics`), through prometheus-client.

use prometheus_client::encoding::EncodeLabelSet;
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::metrics::histogram::{Histogram, exponential_buckets};
use prometheus_client::registry::Registry;

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
pub struct RouteStatus {
    pub route: String,
    pub status: u16,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
pub struct RouteLabel {
    pub route: String,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
pub struct StageLabel {
    pub stage: String,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
pub struct CodeLabel {
    pub code: String,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
pub struct WarningLabel {
    pub kind: String,
}

pub struct Metrics {
    registry: Registry,
    pub requests: Family<RouteStatus, Counter>,
    pub latency: Family<RouteLabel, Histogram>,
    pub stage_seconds: Family<StageLabel, Histogram>,
    pub points: Histogram,
    pub queue_depth: Gauge,
    pub errors: Family<CodeLabel, Counter>,
    pub warnings: Family<WarningLabel, Counter>,
}

impl Default for Metrics {
    fn default() -> Self {
        Self::new()
    }
}

impl Metrics {
    pub fn new() -> Self {
        let mut registry = Registry::with_prefix("supertoroid");
        let requests = Family::<RouteStatus, Counter>::default();
        let latency = Family::<RouteLabel, Histogram>::new_with_constructor(|| {
            Histogram::new(exponential_buckets(0.001, 2.0, 16))
        });
        let stage_seconds = Family::<StageLabel, Histogram>::new_with_constructor(|| {
            Histogram::new(exponential_buckets(0.0005, 2.0, 16))
        });
        let points = Histogram::new(exponential_buckets(16.0, 4.0, 10));
        let queue_depth = Gauge::default();
        let errors = Family::<CodeLabel, Counter>::default();
        let warnings = Family::<WarningLabel, Counter>::default();
        registry.register(
            "http_requests",
            "HTTP requests by route and status",
            requests.clone(),
        );
        registry.register(
            "http_request_duration_seconds",
            "HTTP request latency by route",
            latency.clone(),
        );
        registry.register(
            "fit_stage_duration_seconds",
            "Fit time by stage (stage1, stage2, total)",
            stage_seconds.clone(),
        );
        registry.register(
            "fit_input_points",
            "Points per fitted cloud",
            points.clone(),
        );
        registry.register(
            "queue_depth",
            "Requests waiting for a fit worker",
            queue_depth.clone(),
        );
        registry.register("errors", "Error responses by code", errors.clone());
        registry.register(
            "fit_warnings",
            "Fits that carried a warning, by kind (uncertain_shape, off_its_points, \
             viewpoint_ignored, off_a_precise_cloud): a rising rate is a sensor or set-up to \
             look at",
            warnings.clone(),
        );
        Self {
            registry,
            requests,
            latency,
            stage_seconds,
            points,
            queue_depth,
            errors,
            warnings,
        }
    }

    pub fn record_fit(&self, report: &crate::fit::FitReport) {
        let t = &report.timing_ms;
        let stages = [
            ("stage1", t.stage1),
            ("stage2", t.stage2),
            ("noise_model", t.noise_model),
            ("total", t.total),
        ];
        let later = t.stages.iter().map(|(name, ms)| (name.as_str(), *ms));
        for (stage, ms) in stages.into_iter().chain(later) {
            self.stage_seconds
                .get_or_create(&StageLabel {
                    stage: stage.into(),
                })
                .observe(ms / 1e3);
        }
        self.points.observe(report.points.input as f64);
        for warning in &report.warnings {
            self.warnings
                .get_or_create(&WarningLabel {
                    kind: warning_kind(warning),
                })
                .inc();
        }
    }

    pub fn encode(&self) -> String {
        let mut out = String::new();
        let _ = prometheus_client::encoding::text::encode(&mut out, &self.registry);
        out
    }
}

/// A warning's kind for the metrics label: its documented prefix (the text before the
/// first colon) in snake case, e.g. "unseen surface: ..." -> `unseen_surface`.
fn warning_kind(warning: &str) -> String {
    warning
        .split(':')
        .next()
        .unwrap_or(warning)
        .trim()
        .replace(' ', "_")
}

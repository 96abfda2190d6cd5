//! Service settings. Every flag also reads a `SUPERTOROID_*` environment variable, so a
//! compose file can configure the container without a command line.

use crate::eval::Backend;
use clap::Args;
use std::net::SocketAddr;

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum LogFormat {
    Text,
    Json,
}

#[derive(Args, Clone, Debug)]
pub struct ServiceConfig {
    /// address to listen on
    #[arg(long, env = "SUPERTOROID_BIND", default_value = "127.0.0.1:8080")]
    pub bind: SocketAddr,
    /// evaluator: auto (a hardware GPU when found, else the f64 CPU), gpu (any adapter,
    /// lavapipe included), cpu
    #[arg(long, env = "SUPERTOROID_BACKEND", value_enum, default_value = "auto")]
    pub backend: Backend,
    /// largest request body in bytes (413 beyond)
    #[arg(long, env = "SUPERTOROID_BODY_LIMIT", default_value_t = 64 * 1024 * 1024)]
    pub body_limit: usize,
    /// most points in one cloud or depth frame (413 beyond)
    #[arg(long, env = "SUPERTOROID_MAX_POINTS", default_value_t = 2_000_000)]
    pub max_points: usize,
    /// fits running at once (default: the number of CPU cores)
    #[arg(long, env = "SUPERTOROID_WORKERS")]
    pub workers: Option<usize>,
    /// requests allowed to wait for a worker; more get 503 with Retry-After
    #[arg(long, env = "SUPERTOROID_QUEUE_DEPTH", default_value_t = 64)]
    pub queue_depth: usize,
    /// per-request limit in seconds (504 beyond)
    #[arg(long, env = "SUPERTOROID_REQUEST_TIMEOUT", default_value_t = 30.0)]
    pub request_timeout: f64,
    /// log lines as text or JSON
    #[arg(
        long,
        env = "SUPERTOROID_LOG_FORMAT",
        value_enum,
        default_value = "text"
    )]
    pub log_format: LogFormat,
}

impl ServiceConfig {
    pub fn workers(&self) -> usize {
        self.workers
            .unwrap_or_else(|| std::thread::available_parallelism().map_or(2, |n| n.get()))
            .max(1)
    }

    pub fn validate(&self) -> Result<(), String> {
        if !(self.request_timeout.is_finite() && self.request_timeout > 0.0) {
            return Err("request timeout must be a positive number of seconds".into());
        }
        if self.max_points < crate::fit::MIN_POINTS {
            return Err(format!(
                "max points must be at least {}",
                crate::fit::MIN_POINTS
            ));
        }
        if self.body_limit < 1024 {
            return Err("body limit must be at least 1024 bytes".into());
        }
        Ok(())
    }
}

impl Default for ServiceConfig {
    fn default() -> Self {
        Self {
            bind: "127.0.0.1:8080".parse().unwrap(),
            backend: Backend::Auto,
            body_limit: 64 * 1024 * 1024,
            max_points: 2_000_000,
            workers: None,
            queue_depth: 64,
            request_timeout: 30.0,
            log_format: LogFormat::Text,
        }
    }
}

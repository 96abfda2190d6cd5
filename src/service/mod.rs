//! The HTTP fitting service (`supertoroid serve`): axum on tokio, one shared GPU context,
//! a bounded queue in front of the fit workers, Prometheus metrics, an OpenAPI document.
//!
//! * [`config`]: settings from flags and `SUPERTOROID_*` variables.
//! * [`fitter`]: admission (bounded queue, 503 when full), the workers, the GPU context
//!   and the CPU fallback.
//! * [`api`]: routes, request and response types, content negotiation.
//! * [`geometry`]: routes on a fitted object: surface queries and grasps.
//! * [`scene`]: a table-top frame's objects; [`exports`]: a recent scene's simulator files.
//! * [`error`]: the `{"error": {"code", "message"}}` body every failure carries.
//! * [`metrics`]: the Prometheus registry.

pub mod api;
pub mod config;
pub mod error;
pub mod exports;
pub mod fitter;
pub mod geometry;
pub mod metrics;
pub mod openapi;
pub mod scene;

pub use config::ServiceConfig;

use axum::Router;
use std::net::SocketAddr;
use std::sync::Arc;
use tokio::net::TcpListener;

/// Everything a handler needs, shared by all requests.
pub struct AppState {
    pub config: ServiceConfig,
    pub fitter: fitter::Fitter,
    pub metrics: metrics::Metrics,
    /// the last scenes' objects, for their exports
    pub scenes: exports::SceneStore,
}

/// Builds the state (starts the GPU context when the backend asks for one) and the router.
pub fn app(config: ServiceConfig) -> (Router, Arc<AppState>) {
    let fitter = fitter::Fitter::new(&config);
    let state = Arc::new(AppState {
        fitter,
        metrics: metrics::Metrics::new(),
        scenes: exports::SceneStore::default(),
        config,
    });
    (api::router(state.clone()), state)
}

/// Runs the service until SIGTERM or Ctrl-C; in-flight requests finish first.
pub async fn serve(config: ServiceConfig) -> anyhow::Result<()> {
    let bind: SocketAddr = config.bind;
    let (router, state) = app(config);
    let listener = TcpListener::bind(bind).await?;
    tracing::info!(
        address = %listener.local_addr()?,
        backend = %state.fitter.describe(),
        "supertoroid service listening"
    );
    axum::serve(listener, router)
        .with_graceful_shutdown(shutdown_signal())
        .await?;
    tracing::info!("shut down");
    Ok(())
}

/// Serves on an already bound listener (tests bind 127.0.0.1:0) until `stop` resolves.
pub async fn serve_on(
    listener: TcpListener,
    config: ServiceConfig,
    stop: impl std::future::Future<Output = ()> + Send + 'static,
) -> anyhow::Result<()> {
    let (router, _) = app(config);
    axum::serve(listener, router)
        .with_graceful_shutdown(stop)
        .await?;
    Ok(())
}

async fn shutdown_signal() {
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    #[cfg(unix)]
    let terminate = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let terminate = std::future::pending::<()>();
    tokio::select! {
        _ = ctrl_c => {},
        _ = terminate => {},
    }
    tracing::info!("signal received, finishing in-flight requests");
}

/// Installs the tracing subscriber: `text` (human) or `json` (one object per line).
pub fn init_logging(format: config::LogFormat) {
    use tracing_subscriber::EnvFilter;
    let filter = EnvFilter::try_from_env("SUPERTOROID_LOG")
        .unwrap_or_else(|_| EnvFilter::new("info,tower_http=info"));
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_target(false);
    let _ = match format {
        config::LogFormat::Json => builder.json().try_init(),
        config::LogFormat::Text => builder.try_init(),
    };
}

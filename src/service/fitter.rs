//! Admission and execution of fits.
//!
//! A request first takes an admission permit (workers + queue depth of them): when none
//! is left the queue is full and the answer is 503 at once, so memory stays bounded
//! whatever the load. It then waits for one of `workers` worker permits and runs on
//! tokio's blocking pool: on every core (rayon's pool) when no other fit is running, else
//! on its own one. Both permits travel into the blocking task, so a fit that
//! outlives its request's timeout still counts until it really ends.
//!
//! One GPU context serves every request (pipelines compiled once); each fit gets its own
//! evaluator on it. When the GPU fails at start or during a fit, the CPU evaluator takes
//! over, the fit is redone on it, and `/readyz` reports the degradation.

use super::config::ServiceConfig;
use super::error::ApiError;
use crate::eval::{
    AdapterChoice, Backend, CpuEvaluator, Evaluator, GpuContext, GpuEvaluator, auto_prefers_gpu,
};
use crate::fit::{FitOptions, FitReport, fit_batch};
use axum::http::StatusCode;
use glam::DVec3;
use serde::Serialize;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::sync::Semaphore;

pub struct Fitter {
    gpu: Option<Arc<GpuContext>>,
    /// the service's `--backend`: what a request that names none gets
    configured: Backend,
    /// why the GPU is not in use, when it is not
    degraded: Arc<Mutex<Option<String>>>,
    admission: Arc<Semaphore>,
    workers: Arc<Semaphore>,
    waiting: Arc<AtomicUsize>,
    worker_count: usize,
    queue_depth: usize,
    timeout: Duration,
}

/// What `/readyz` reports.
#[derive(Serialize, utoipa::ToSchema)]
pub struct Readiness {
    pub ready: bool,
    /// gpu when a GPU is in use (for clouds that ask for it, and under `auto` for those
    /// with large stage-2 samples; the rest fit on the CPU), else cpu
    pub backend: String,
    pub adapter: Option<String>,
    /// why the GPU is not used, when it was wanted
    pub degraded: Option<String>,
    pub workers: usize,
    pub queue_capacity: usize,
    pub queued: usize,
}

/// One cloud to fit, with the evaluator asked for.
pub struct FitJob {
    pub points: Vec<DVec3>,
    pub options: FitOptions,
    pub backend: Backend,
}

impl Fitter {
    pub fn new(config: &ServiceConfig) -> Self {
        let (gpu, degraded) = match config.backend {
            Backend::Cpu => (None, None),
            Backend::Auto | Backend::Gpu => match GpuContext::shared(&AdapterChoice::from_env()) {
                // auto leaves a software adapter alone (see `eval::make_evaluator`)
                Ok(ctx) if config.backend == Backend::Auto && ctx.is_software() => {
                    tracing::info!(adapter = %ctx.adapter_name(), "only a software GPU adapter; auto fits on the CPU");
                    (None, None)
                }
                Ok(ctx) => (Some(ctx), None),
                Err(e) => {
                    tracing::warn!(error = %e, "no GPU adapter; fitting on the CPU");
                    (None, Some(format!("no GPU adapter: {e}")))
                }
            },
        };
        let workers = config.workers();
        Self {
            gpu,
            configured: config.backend,
            degraded: Arc::new(Mutex::new(degraded)),
            admission: Arc::new(Semaphore::new(workers + config.queue_depth)),
            workers: Arc::new(Semaphore::new(workers)),
            waiting: Arc::new(AtomicUsize::new(0)),
            worker_count: workers,
            queue_depth: config.queue_depth,
            timeout: Duration::from_secs_f64(config.request_timeout),
        }
    }

    fn gpu_usable(&self) -> Option<Arc<GpuContext>> {
        let degraded = self.degraded.lock().map(|d| d.is_some()).unwrap_or(true);
        if degraded { None } else { self.gpu.clone() }
    }

    pub fn describe(&self) -> String {
        match self.gpu_usable() {
            Some(ctx) => format!("gpu: {}", ctx.adapter_name()),
            None => "cpu".into(),
        }
    }

    pub fn readiness(&self) -> Readiness {
        let gpu = self.gpu_usable();
        Readiness {
            ready: true,
            backend: if gpu.is_some() { "gpu" } else { "cpu" }.into(),
            adapter: gpu.map(|c| c.adapter_name()),
            degraded: self.degraded.lock().ok().and_then(|d| d.clone()),
            workers: self.worker_count,
            queue_capacity: self.queue_depth,
            queued: self.queued(),
        }
    }

    pub fn queued(&self) -> usize {
        self.waiting.load(Ordering::Relaxed)
    }

    /// Runs the jobs (one request's clouds) on one worker, fitted together (one lockstep
    /// batch per evaluator); each result is the fit or the reason it failed. Err is for
    /// the request as a whole: queue full, timeout, or the GPU asked for and not available.
    pub async fn run(
        &self,
        mut jobs: Vec<FitJob>,
    ) -> Result<Vec<Result<FitReport, ApiError>>, ApiError> {
        let admission = self
            .admission
            .clone()
            .try_acquire_owned()
            .map_err(|_| ApiError::overloaded())?;
        let gpu = self.gpu_usable();
        if gpu.is_none() && jobs.iter().any(|j| j.backend == Backend::Gpu) {
            return Err(ApiError::unprocessable(
                "gpu_unavailable",
                format!(
                    "backend gpu was asked for, but the service runs on the CPU ({})",
                    self.degraded
                        .lock()
                        .ok()
                        .and_then(|d| d.clone())
                        .unwrap_or_else(|| "started with backend cpu".into())
                ),
            ));
        }
        // a service started with `--backend gpu` (or cpu) decides for requests that leave
        // the choice to it (after the check above: with its GPU lost, they fit on the CPU)
        for job in &mut jobs {
            if job.backend == Backend::Auto {
                job.backend = self.configured;
            }
        }
        let work = async {
            // counted while waiting for a worker, however the wait ends (a worker, the
            // timeout, the client gone: the future is then dropped here)
            let waiting = Waiting::enter(&self.waiting);
            let worker = self.workers.clone().acquire_owned().await;
            drop(waiting);
            let worker = worker.map_err(|_| ApiError::overloaded())?;
            let degraded = self.degraded.clone();
            // a fit alone takes every core (a robot cell posts one frame and waits for
            // it); beside others, one each
            let alone = self.workers.available_permits() + 1 >= self.worker_count;
            let serial = !alone;
            tokio::task::spawn_blocking(move || {
                let _permits = (admission, worker);
                run_jobs(jobs, gpu.as_ref(), &degraded, serial)
            })
            .await
            .map_err(|e| {
                ApiError::new(
                    StatusCode::INTERNAL_SERVER_ERROR,
                    "internal",
                    format!("the fit task failed: {e}"),
                )
            })
        };
        match tokio::time::timeout(self.timeout, work).await {
            Ok(result) => result,
            Err(_) => Err(ApiError::new(
                StatusCode::GATEWAY_TIMEOUT,
                "timeout",
                format!("the fit did not finish within {:?}", self.timeout),
            )),
        }
    }
}

/// One request counted in [`Fitter::queued`] for as long as it lives.
struct Waiting<'a>(&'a AtomicUsize);

impl<'a> Waiting<'a> {
    fn enter(count: &'a AtomicUsize) -> Self {
        count.fetch_add(1, Ordering::Relaxed);
        Self(count)
    }
}

impl Drop for Waiting<'_> {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::Relaxed);
    }
}

thread_local! {
    /// A one-thread rayon pool per fit worker, for a fit that starts while others run:
    /// with `workers` fits in parallel, the CPU evaluator's own parallelism would only
    /// oversubscribe the cores and lengthen the tail latency.
    static SERIAL: Option<rayon::ThreadPool> =
        rayon::ThreadPoolBuilder::new().num_threads(1).build().ok();
}

/// One request's clouds on the requested evaluators; a GPU failure marks the service
/// degraded and the clouds are redone on the CPU.
fn run_jobs(
    jobs: Vec<FitJob>,
    gpu: Option<&Arc<GpuContext>>,
    degraded: &Mutex<Option<String>>,
    serial: bool,
) -> Vec<Result<FitReport, ApiError>> {
    if serial {
        SERIAL.with(|pool| match pool {
            Some(pool) => pool.install(|| run_jobs_here(&jobs, gpu, degraded)),
            None => run_jobs_here(&jobs, gpu, degraded),
        })
    } else {
        run_jobs_here(&jobs, gpu, degraded)
    }
}

/// The clouds that may use the GPU are fitted together in one lockstep batch on it
/// (`fit::fit_batch`: every solver iteration of every cloud in one dispatch), the rest
/// together on the CPU.
fn run_jobs_here(
    jobs: &[FitJob],
    gpu: Option<&Arc<GpuContext>>,
    degraded: &Mutex<Option<String>>,
) -> Vec<Result<FitReport, ApiError>> {
    let mut results: Vec<Option<Result<FitReport, ApiError>>> = jobs.iter().map(|_| None).collect();
    // `auto` clouds go to the GPU only when their stage-2 sample is large enough for it
    // to win (`eval::auto_prefers_gpu`)
    let wants_gpu = |job: &FitJob| match job.backend {
        Backend::Gpu => true,
        Backend::Cpu => false,
        Backend::Auto => auto_prefers_gpu(job.options.stage2_points.min(job.points.len())),
    };
    let (on_gpu, on_cpu): (Vec<usize>, Vec<usize>) =
        (0..jobs.len()).partition(|&i| gpu.is_some() && wants_gpu(&jobs[i]));
    let clouds = |indices: &[usize]| -> Vec<(&[DVec3], &FitOptions)> {
        indices
            .iter()
            .map(|&i| (jobs[i].points.as_slice(), &jobs[i].options))
            .collect()
    };
    let mut for_cpu = on_cpu;
    if let (Some(ctx), false) = (gpu, on_gpu.is_empty()) {
        let mut evaluator = GpuEvaluator::new(ctx.clone());
        match fit_batch(&mut evaluator as &mut dyn Evaluator, &clouds(&on_gpu)) {
            Ok(fits) => {
                for (&i, r) in on_gpu.iter().zip(fits) {
                    results[i] = Some(r.map_err(ApiError::from));
                }
            }
            Err(e) => {
                tracing::error!(error = %e, "GPU evaluator failed; switching to the CPU");
                if let Ok(mut d) = degraded.lock() {
                    *d = Some(format!("GPU evaluator failed: {e}"));
                }
                for_cpu.extend(on_gpu);
                for_cpu.sort_unstable();
            }
        }
    }
    if !for_cpu.is_empty() {
        match fit_batch(&mut CpuEvaluator::new(), &clouds(&for_cpu)) {
            Ok(fits) => {
                for (&i, r) in for_cpu.iter().zip(fits) {
                    results[i] = Some(r.map_err(ApiError::from));
                }
            }
            Err(e) => {
                for &i in &for_cpu {
                    results[i] = Some(Err(ApiError::from(e.clone())));
                }
            }
        }
    }
    results
        .into_iter()
        .map(|r| r.expect("every job ran"))
        .collect()
}

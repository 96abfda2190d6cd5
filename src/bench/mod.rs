//! The benchmark harness behind `supertoroid bench`: the paper's table on real clouds
//! ([`paper`]), the ground-truth suite ([`synthetic`]) and evaluator scaling
//! ([`scaling`]), grasps planned on fits checked on the truth ([`grasps`]), and the choice between
//! supertoroid and superellipsoid ([`models`]), single views beyond the suite through a depth
//! sensor ([`broad`]), and whole table-top scenes ([`scenes`]). Every sub-bench returns a serialisable report and writes it as JSON and
//! CSV (for machines) and markdown (for people), with the machine and git revision.

pub mod ablation;
pub mod boxes;
pub mod broad;
pub mod grasps;
pub mod models;
pub mod paper;
pub mod plot;
pub mod scaling;
pub mod scenes;
pub mod synthetic;

use serde::Serialize;
use std::path::Path;

/// Where the figures were measured.
#[derive(Clone, Debug, Serialize)]
pub struct Machine {
    pub cpu: String,
    pub cores: usize,
    /// the GPU adapter wgpu finds (or why none)
    pub adapter: String,
    pub os: String,
    pub git_revision: String,
    pub version: String,
}

impl Machine {
    pub fn probe() -> Self {
        let cpu = std::fs::read_to_string("/proc/cpuinfo")
            .ok()
            .and_then(|s| {
                s.lines()
                    .find(|l| l.starts_with("model name"))
                    .and_then(|l| l.split(':').nth(1))
                    .map(|m| m.trim().to_owned())
            })
            .unwrap_or_else(|| "unknown".into());
        let adapter = match crate::eval::GpuContext::shared(&crate::eval::AdapterChoice::from_env())
        {
            Ok(ctx) => ctx.adapter_name(),
            Err(e) => format!("none ({e})"),
        };
        let git_revision = std::process::Command::new("git")
            .args(["rev-parse", "--short", "HEAD"])
            .output()
            .ok()
            .filter(|o| o.status.success())
            .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_owned())
            .unwrap_or_else(|| "unknown".into());
        Self {
            cpu,
            cores: std::thread::available_parallelism().map_or(1, |n| n.get()),
            adapter,
            os: std::env::consts::OS.into(),
            git_revision,
            version: env!("CARGO_PKG_VERSION").into(),
        }
    }

    pub fn markdown(&self) -> String {
        format!(
            "Machine: {} ({} cores), GPU adapter: {}; supertoroid {} at git {}.\n",
            self.cpu, self.cores, self.adapter, self.version, self.git_revision
        )
    }
}

/// The q-quantile of `values` (the element at rank q·n, sorted), NaN for none.
pub fn percentile(mut values: Vec<f64>, q: f64) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    values.sort_by(f64::total_cmp);
    values[((values.len() as f64 * q) as usize).min(values.len() - 1)]
}

/// A report that can be written in the three forms.
pub trait Report: Serialize {
    /// The file stem (`paper`, `synthetic`, `scaling`).
    fn name(&self) -> &'static str;
    /// CSV: header line, then one line per row.
    fn csv(&self) -> String;
    fn markdown(&self) -> String;
    /// Plots to write beside the report: (file name, PNG bytes).
    fn plots(&self) -> Result<Vec<(String, Vec<u8>)>, String> {
        Ok(Vec::new())
    }
}

/// Writes `<dir>/<name>.json`, `.csv` and `.md`; returns their paths.
pub fn write_report(dir: &Path, report: &impl Report) -> std::io::Result<Vec<std::path::PathBuf>> {
    std::fs::create_dir_all(dir)?;
    let stem = dir.join(report.name());
    let paths = [
        stem.with_extension("json"),
        stem.with_extension("csv"),
        stem.with_extension("md"),
    ];
    std::fs::write(&paths[0], serde_json::to_string_pretty(report)?)?;
    std::fs::write(&paths[1], report.csv())?;
    std::fs::write(&paths[2], report.markdown())?;
    let mut paths = paths.to_vec();
    for (name, png) in report.plots().map_err(std::io::Error::other)? {
        let path = dir.join(name);
        std::fs::write(&path, png)?;
        paths.push(path);
    }
    Ok(paths)
}

/// A progress bar on a terminal, nothing otherwise (indicatif hides itself when stderr
/// is not a terminal).
pub fn progress(len: u64, what: &str) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::new(len);
    if let Ok(style) =
        indicatif::ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} {elapsed}")
    {
        bar.set_style(style.progress_chars("=> "));
    }
    bar.set_message(what.to_owned());
    bar
}

/// Where `--render DIR` pictures go: written to `dir`, linked from the report as
/// `link/<name>` (DIR relative to the report directory, unless absolute).
#[derive(Clone, Debug)]
pub struct RenderTarget {
    pub dir: std::path::PathBuf,
    pub link: std::path::PathBuf,
    /// pixels per view
    pub size: u32,
}

impl RenderTarget {
    pub fn new(out: &Path, dir: &Path, size: u32) -> Self {
        Self {
            dir: out.join(dir),
            link: dir.to_path_buf(),
            size,
        }
    }

    /// Draws a cloud and its fit; returns the link for the markdown.
    pub fn draw(
        &self,
        name: &str,
        points: &[glam::DVec3],
        fit: (crate::model::Shape, crate::model::Pose),
    ) -> Result<String, String> {
        let png = crate::render::render_png(
            &crate::render::Scene {
                points,
                fit: Some(fit),
                objects: None,
            },
            self.size,
        )?;
        std::fs::create_dir_all(&self.dir).map_err(|e| format!("{}: {e}", self.dir.display()))?;
        let file = format!("{name}.png");
        std::fs::write(self.dir.join(&file), png).map_err(|e| e.to_string())?;
        Ok(self.link.join(file).to_string_lossy().into_owned())
    }
}

/// Median and spread of a sample.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct Stats {
    pub median: f64,
    pub mean: f64,
    pub std: f64,
    pub min: f64,
    pub max: f64,
    pub p90: f64,
}

impl Stats {
    pub fn of(values: &[f64]) -> Self {
        if values.is_empty() {
            return Self::default();
        }
        let mut v = values.to_vec();
        v.sort_by(f64::total_cmp);
        let n = v.len() as f64;
        let mean = v.iter().sum::<f64>() / n;
        let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
        let at = |f: f64| v[((v.len() - 1) as f64 * f).round() as usize];
        Self {
            median: at(0.5),
            mean,
            std: var.sqrt(),
            min: v[0],
            max: v[v.len() - 1],
            p90: at(0.9),
        }
    }
}

//! `bench scaling`: time of one solver iteration (residuals, Jacobians and the reduction
//! to normal equations) against points N and candidates K, for each backend. A cell is
//! repeated until it has `min_repeats` samples and `budget` seconds are spent; cells
//! whose estimate (from the cell with a tenth of the points) exceeds the budget a
//! hundredfold are skipped and say so.

use super::{Machine, Report, Stats};
use crate::eval::{
    AdapterChoice, Candidate, CpuEvaluator, Evaluator, GpuContext, GpuEvaluator, Loss,
    Normalization,
};
use crate::model::{Pose, Shape};
use crate::synth;
use glam::{DQuat, DVec3};
use serde::Serialize;
use std::time::Instant;

#[derive(Clone, Debug, Serialize)]
pub struct Cell {
    pub backend: String,
    pub points: usize,
    pub candidates: usize,
    /// milliseconds per iteration; None when skipped
    pub time_ms: Option<Stats>,
    pub point_jacobians_per_s: Option<f64>,
    pub samples: usize,
}

#[derive(Clone, Debug, Serialize)]
pub struct ScalingReport {
    pub machine: Machine,
    pub budget_s: f64,
    pub cells: Vec<Cell>,
}

pub struct ScalingOptions {
    pub points: Vec<usize>,
    pub candidates: Vec<usize>,
    pub backends: Vec<String>,
    /// seconds per cell
    pub budget: f64,
    pub min_repeats: usize,
}

impl Default for ScalingOptions {
    fn default() -> Self {
        Self {
            points: vec![1_000, 10_000, 100_000, 1_000_000],
            candidates: vec![1, 8, 64],
            backends: vec!["cpu".into(), "gpu".into()],
            budget: 2.0,
            min_repeats: 3,
        }
    }
}

pub fn run(o: &ScalingOptions) -> Result<ScalingReport, String> {
    let shape = Shape::new(0.05, 0.04, 0.02, 2.0, 0.8, 1.2);
    let pose = Pose::new(DQuat::from_rotation_x(0.3), DVec3::new(0.1, 0.2, 0.5));
    let mut cells = Vec::new();
    let total = (o.backends.len() * o.points.len() * o.candidates.len()) as u64;
    let bar = super::progress(total, "scaling");
    for name in &o.backends {
        let mut evaluator: Box<dyn Evaluator> = match name.as_str() {
            "cpu" => Box::new(CpuEvaluator::new()),
            "gpu" => Box::new(GpuEvaluator::new(
                GpuContext::shared(&AdapterChoice::from_env()).map_err(|e| e.to_string())?,
            )),
            other => return Err(format!("unknown backend {other:?} (cpu, gpu)")),
        };
        let label = format!("{name}: {}", evaluator.device_name());
        let mut rng = synth::rng(1);
        // seconds per point-candidate seen so far, for the skip estimate
        let mut per_unit: Option<f64> = None;
        for &n in &o.points {
            let mut world = synth::sample_surface(&shape, &pose, n, &mut rng);
            synth::add_noise(&mut world, 0.01 * shape.size(), &mut rng);
            let norm = Normalization::of(&world);
            evaluator
                .set_points(&norm.points(&world))
                .map_err(|e| e.to_string())?;
            let truth = norm.candidate(&shape, &pose);
            for &k in &o.candidates {
                bar.inc(1);
                if let Some(u) = per_unit
                    && u * (n * k) as f64 > 100.0 * o.budget
                {
                    cells.push(Cell {
                        backend: label.clone(),
                        points: n,
                        candidates: k,
                        time_ms: None,
                        point_jacobians_per_s: None,
                        samples: 0,
                    });
                    continue;
                }
                let batch: Vec<Candidate> = (0..k)
                    .map(|i| {
                        let mut c = truth;
                        c.shape.a1 *= 1.0 + 0.01 * i as f64;
                        c
                    })
                    .collect();
                evaluator
                    .normal_equations(&batch, Loss::Huber(0.05))
                    .map_err(|e| e.to_string())?; // warm-up
                let mut samples = Vec::new();
                let start = Instant::now();
                while samples.len() < o.min_repeats || start.elapsed().as_secs_f64() < o.budget {
                    let t = Instant::now();
                    evaluator
                        .normal_equations(&batch, Loss::Huber(0.05))
                        .map_err(|e| e.to_string())?;
                    samples.push(t.elapsed().as_secs_f64());
                    if samples.len() >= 200 {
                        break;
                    }
                }
                let stats = Stats::of(&samples.iter().map(|s| s * 1e3).collect::<Vec<_>>());
                per_unit = Some(stats.median / 1e3 / (n * k) as f64);
                cells.push(Cell {
                    backend: label.clone(),
                    points: n,
                    candidates: k,
                    point_jacobians_per_s: Some((n * k) as f64 / (stats.median / 1e3)),
                    time_ms: Some(stats),
                    samples: samples.len(),
                });
            }
        }
    }
    bar.finish_and_clear();
    Ok(ScalingReport {
        machine: Machine::probe(),
        budget_s: o.budget,
        cells,
    })
}

impl Report for ScalingReport {
    fn name(&self) -> &'static str {
        "scaling"
    }

    fn csv(&self) -> String {
        let mut s = String::from(
            "backend,points,candidates,median_ms,min_ms,max_ms,std_ms,samples,point_jacobians_per_s\n",
        );
        for c in &self.cells {
            match &c.time_ms {
                Some(t) => {
                    s += &format!(
                        "\"{}\",{},{},{},{},{},{},{},{}\n",
                        c.backend,
                        c.points,
                        c.candidates,
                        t.median,
                        t.min,
                        t.max,
                        t.std,
                        c.samples,
                        c.point_jacobians_per_s.unwrap_or(0.0)
                    )
                }
                None => s += &format!("\"{}\",{},{},,,,,0,\n", c.backend, c.points, c.candidates),
            }
        }
        s
    }

    fn plots(&self) -> Result<Vec<(String, Vec<u8>)>, String> {
        use super::plot::{COLORS, Panel, Series, panels_png};
        let mut backends: Vec<&str> = self.cells.iter().map(|c| c.backend.as_str()).collect();
        backends.dedup();
        let mut ks: Vec<usize> = self.cells.iter().map(|c| c.candidates).collect();
        ks.sort();
        ks.dedup();
        let panels: Vec<Panel> = backends
            .iter()
            .map(|b| Panel {
                series: ks
                    .iter()
                    .enumerate()
                    .map(|(i, k)| Series {
                        color: COLORS[i % COLORS.len()],
                        points: self
                            .cells
                            .iter()
                            .filter(|c| c.backend == *b && c.candidates == *k)
                            .filter_map(|c| c.time_ms.map(|t| (c.points as f64, t.median)))
                            .collect(),
                    })
                    .collect(),
                log_x: true,
                log_y: true,
                marker_x: None,
                y_range: None,
            })
            .collect();
        Ok(vec![("scaling.png".into(), panels_png(&panels, 360)?)])
    }

    fn markdown(&self) -> String {
        let mut md = String::from("# Evaluator scaling\n\n");
        md += &self.machine.markdown();
        md += &format!(
            "Time per solver iteration (residuals + Jacobians + normal equations), median [min, max] over repeats within {} s per cell.\n\n| backend | N | K | time | point-Jacobians/s |\n|---|---:|---:|---|---:|\n",
            self.budget_s
        );
        for c in &self.cells {
            let (t, rate) = match (&c.time_ms, c.point_jacobians_per_s) {
                (Some(t), Some(r)) => (
                    format!(
                        "{:.3} ms [{:.3}, {:.3}] ({} samples)",
                        t.median, t.min, t.max, c.samples
                    ),
                    format!("{:.2} M", r / 1e6),
                ),
                _ => ("skipped (over budget)".into(), "-".into()),
            };
            md += &format!(
                "| {} | {} | {} | {} | {} |\n",
                c.backend, c.points, c.candidates, t, rate
            );
        }
        md += "\n![Milliseconds per iteration against points (log-log), one panel per backend in the table's order; blue, red, green, ... for the candidate counts in increasing order](scaling.png)\n";
        md
    }
}

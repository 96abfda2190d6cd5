use super::{Candidate, Cost, EvalError, Evaluator, Loss, NUM_PARAMS, NormalEquations};
use crate::model::{meridian_distance, meridian_residual_with_gradient};
use glam::{DMat3, DVec3};
use rayon::prelude::*;

/// The f64 reference evaluator, parallel over points with rayon.
#[derive(Default)]
pub struct CpuEvaluator {
    points: Vec<DVec3>,
}

impl CpuEvaluator {
    pub fn new() -> Self {
        Self::default()
    }
}

/// Residual and 12-column Jacobian row of one point (see `eval::NUM_PARAMS` for the order).
pub fn jacobian_row(c: &Candidate, rotation: &DMat3, p: DVec3) -> (f64, [f64; NUM_PARAMS]) {
    let q = rotation.transpose() * (p - c.pose.translation);
    let g = meridian_residual_with_gradient(&c.shape, q);
    // dq/dt = -R^T  =>  dr/dt = -R·dr/dq;  dq/dd = [q]x  =>  dr/dd = dr/dq x q
    let dt = -(*rotation * g.d_point);
    let dd = g.d_point.cross(q);
    let mut row = [0.0; NUM_PARAMS];
    row[..6].copy_from_slice(&g.d_shape);
    row[6..9].copy_from_slice(&dt.to_array());
    row[9..].copy_from_slice(&dd.to_array());
    (g.residual, row)
}

/// Points per work item: small enough that a 1000-point stage-2 sample splits over
/// cores, large enough that a work item outweighs rayon's scheduling.
const CHUNK: usize = 256;

impl CpuEvaluator {
    fn chunks(&self) -> usize {
        self.points.len().div_ceil(CHUNK)
    }

    /// `work(candidate, chunk)` over every (candidate, chunk) pair in parallel, so a
    /// batch of small stage-1 samples spreads over cores as well as one large cloud.
    /// Results come back in (candidate, chunk) order and are summed in that order by
    /// the callers: the same sums whatever the thread schedule, so a seed always gives
    /// the same fit.
    fn per_chunk<T: Send>(
        &self,
        candidates: usize,
        work: impl Fn(usize, &[DVec3]) -> T + Sync,
    ) -> Vec<T> {
        let chunks = self.chunks();
        (0..candidates * chunks)
            .into_par_iter()
            .map(|item| {
                let (k, j) = (item / chunks, item % chunks);
                let end = ((j + 1) * CHUNK).min(self.points.len());
                work(k, &self.points[j * CHUNK..end])
            })
            .collect()
    }
}

impl Evaluator for CpuEvaluator {
    fn kind(&self) -> &'static str {
        "cpu"
    }

    fn device_name(&self) -> String {
        format!("cpu (f64, {} threads)", rayon::current_num_threads())
    }

    fn set_points(&mut self, points: &[DVec3]) -> Result<(), EvalError> {
        self.points = points.to_vec();
        Ok(())
    }

    fn normal_equations(
        &mut self,
        candidates: &[Candidate],
        loss: Loss,
    ) -> Result<Vec<NormalEquations>, EvalError> {
        if self.points.is_empty() {
            return Err(EvalError::NoPoints);
        }
        let rotations: Vec<DMat3> = candidates.iter().map(|c| c.pose.matrix()).collect();
        let partials = self.per_chunk(candidates.len(), |k, chunk| {
            let (c, rotation) = (&candidates[k], &rotations[k]);
            let mut ne = NormalEquations::zero();
            for p in chunk {
                let (r, row) = jacobian_row(c, rotation, *p);
                if !r.is_finite() || row.iter().any(|x| !x.is_finite()) {
                    continue;
                }
                let (rho, w) = loss.eval(r);
                for a in 0..NUM_PARAMS {
                    let wa = w * row[a];
                    for b in a..NUM_PARAMS {
                        ne.jtj[a][b] += wa * row[b];
                    }
                    ne.jtr[a] += wa * r;
                }
                ne.cost += rho;
                ne.count += 1;
            }
            ne
        });
        Ok(partials
            .chunks(self.chunks())
            .map(|parts| {
                let mut x = NormalEquations::zero();
                for y in parts {
                    for a in 0..NUM_PARAMS {
                        for b in a..NUM_PARAMS {
                            x.jtj[a][b] += y.jtj[a][b];
                        }
                        x.jtr[a] += y.jtr[a];
                    }
                    x.cost += y.cost;
                    x.count += y.count;
                }
                for a in 0..NUM_PARAMS {
                    for b in 0..a {
                        x.jtj[a][b] = x.jtj[b][a];
                    }
                }
                x
            })
            .collect())
    }

    fn costs(&mut self, candidates: &[Candidate], loss: Loss) -> Result<Vec<Cost>, EvalError> {
        if self.points.is_empty() {
            return Err(EvalError::NoPoints);
        }
        let inverses: Vec<_> = candidates
            .iter()
            .map(|c| c.pose.rotation.inverse())
            .collect();
        let partials = self.per_chunk(candidates.len(), |k, chunk| {
            let c = &candidates[k];
            chunk.iter().fold((0.0, 0u64), |(cost, count), p| {
                let r = meridian_distance(&c.shape, inverses[k] * (*p - c.pose.translation)).signed;
                if r.is_finite() {
                    (cost + loss.eval(r).0, count + 1)
                } else {
                    (cost, count)
                }
            })
        });
        Ok(partials
            .chunks(self.chunks())
            .map(|parts| {
                let (cost, count) = parts.iter().fold((0.0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
                Cost { cost, count }
            })
            .collect())
    }

    fn residuals(&mut self, candidates: &[Candidate]) -> Result<Vec<f64>, EvalError> {
        if self.points.is_empty() {
            return Err(EvalError::NoPoints);
        }
        let mut out = Vec::with_capacity(candidates.len() * self.points.len());
        for c in candidates {
            let inverse = c.pose.rotation.inverse();
            out.par_extend(
                self.points.par_iter().map(|p| {
                    meridian_distance(&c.shape, inverse * (*p - c.pose.translation)).signed
                }),
            );
        }
        Ok(out)
    }
}

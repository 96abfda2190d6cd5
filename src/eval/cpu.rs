use super::{
    Candidate, Cost, EvalError, Evaluator, Loss, NUM_PARAMS, NormalEquations, PointSet, check_sets,
    point_residual,
};
use crate::model::{meridian_distance, meridian_residual_with_gradient};
use glam::{DMat3, DVec3};
use rayon::prelude::*;

/// Whether a point in a shape's canonical frame lies beyond its bounding box
/// (`half`, [`crate::model::Shape::half_extents`]), and so outside the solid: a
/// free-space point there has a residual of zero, told without its distance.
fn beyond_the_box(half: DVec3, q: DVec3) -> bool {
    q.abs().cmpgt(half).any()
}

/// The f64 reference evaluator, parallel over points with rayon.
#[derive(Default)]
pub struct CpuEvaluator {
    /// all point sets, one after another, each its surface points then its free-space ones
    points: Vec<DVec3>,
    /// (first, surface count, free-space count) of each set in `points`
    sets: Vec<(usize, usize, usize)>,
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
    /// The points of set `s`, surface then free space.
    fn set(&self, s: usize) -> &[DVec3] {
        let (first, surface, free) = self.sets[s];
        &self.points[first..first + surface + free]
    }

    /// `work(candidate, chunk, surface points in the chunk)` over every (candidate, chunk
    /// of its set) pair in parallel, so a batch of small stage-1 samples spreads over
    /// cores as well as one large cloud. Returns, per candidate, its chunks' results in chunk order; the
    /// callers sum them in that order: the same sums whatever the thread schedule or the
    /// other candidates of the batch, so a seed always gives the same fit, alone or in a
    /// batch of clouds. A chunk's leading points are surface points, the rest (of the
    /// last chunks) free-space points.
    fn per_chunk<T: Send>(
        &self,
        sets: &[usize],
        work: impl Fn(usize, &[DVec3], usize) -> T + Sync,
    ) -> Vec<Vec<T>> {
        let items: Vec<(usize, usize)> = sets
            .iter()
            .enumerate()
            .flat_map(|(k, &s)| {
                let (_, surface, free) = self.sets[s];
                (0..(surface + free).div_ceil(CHUNK)).map(move |j| (k, j))
            })
            .collect();
        let results: Vec<(usize, T)> = items
            .into_par_iter()
            .map(|(k, j)| {
                let set = self.set(sets[k]);
                let surface = self.sets[sets[k]].1;
                let (start, end) = (j * CHUNK, ((j + 1) * CHUNK).min(set.len()));
                let surface_in_chunk = surface.clamp(start, end) - start;
                (k, work(k, &set[start..end], surface_in_chunk))
            })
            .collect();
        let mut out: Vec<Vec<T>> = (0..sets.len()).map(|_| Vec::new()).collect();
        // `collect` keeps the items' order: candidate by candidate, chunk by chunk
        for (k, t) in results {
            out[k].push(t);
        }
        out
    }

    fn check(&self, candidates: usize, sets: &[usize]) -> Result<(), EvalError> {
        // a set needs surface points: free space alone fits nothing
        let sizes: Vec<usize> = self.sets.iter().map(|s| s.1).collect();
        check_sets(candidates, sets, &sizes)
    }
}

impl Evaluator for CpuEvaluator {
    fn kind(&self) -> &'static str {
        "cpu"
    }

    fn device_name(&self) -> String {
        format!("cpu (f64, {} threads)", rayon::current_num_threads())
    }

    fn set_point_sets_with_free_space(&mut self, sets: &[PointSet]) -> Result<(), EvalError> {
        self.points.clear();
        self.sets.clear();
        for set in sets {
            self.sets
                .push((self.points.len(), set.surface.len(), set.free_space.len()));
            self.points.extend_from_slice(set.surface);
            self.points.extend_from_slice(set.free_space);
        }
        Ok(())
    }

    fn normal_equations_on(
        &mut self,
        candidates: &[Candidate],
        sets: &[usize],
        loss: Loss,
    ) -> Result<Vec<NormalEquations>, EvalError> {
        self.check(candidates.len(), sets)?;
        let rotations: Vec<DMat3> = candidates.iter().map(|c| c.pose.matrix()).collect();
        let partials = self.per_chunk(sets, |k, chunk, surface| {
            let (c, rotation) = (&candidates[k], &rotations[k]);
            let half = c.shape.half_extents();
            let mut ne = NormalEquations::zero();
            for (i, p) in chunk.iter().enumerate() {
                let free_space = i >= surface;
                // most free-space points lie outside: the bounding box or the distance
                // alone tells, at a fraction of the cost of the Jacobian row
                if free_space {
                    let q = rotation.transpose() * (*p - c.pose.translation);
                    if beyond_the_box(half, q) || meridian_distance(&c.shape, q).signed >= 0.0 {
                        continue;
                    }
                }
                let (r, row) = jacobian_row(c, rotation, *p);
                if !r.is_finite() || row.iter().any(|x| !x.is_finite()) {
                    continue;
                }
                let r = point_residual(r, free_space);
                if free_space && r == 0.0 {
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
                ne.count += u64::from(!free_space);
            }
            ne
        });
        Ok(partials
            .iter()
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

    fn costs_on(
        &mut self,
        candidates: &[Candidate],
        sets: &[usize],
        loss: Loss,
    ) -> Result<Vec<Cost>, EvalError> {
        self.check(candidates.len(), sets)?;
        let inverses: Vec<_> = candidates
            .iter()
            .map(|c| c.pose.rotation.inverse())
            .collect();
        let partials = self.per_chunk(sets, |k, chunk, surface| {
            let c = &candidates[k];
            let half = c.shape.half_extents();
            chunk
                .iter()
                .enumerate()
                .fold((0.0, 0u64), |(cost, count), (i, p)| {
                    let free_space = i >= surface;
                    let q = inverses[k] * (*p - c.pose.translation);
                    // (a free-space point outside the box adds nothing: told without its
                    // distance)
                    if free_space && beyond_the_box(half, q) {
                        return (cost, count);
                    }
                    let r = meridian_distance(&c.shape, q).signed;
                    if r.is_finite() {
                        let r = point_residual(r, free_space);
                        (cost + loss.eval(r).0, count + u64::from(!free_space))
                    } else {
                        (cost, count)
                    }
                })
        });
        Ok(partials
            .iter()
            .map(|parts| {
                let (cost, count) = parts.iter().fold((0.0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
                Cost { cost, count }
            })
            .collect())
    }

    fn residuals_on(
        &mut self,
        candidates: &[Candidate],
        sets: &[usize],
    ) -> Result<Vec<f64>, EvalError> {
        self.check(candidates.len(), sets)?;
        let mut out = Vec::new();
        for (c, &s) in candidates.iter().zip(sets) {
            let inverse = c.pose.rotation.inverse();
            let surface = &self.set(s)[..self.sets[s].1];
            out.par_extend(
                surface.par_iter().map(|p| {
                    meridian_distance(&c.shape, inverse * (*p - c.pose.translation)).signed
                }),
            );
        }
        Ok(out)
    }
}

//! One cloud made ready for the fit: checked, normalised, sampled for both stages, with
//! free-space points where a viewpoint is known, the stage-1 starts and both stages'
//! solver settings; and what the later stages ask of it (point sets, size boxes, the
//! noise model's limits, the other reading of a top view, collapsed starts).

use super::*;
use crate::eval::GpuObjective;
use std::sync::Arc;

/// `shape` with the known parameters (normalised sizes) put in.
pub(super) fn holding_known(shape: Shape, known: &[Option<f64>; 6]) -> Shape {
    let mut v = shape.to_array();
    for (v, k) in v.iter_mut().zip(known) {
        if let Some(k) = k {
            *v = *k;
        }
    }
    Shape::from_array(v)
}

/// Starting shape for a hole axis: sizes from the cloud's extent across and along it.
pub(super) fn start_for_axis(points: &[DVec3], axis: DVec3, hint: DVec3, a4: f64) -> Candidate {
    let rotation = starts::frame_with_z(axis, hint);
    let inverse = rotation.inverse();
    let local: Vec<DVec3> = points.iter().map(|p| inverse * *p).collect();
    let mut radial: Vec<f64> = local.iter().map(|q| q.x.hypot(q.y)).collect();
    let mut height: Vec<f64> = local.iter().map(|q| q.z.abs()).collect();
    radial.sort_by(f64::total_cmp);
    height.sort_by(f64::total_cmp);
    let pick = |v: &[f64], f: f64| v[((v.len() - 1) as f64 * f) as usize];
    let outer = pick(&radial, 0.95).max(1e-3);
    let half_height = pick(&height, 0.95).max(1e-3 * outer);
    let a = outer / (1.0 + a4);
    Candidate {
        shape: Shape::new(a, a, half_height, a4, 1.0, 1.0),
        pose: Pose::new(rotation, DVec3::ZERO),
    }
}

/// Which stage-1 starts a fit runs from.
#[derive(Clone, Copy, PartialEq)]
pub(super) enum StartSet {
    /// [`prepare`]'s starts
    Usual,
    /// the search's broad set: the usual starts, the hole axes across the line of sight,
    /// and the normal lines' starts moved behind the skin the sensor saw
    /// ([`starts::behind_the_skin`])
    Broad,
}

/// One cloud, checked, normalised, sampled, with its stage-1 starts and solver settings.
pub(super) struct Prepared<'a> {
    pub(super) points: &'a [DVec3],
    pub(super) method: Method,
    pub(super) norm: Normalization,
    pub(super) stage1_pts: Vec<DVec3>,
    pub(super) stage2_pts: Vec<DVec3>,
    /// free-space points of each stage (in front of the points seen from the viewpoint,
    /// and under them inside the support; empty without either)
    pub(super) stage1_free: Vec<DVec3>,
    pub(super) stage2_free: Vec<DVec3>,
    /// stage 1's starts, of the [`StartSet`] asked for (the hole axes across the line of
    /// sight: none unless a viewpoint is given and the normal lines' axis is across it)
    pub(super) starts: Vec<Candidate>,
    pub(super) bounds: Bounds,
    pub(super) opts1: SolverOptions,
    pub(super) opts2: SolverOptions,
    /// solutions that [`overreach`] beyond this rank below every one that does not
    pub(super) max_overreach: Option<f64>,
    /// Cauchy scale of the final refinement in robust residual scales, if it runs
    pub(super) refine_scale: Option<f64>,
    /// the viewpoint in the normalised frame, if given
    pub(super) viewpoint: Option<DVec3>,
    /// the edges of the viewpoint's frame, if given (normalising leaves them as they are)
    pub(super) field: Option<FieldOfView>,
    /// the known shape parameters (normalised sizes), held fixed
    pub(super) known: [Option<f64>; 6],
    /// run [`likelihood::refine`] on noisy fits
    pub(super) noise_model: bool,
    pub(super) known_axis: bool,
    /// the cloud's own scatter ([`scatter::local_scatter`], normalised units), measured
    /// when first asked
    pub(super) scatter: std::sync::OnceLock<Option<f64>>,
    /// optional stages left out ([`FitOptions::skip`])
    pub(super) skip: Vec<Stage>,
    /// the time budget's end, counted from the preparation's start
    /// ([`FitOptions::time_budget_ms`]): no likelihood step is taken past it
    pub(super) deadline: Option<Instant>,
    /// where the objective's per-point sums run (the search's evaluator's GPU, or the
    /// f64 loop)
    pub(super) device: Option<Arc<GpuObjective>>,
}

pub(super) fn prepare<'a>(
    points: &'a [DVec3],
    o: &FitOptions,
    start_set: StartSet,
) -> Result<Prepared<'a>, FitError> {
    let started = Instant::now();
    check_options(o)?;
    let (axes, _) = check_cloud(points)?;
    let norm = Normalization::of(points);
    let normalised = norm.points(points);
    let mut rng = synth::rng(o.seed);
    let stage1_pts = synth::subsample(&normalised, o.stage1_points, &mut rng);
    let stage2_pts = synth::subsample(&normalised, o.stage2_points, &mut rng);
    let viewpoint = o.viewpoint.position().map(|v| norm.point(v));
    let free = |sample: &[DVec3]| free_space_of(o, &norm, viewpoint, sample);
    let (stage1_free, stage2_free) = (free(&stage1_pts), free(&stage2_pts));
    let bounds = o.bounds();
    let paper = o.method == Method::Paper;
    let known = known_shape(o, &norm, &bounds)?;
    // normal lines meet the hole axis (see `starts`): the start that handles partial views
    let axis_sample = synth::subsample(&normalised, 400, &mut rng.clone());
    let (mut starts, mut across) = if paper {
        (paper_starts(&stage1_pts, o.known_axis), Vec::new())
    } else {
        let (mut on_lines, across) =
            normal_line_starts(&axis_sample, axes, o, viewpoint, start_set);
        on_lines.extend(principal_axis_starts(&stage1_pts, axes, o.known_axis));
        if let Some(table) = &o.resting_on
            && o.known_axis.is_none()
        {
            let (normal, offset) = normalised_plane(table, &norm);
            on_lines.extend(starts::resting_starts(
                &stage1_pts,
                normal,
                offset,
                known[3],
            ));
        }
        (on_lines, across)
    };
    for start in starts.iter_mut().chain(&mut across) {
        start.shape = holding_known(start.shape, &known);
    }
    // with a1 and a2 both held, the in-plane turn cannot trade them any more: each start
    // also goes a quarter turn about its axis
    if known[0].is_some() && known[1].is_some() {
        for starts in [&mut starts, &mut across] {
            let turned: Vec<Candidate> = starts
                .iter()
                .map(|s| {
                    let mut t = *s;
                    t.pose.rotation =
                        s.pose.rotation * DQuat::from_rotation_z(std::f64::consts::FRAC_PI_2);
                    t
                })
                .collect();
            starts.extend(turned);
        }
    }
    let starts = match start_set {
        StartSet::Usual => starts,
        StartSet::Broad => {
            // the normal lines' starts (the first three) behind the skin
            let behind: Vec<Candidate> = match viewpoint {
                Some(v) if !paper => starts
                    .iter()
                    .take(3)
                    .filter_map(|s| starts::behind_the_skin(s, v))
                    .collect(),
                _ => Vec::new(),
            };
            starts.into_iter().chain(across).chain(behind).collect()
        }
    };
    let (opts1, opts2) = solver_options(o, &known);
    Ok(Prepared {
        points,
        method: o.method,
        norm,
        stage1_pts,
        stage2_pts,
        stage1_free,
        stage2_free,
        starts,
        bounds,
        opts1,
        opts2,
        max_overreach: (!paper).then_some(MAX_OVERREACH),
        refine_scale: (!paper && o.refine_scale > 0.0).then_some(o.refine_scale),
        viewpoint,
        field: o.field_of_view,
        known,
        noise_model: !paper && o.noise_model,
        known_axis: o.known_axis.is_some(),
        scatter: std::sync::OnceLock::new(),
        skip: o.skip.clone(),
        // (a budget past what a clock can hold is no budget)
        deadline: o.time_budget_ms.and_then(|budget| {
            started.checked_add(std::time::Duration::try_from_secs_f64(budget / 1e3).ok()?)
        }),
        device: None,
    })
}

/// The options a fit cannot run with, named.
fn check_options(o: &FitOptions) -> Result<(), FitError> {
    let invalid = |message: String| Err(FitError::InvalidOption(message));
    if let Some(budget) = o.time_budget_ms
        && !(budget.is_finite() && budget > 0.0)
    {
        return invalid(format!(
            "the time budget must be a positive number of milliseconds, got {budget}"
        ));
    }
    if !(o.refine_scale.is_finite() && o.refine_scale >= 0.0) {
        return invalid(format!(
            "refine scale must be finite and >= 0, got {}",
            o.refine_scale
        ));
    }
    if o.stage1_points < MIN_POINTS || o.stage2_points < MIN_POINTS {
        return invalid(format!("points per stage must be at least {MIN_POINTS}"));
    }
    if o.polish_points != 0 && o.polish_points < MIN_POINTS {
        return invalid(format!(
            "polish points must be 0 (no polish) or at least {MIN_POINTS}"
        ));
    }
    if o.viewpoint.position().is_some_and(|v| !v.is_finite()) {
        return invalid("the viewpoint must be finite".into());
    }
    if o.field_of_view.is_some_and(|f| !f.is_finite()) {
        return invalid("the field of view must be finite".into());
    }
    if let Some(plane) = &o.support
        && !(plane.normal().is_finite() && plane.offset.is_finite())
    {
        return invalid("the support plane must be finite".into());
    }
    if let Some(plane) = &o.resting_on
        && !(plane.normal().is_finite() && plane.offset.is_finite())
    {
        return invalid("the table's plane must be finite".into());
    }
    if !o.seen_through.iter().all(|p| p.is_finite()) {
        return invalid("the points seen through must be finite".into());
    }
    if o.known_axis.is_some_and(|a| !(a.length() > 0.0)) {
        return invalid("known axis must not be zero".into());
    }
    Ok(())
}

/// The free-space points of a sample (normalised): in front of it seen from the
/// viewpoint, under it inside the support plane, and the caller's points seen through.
fn free_space_of(
    o: &FitOptions,
    norm: &Normalization,
    viewpoint: Option<DVec3>,
    sample: &[DVec3],
) -> Vec<DVec3> {
    let mut free = viewpoint.map_or_else(Vec::new, |v| free_space::in_front(sample, v));
    if let Some(plane) = &o.support {
        let (normal, offset) = normalised_plane(plane, norm);
        free.extend(free_space::below_support(sample, normal, offset));
    }
    free.extend(o.seen_through.iter().map(|&p| norm.point(p)));
    free
}

/// A plane's unit normal and offset in the normalised frame: n·(s x + c) + d = 0.
fn normalised_plane(plane: &crate::model::Plane, norm: &Normalization) -> (DVec3, f64) {
    let normal = plane.normal();
    (
        normal,
        (plane.offset + normal.dot(norm.centre)) / norm.scale,
    )
}

/// The known shape parameters (sizes normalised), each checked to be plausible.
fn known_shape(
    o: &FitOptions,
    norm: &Normalization,
    bounds: &Bounds,
) -> Result<[Option<f64>; 6], FitError> {
    let mut known = [None; 6];
    for (i, value) in o.known_shape.iter().enumerate() {
        let Some(value) = *value else { continue };
        let v = if i < 3 { value / norm.scale } else { value };
        let plausible = match i {
            0..3 => (0.002..=5.0).contains(&v),
            3 => (0.0..bounds.upper[3]).contains(&v),
            _ => (o.eps_min..=o.eps_max).contains(&v),
        };
        if !(v.is_finite() && plausible) {
            return Err(FitError::InvalidOption(format!(
                "{} = {value} is not plausible{}",
                SHAPE_NAMES[i],
                match i {
                    0..3 => " for a cloud of this size".to_string(),
                    3 => format!(" (0 <= a4 < {})", bounds.upper[3]),
                    _ => format!(" (eps within {} and {})", o.eps_min, o.eps_max),
                }
            )));
        }
        known[i] = Some(v);
    }
    Ok(known)
}

/// The hint for the in-plane direction of a start about `axis`: a principal axis across
/// it.
fn hint_across(axis: DVec3, axes: DMat3) -> DVec3 {
    if axis.dot(axes.x_axis).abs() > 0.9 {
        axes.y_axis
    } else {
        axes.x_axis
    }
}

/// The starts on the hole axis the normal lines give (or on the known axis through
/// them), at three hole ratios and two in-plane turns (a squarish top view turned 45
/// degrees looks like a diamond, a local minimum); and, for the broad set with a
/// viewpoint, the same across the line of sight (an edge-on ring's normal lines point
/// elsewhere).
fn normal_line_starts(
    axis_sample: &[DVec3],
    axes: DMat3,
    o: &FitOptions,
    viewpoint: Option<DVec3>,
    start_set: StartSet,
) -> (Vec<Candidate>, Vec<Candidate>) {
    let normals = starts::estimate_normals(axis_sample, 12);
    let line = match o.known_axis {
        Some(d) => starts::axis_point_for_direction(axis_sample, &normals, d.normalize())
            .map(|c| (d.normalize(), c)),
        None => starts::axis_from_normal_lines(axis_sample, &normals),
    };
    let (mut starts, mut across_starts) = (Vec::new(), Vec::new());
    let Some((axis, on_axis)) = line else {
        return (starts, across_starts);
    };
    // each line's starts at three hole ratios (the first from the points' spread)
    let on_line = |axis: DVec3, on: DVec3, hint: DVec3| {
        [None, Some(1.3), Some(2.5)]
            .map(|a4| starts::start_on_axis_line(axis_sample, axis, on, hint, a4))
    };
    let hint = hint_across(axis, axes);
    let turned = DQuat::from_axis_angle(axis, std::f64::consts::FRAC_PI_4) * hint;
    for hint in [hint, turned] {
        starts.extend(on_line(axis, on_axis, hint));
    }
    if let Some(across) = starts::across_line_of_sight(axis, viewpoint)
        .filter(|_| start_set != StartSet::Usual && o.known_axis.is_none())
        && let Some(on_across) = starts::axis_point_for_direction(axis_sample, &normals, across)
    {
        across_starts.extend(on_line(across, on_across, axis));
    }
    (starts, across_starts)
}

/// Starts on the cloud's principal axes (or the known axis) at its centroid, at two hole
/// ratios.
fn principal_axis_starts(
    stage1_pts: &[DVec3],
    axes: DMat3,
    known_axis: Option<DVec3>,
) -> Vec<Candidate> {
    let axes_to_try = match known_axis {
        Some(a) => vec![a.normalize()],
        None => vec![axes.z_axis, axes.y_axis, axes.x_axis],
    };
    let mut starts = Vec::new();
    for axis in axes_to_try {
        for a4 in [1.5, 3.0] {
            starts.push(start_for_axis(
                stage1_pts,
                axis,
                hint_across(axis, axes),
                a4,
            ));
        }
    }
    starts
}

/// The paper's starts (§V): x, y and z of the cloud's frame (or the known axis) at the
/// centroid, a3 = 0.6 of the half-diagonal.
fn paper_starts(stage1_pts: &[DVec3], known_axis: Option<DVec3>) -> Vec<Candidate> {
    let (lo, hi) = stage1_pts
        .iter()
        .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(*p), hi.max(*p))
        });
    let a3 = 0.6 * 0.5 * (hi - lo).length();
    let axes_to_try = match known_axis {
        Some(a) => vec![a.normalize()],
        None => vec![DVec3::X, DVec3::Y, DVec3::Z],
    };
    axes_to_try
        .into_iter()
        .map(|axis| {
            let hint = if axis.dot(DVec3::X).abs() > 0.9 {
                DVec3::Y
            } else {
                DVec3::X
            };
            let mut start = start_for_axis(stage1_pts, axis, hint, 1.5);
            start.shape.a3 = a3;
            start
        })
        .collect()
}

/// Both stages' solver settings: the loss, what is held (a known axis: the turns off
/// it; known shape parameters), and each stage's stopping rules.
fn solver_options(o: &FitOptions, known: &[Option<f64>; 6]) -> (SolverOptions, SolverOptions) {
    let paper = o.method == Method::Paper;
    let loss = if paper {
        Loss::Squared
    } else {
        Loss::Huber(o.huber)
    };
    let mut opts1 = SolverOptions {
        loss,
        max_iterations: STAGE1_MAX_ITERATIONS,
        cost_tolerance: STAGE1_COST_TOLERANCE,
        prune_after: if paper { 0 } else { STAGE1_PRUNE_AFTER },
        prune_ratio: STAGE1_PRUNE_RATIO,
        // starts that met in one basin run on as one (the paper clouds' stage 1 sends
        // two to five of its twelve starts into one basin)
        merge_tolerance: if paper { 0.0 } else { MERGE_TOLERANCE },
        step_tolerance: STAGE1_STEP_TOLERANCE,
        ..Default::default()
    };
    if o.known_axis.is_some() {
        opts1.fixed[9] = true;
        opts1.fixed[10] = true;
    }
    for (fixed, known) in opts1.fixed.iter_mut().zip(known) {
        *fixed |= known.is_some();
    }
    // (the paper's stage 2 rewards a wider hole)
    let a4_reward = if paper { PAPER_A4_REWARD } else { 0.0 };
    let opts2 = SolverOptions {
        loss,
        shape_prior: [0.0, 0.0, 0.0, -a4_reward, 0.0, 0.0],
        fixed: opts1.fixed,
        step_tolerance: STAGE2_STEP_TOLERANCE,
        max_iterations: STAGE2_MAX_ITERATIONS,
        ..Default::default()
    };
    (opts1, opts2)
}

/// Stage 1's least-squares iterations at most.
pub const STAGE1_MAX_ITERATIONS: usize = 40;
/// Stage 1 stops where the cost's relative decrease stays below this.
pub const STAGE1_COST_TOLERANCE: f64 = 1e-5;
/// Stage 1 stops the starts whose cost is over [`STAGE1_PRUNE_RATIO`] times the best
/// one's after this many iterations.
pub const STAGE1_PRUNE_AFTER: usize = 4;
/// The multiple of the best start's cost over which stage 1 stops a start (after
/// [`STAGE1_PRUNE_AFTER`] iterations).
pub const STAGE1_PRUNE_RATIO: f64 = 1.5;
/// Stage 1 stops where a step moves the fit by less than this (normalised units: the
/// cloud's RMS radius is 1); stage 2 polishes.
pub const STAGE1_STEP_TOLERANCE: f64 = 1e-3;
/// Stage 2 stops where a step moves the fit by less than this (normalised units): such
/// steps no longer move the fit, and near the end Gauss-Newton on a Huber loss converges
/// only linearly, so this saves half the iterations.
pub const STAGE2_STEP_TOLERANCE: f64 = 1e-4;
/// Stage 2's iterations at most, a cap for the tail latency: the 24-case sweeps and the
/// paper clouds gave the same successes and grades at 30 as at 60.
pub const STAGE2_MAX_ITERATIONS: usize = 30;

impl Prepared<'_> {
    /// Stage 1's point set: its sample and the free-space points in front of it.
    pub(super) fn stage1_set(&self) -> PointSet<'_> {
        PointSet {
            surface: &self.stage1_pts,
            free_space: &self.stage1_free,
        }
    }

    /// Stage 2's point set.
    pub(super) fn stage2_set(&self) -> PointSet<'_> {
        PointSet {
            surface: &self.stage2_pts,
            free_space: &self.stage2_free,
        }
    }

    /// The cloud's own scatter in normalised units ([`scatter::local_scatter`]), measured
    /// once.
    pub(super) fn scatter(&self) -> Option<f64> {
        *self
            .scatter
            .get_or_init(|| scatter::local_scatter(self.points).map(|s| s / self.norm.scale))
    }

    /// The solver's box for a stage-2 finalist: sizes no larger than `max_overreach`
    /// times the stage-2 sample's half-extent along the finalist's axes, about its centre.
    pub(super) fn supported_bounds(&self, candidate: &Candidate) -> Bounds {
        let mut bounds = self.bounds;
        if let Some(limit) = self.max_overreach {
            let extent = half_extents_about(candidate, &self.stage2_pts);
            for (i, e) in extent.to_array().into_iter().enumerate() {
                bounds.upper[i] = bounds.upper[i].min((limit * e).max(10.0 * bounds.lower[i]));
            }
        }
        // a known size stays what it is, supported or not
        for (i, v) in self.known.iter().enumerate() {
            if let Some(v) = *v {
                bounds.lower[i] = bounds.lower[i].min(0.5 * v);
                bounds.upper[i] = bounds.upper[i].max(2.0 * v);
            }
        }
        bounds
    }

    /// What the noise model may move from `start` ([`objective::Limits`]): the supported
    /// box, the known shape parameters and the known axis held.
    pub(super) fn likelihood_limits(&self, start: &Candidate) -> objective::Limits {
        objective::Limits {
            bounds: self.supported_bounds(start),
            fixed_shape: self.known.map(|k| k.is_some()),
            fixed_axis: self.known_axis,
            deadline: self.deadline,
        }
    }

    /// The other reading of the top view of `fitted` ([`starts::turned_dual`]) inside its
    /// supported box; none where the caller's dimensions fix a1, a2 or eps2.
    pub(super) fn turned_dual(&self, fitted: &Candidate) -> Option<Candidate> {
        if self.known[0].is_some() || self.known[1].is_some() || self.known[5].is_some() {
            return None;
        }
        // a roundish top view is its own other reading
        if (fitted.shape.eps2 - 1.0).abs() < search::polish::DUAL_MIN_ROUNDNESS_GAP {
            return None;
        }
        let mut dual = starts::turned_dual(fitted);
        dual.shape = self.supported_bounds(fitted).interior(&dual.shape);
        Some(dual)
    }

    /// The hollow reading of a closed fit ([`starts::hollowed`], a4
    /// [`search::HOLLOWED_A4`]) inside its supported box, where a4 is free, no size is
    /// known and the view is across the fit's axis ([`search::HOLLOW_ACROSS_DEGREES`]);
    /// none for a fit with a hole already, and none without a viewpoint (a cloud all round
    /// its object shows a hole's inside).
    pub(super) fn hollowed(&self, fitted: &Candidate) -> Option<Candidate> {
        if self.skip.contains(&Stage::HollowedReading)
            || fitted.shape.a4 >= 1.0
            || self.known[..4].iter().any(Option::is_some)
            || !search::seen_across_its_axis(fitted, self.viewpoint?)
        {
            return None;
        }
        let mut hollow = starts::hollowed(fitted, search::HOLLOWED_A4);
        hollow.shape = self.supported_bounds(&hollow).interior(&hollow.shape);
        Some(hollow)
    }

    /// `hollow`, a hollow reading ([`Prepared::hollowed`]) that stood against its closed
    /// fit (so with a hole, a4 > 1), around a hole [`search::NARROWER_HOLE`] as wide
    /// ([`starts::hollowed`] with the outline kept), inside its supported box.
    pub(super) fn narrowed(&self, hollow: &Candidate) -> Candidate {
        let a4 = 1.0 + search::NARROWER_HOLE * (hollow.shape.a4 - 1.0);
        let mut narrower = starts::hollowed(hollow, a4);
        narrower.shape = self.supported_bounds(&narrower).interior(&narrower.shape);
        narrower
    }

    /// The rings `fitted`, a closed body (a4 < 1), may be lying across
    /// ([`starts::rings_across`]) inside their supported boxes, those the viewpoint sees
    /// across their axis ([`search::seen_across_its_axis`]: nearer their axis it would
    /// have seen into the hole, and the closed fit would not stand over it). None without
    /// a viewpoint (a cloud all round a ring shows its hole), for a fit with a hole, a
    /// superellipsoid's fit, or a fit whose axis or sizes are known (the caller has said
    /// which way the hole goes, or how large the body is).
    pub(super) fn rings_across(&self, fitted: &Candidate) -> Vec<Candidate> {
        let Some(viewpoint) = self.viewpoint else {
            return Vec::new();
        };
        if self.skip.contains(&Stage::RingsAcross)
            || fitted.shape.a4 >= 1.0
            || self.holds_a4_at_zero()
            || self.known_axis
            || self.known[..4].iter().any(Option::is_some)
        {
            return Vec::new();
        }
        starts::rings_across(fitted, search::HOLLOWED_A4)
            .into_iter()
            .filter(|ring| search::seen_across_its_axis(ring, viewpoint))
            .map(|mut ring| {
                ring.shape = self.supported_bounds(&ring).interior(&ring.shape);
                ring
            })
            .collect()
    }

    /// Whether this is a superellipsoid's fit: a4 held at 0 (`model: superellipsoid`, or
    /// `auto`'s second fit).
    pub(super) fn holds_a4_at_zero(&self) -> bool {
        self.known[3] == Some(0.0)
    }

    /// The readings of `fitted` with its axes cycled ([`starts::axes_cycled`]) inside its
    /// supported box, for a fit with a4 held at 0 and no size or exponent known; none
    /// otherwise (a hole's axis is its own).
    pub(super) fn axes_cycled(&self, fitted: &Candidate) -> Vec<Candidate> {
        let free = |i: usize| self.known[i].is_none();
        if !self.holds_a4_at_zero() || ![0, 1, 2, 4, 5].into_iter().all(free) {
            return Vec::new();
        }
        starts::axes_cycled(fitted)
            .into_iter()
            .map(|mut c| {
                c.shape = self.supported_bounds(&c).interior(&c.shape);
                c
            })
            .collect()
    }

    /// What the noise model takes the sensor to have seen from: the viewpoint and its
    /// frame's edges.
    pub(super) fn sight(&self) -> Option<Sight> {
        self.viewpoint.map(|viewpoint| Sight {
            viewpoint,
            field: self.field,
        })
    }

    pub(super) fn overreaches(&self, candidate: &Candidate, sample: &[DVec3]) -> bool {
        self.max_overreach
            .is_some_and(|limit| overreach(candidate, sample) > limit)
    }
}

/// The cloud's largest |x|, |y|, |z| in the candidate's canonical frame.
pub(super) fn half_extents_about(candidate: &Candidate, points: &[DVec3]) -> DVec3 {
    let inverse = candidate.pose.rotation.inverse();
    points.iter().fold(DVec3::ZERO, |e, p| {
        e.max((inverse * (*p - candidate.pose.translation)).abs())
    })
}

/// A size reaching past the points by more than this is not supported by them (the
/// ground-truth suite's true shapes reach at most 0.92 of their noisy clouds, full or
/// single view; the pot's stretched fits 2.5 and more).
pub const MAX_OVERREACH: f64 = 1.5;

/// Stage 1's [`SolverOptions::merge_tolerance`] (normalised units, radians). Starts that
/// close on one another converge to one solution: at 1e-2 apart the paper clouds' starts
/// ended within 1e-4 of each other.
pub(super) const MERGE_TOLERANCE: f64 = 1e-2;

/// How far a candidate's sizes reach beyond the cloud: the largest ratio, over the
/// canonical axes, of a1, a2, a3 to the cloud's half-extent about the candidate's centre
/// along that axis. A shape the points support has at most about 1, on a single view
/// too (the silhouette spans the object across the view, the front face lies a
/// half-extent from the centre, and a1, a2 are at most the outer radii a1(1 + a4),
/// a2(1 + a4)). The outer radii themselves are not used: the ring the paper fits to its
/// pot reaches twice past the pot's wall on the outside.
/// Least squares alone happily stretches a size to its bound where no point watches
/// (measured on the paper's pot: a cylinder ten times taller than the pot, or a body
/// stretched sideways, each fitted the wall with a lower cost than the true supertoroid).
pub fn overreach(candidate: &Candidate, points: &[DVec3]) -> f64 {
    let extent = half_extents_about(candidate, points);
    let s = &candidate.shape;
    let reach = DVec3::new(s.a1, s.a2, s.a3);
    (reach / extent.max(DVec3::splat(1e-9))).max_element()
}

//! What a caller asks of a fit: the method, the seed, the priors (a known axis or shape
//! parameters, the viewpoint), the time budget, and the pipeline's settings.

use super::*;

/// The default of [`FitOptions::stage1_points`]: stage 1's sample.
pub const STAGE1_POINTS: usize = 150;
/// The default of [`FitOptions::stage2_points`]: stage 2's sample.
pub const STAGE2_POINTS: usize = 1000;
/// The default of [`FitOptions::huber`].
pub const HUBER: f64 = 0.05;
/// The default of [`FitOptions::refine_scale`].
pub const REFINE_SCALE: f64 = 1.5;

/// The a4 reward of the paper's procedure (its stage-2 term for a wider hole).
pub const PAPER_A4_REWARD: f64 = 1e-4;

/// The shape parameters' names, in their order.
pub const SHAPE_NAMES: [&str; 6] = ["a1", "a2", "a3", "a4", "eps1", "eps2"];

/// Reads known shape parameters from text, `name=value` pairs separated by commas (`:`
/// works as well as `=`, for query strings): `"a1=0.05,a4=2.1"` -> a1 and a4 known.
pub fn parse_known_shape(text: &str) -> Result<[Option<f64>; 6], String> {
    let mut known = [None; 6];
    for pair in text.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        let (name, value) = pair
            .split_once(['=', ':'])
            .ok_or_else(|| format!("known shape: '{pair}' is not name=value"))?;
        let i = SHAPE_NAMES
            .iter()
            .position(|n| *n == name.trim())
            .ok_or_else(|| {
                format!("known shape: '{name}' is not one of a1, a2, a3, a4, eps1, eps2")
            })?;
        let value: f64 = value
            .trim()
            .parse()
            .map_err(|_| format!("known shape: '{value}' is not a number"))?;
        if known[i].replace(value).is_some() {
            return Err(format!("known shape: {name} given twice"));
        }
    }
    Ok(known)
}

/// Adds an a3 given on its own (the `a3` option) to known shape parameters; a3 given
/// both ways is an error.
pub fn known_with_a3(
    mut known: [Option<f64>; 6],
    a3: Option<f64>,
) -> Result<[Option<f64>; 6], String> {
    if let Some(a3) = a3 {
        if known[2].is_some() {
            return Err("a3 given twice (as a3 and in known)".into());
        }
        known[2] = Some(a3);
    }
    Ok(known)
}

/// Which pipeline runs.
#[derive(
    Clone,
    Copy,
    Debug,
    Default,
    PartialEq,
    Eq,
    serde::Serialize,
    serde::Deserialize,
    clap::ValueEnum,
    utoipa::ToSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// one bounded search on one objective ([`search`]): least squares from the broad
    /// start set, the candidates ranked and refined by the noise model's likelihood
    /// ([`objective`]), the likeliest polished by the noise model on more points
    #[default]
    Default,
    /// the paper's procedure as a baseline: three starts along the cloud frame's x, y, z
    /// at the centroid, a3 started at 0.6 of the bounding box half-diagonal, plain least
    /// squares, the lowest stage-1 cost to stage 2. Stage 1 minimises the meridian
    /// distance: the paper's top-view cost cannot be rebuilt from its text (the weights
    /// are unpublished).
    Paper,
}

#[derive(Clone, Debug)]
pub struct FitOptions {
    pub method: Method,
    /// supertoroid, superellipsoid (a4 held at 0), or both and the better by BIC
    /// ([`model_choice`])
    pub model: Model,
    pub seed: u64,
    pub stage1_points: usize,
    pub stage2_points: usize,
    /// Huber threshold of the search's least squares, as a fraction of the cloud's RMS
    /// radius
    pub huber: f64,
    /// a precise cloud's candidates are refined under a Cauchy loss whose scale is this
    /// many robust residual scales (1.4826 · median |r| at the candidate); 0 turns the
    /// refinement off (`robust_least_squares` in [`search`]).
    pub refine_scale: f64,
    pub eps_min: f64,
    pub eps_max: f64,
    /// prior: the hole axis in world coordinates, if known (e.g. "on a table, hole up")
    pub known_axis: Option<DVec3>,
    /// prior: shape parameters known in advance (a product's dimensions), in the order
    /// a1 a2 a3 a4 eps1 eps2, sizes in world units; each one given is held fixed. A
    /// one-sided view cannot tell how thick an object is, nor how wide its hole; a
    /// catalogue can. See [`parse_known_shape`] for the text form.
    pub known_shape: [Option<f64>; 6],
    /// where the depth sensor that saw the cloud was (world units; the origin for a cloud
    /// in the camera's own frame). The space between it and every point is empty, so a
    /// candidate that puts solid there pays for it (see [`free_space`]).
    pub viewpoint: Viewpoint,
    /// the edges of the viewpoint's frame (a camera's image, or the region of it the
    /// points were read from), in the cloud's frame: the sensor saw nothing past them, so
    /// an object they cut is not expected to show points there ([`super::sight`])
    pub field_of_view: Option<FieldOfView>,
    /// prior: the surface the object rests on (a table, in world units, its normal
    /// towards the object): the object does not reach below it (see
    /// [`free_space::below_support`])
    pub support: Option<crate::model::Plane>,
    /// prior: the table the object stands on (world units, its normal towards the
    /// object). A resting object has an axis along the table's normal and reaches down to
    /// the table, so the search also starts from the table's normal and the two axes of
    /// the object's footprint on it, each box reaching from the table to the object's top
    /// ([`starts::resting_starts`])
    pub resting_on: Option<crate::model::Plane>,
    /// points the sensor saw past, in the cloud's frame: free space the object does not
    /// fill (a scene gives the rays to the table seen through and beside each object)
    pub seen_through: Vec<DVec3>,
    /// a fit noisy enough for it ([`LIKELIHOOD_NOISE_RATIO`] of its thinnest half-axis,
    /// [`LIKELIHOOD_VIEW_NOISE_RATIO`] with a viewpoint) is refined to the maximum
    /// likelihood of a model of the noise (and, with a viewpoint, of what the sensor saw;
    /// see [`objective`], [`likelihood`]); the paper's method never is
    pub noise_model: bool,
    /// a fit the noise model refined is refined by it once more at the end, on up to this
    /// many of the cloud's points (all of them where the cloud has fewer), and its top
    /// view read both ways again ([`search::polish`]); 0 turns it off
    pub polish_points: usize,
    /// optional stages left out, for ablations ([`ablation`]); empty for every caller
    /// but the benchmarks
    pub skip: Vec<ablation::Stage>,
    /// the fit's time budget in milliseconds, counted from the cloud's preparation: no
    /// likelihood step of the search or the polish is taken past it, and the polish
    /// starts only while the fit's time is under it; the least-squares rounds always
    /// complete. A stage cut short or left out for it is named in `timing_ms.over_budget`.
    /// None (the default): no budget, and the fit does not depend on the machine's speed.
    pub time_budget_ms: Option<f64>,
}

impl Default for FitOptions {
    fn default() -> Self {
        Self {
            method: Method::Default,
            model: Model::Supertoroid,
            seed: 0,
            stage1_points: STAGE1_POINTS,
            stage2_points: STAGE2_POINTS,
            huber: HUBER,
            refine_scale: REFINE_SCALE,
            eps_min: 0.1,
            eps_max: 2.0,
            known_axis: None,
            known_shape: [None; 6],
            viewpoint: Viewpoint::Auto,
            field_of_view: None,
            support: None,
            resting_on: None,
            seen_through: Vec::new(),
            noise_model: true,
            polish_points: POLISH_POINTS,
            skip: Vec::new(),
            time_budget_ms: None,
        }
    }
}

impl FitOptions {
    /// What is left of the time budget once `spent_ms` of it is gone (at least a
    /// microsecond, so that a stage run after it is still a valid option and stops at once);
    /// None without a budget.
    pub(crate) fn budget_left(&self, spent_ms: f64) -> Option<f64> {
        self.time_budget_ms
            .map(|budget| (budget - spent_ms).max(1e-3))
    }

    /// The solver's box in the normalised frame (the cloud's RMS radius is 1): sizes in
    /// [1e-3, 10], a4 up to 8, eps in [eps_min, eps_max].
    pub fn bounds(&self) -> Bounds {
        Bounds::new(1e-3, 10.0, 8.0, self.eps_min, self.eps_max)
    }
}

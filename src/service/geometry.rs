//! Routes on a fitted object rather than on a cloud: surface queries and grasps
//! (`crate::grasp`). A fit's answer can be posted as the `object` as it came back.

use super::AppState;
use super::api::{RequestId, content_type, read_body};
use super::error::{ApiError, ErrorBody};
use crate::fit::FitReport;
use crate::grasp::{GraspOptions, GraspsOut, SurfacePoint, surface};
use crate::model::FittedObject;
use axum::Extension;
use axum::Json;
use axum::body::Body;
use axum::extract::State;
use axum::http::{HeaderMap, StatusCode};
use glam::{DQuat, DVec3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::sync::Arc;
use utoipa::ToSchema;

type Shared = State<Arc<AppState>>;

/// The most surface points one request may ask for on a grid or at parameters.
pub const MAX_SURFACE_POINTS: usize = 1_000_000;
/// The most points one request may ask the nearest surface points of (each takes tens
/// of microseconds: a grid search and Gauss-Newton steps).
pub const MAX_NEAREST_POINTS: usize = 20_000;

/// Exactly one of `grid`, `parameters`, `points`.
#[derive(Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct SurfaceRequest {
    /// the object (a fit's JSON as it came back will do: only `shape` and `pose` are read)
    pub object: FittedObject,
    /// [n_eta, n_omega]: a grid at its cells' centres
    #[schema(value_type = Option<Vec<usize>>)]
    pub grid: Option<[usize; 2]>,
    /// [[eta, omega], ...]: the surface at these parameters (paper eq. 2)
    #[schema(value_type = Option<Vec<Vec<f64>>>)]
    pub parameters: Option<Vec<[f64; 2]>>,
    /// [[x, y, z], ...] in the fit's frame: the nearest surface points
    #[schema(value_type = Option<Vec<Vec<f64>>>)]
    pub points: Option<Vec<[f64; 3]>>,
}

#[derive(Serialize, ToSchema)]
pub struct SurfaceResponse {
    pub request_id: String,
    pub points: Vec<SurfacePoint>,
}

#[derive(Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct GraspsRequest {
    /// the object (a fit's JSON as it came back will do: `shape`, `pose` and, for the
    /// camera, `viewpoint.position` are read)
    pub object: ObjectWithViewpoint,
    pub options: GraspOptions,
}

/// A fitted object and, where the fit had one, its viewpoint.
#[derive(Deserialize, ToSchema)]
pub struct ObjectWithViewpoint {
    #[serde(flatten)]
    pub object: FittedObject,
    pub viewpoint: Option<ViewpointIn>,
}

#[derive(Deserialize, ToSchema)]
pub struct ViewpointIn {
    #[schema(value_type = Option<Vec<f64>>)]
    pub position: Option<[f64; 3]>,
}

#[derive(Serialize, ToSchema)]
pub struct GraspsResponse {
    pub request_id: String,
    #[serde(flatten)]
    pub grasps: GraspsOut,
}

fn invalid(code: &'static str) -> impl Fn(String) -> ApiError {
    move |m| ApiError::unprocessable(code, m)
}

fn json_only(headers: &HeaderMap) -> Result<(), ApiError> {
    let kind = content_type(headers);
    if kind != "application/json" {
        return Err(ApiError::new(
            StatusCode::UNSUPPORTED_MEDIA_TYPE,
            "unsupported_media_type",
            format!("content type {kind:?}: send application/json"),
        ));
    }
    Ok(())
}

/// A fit request's grasp options checked before the fit runs (a bad gripper is a 422 at
/// once, not after the fit).
pub fn checked_grasp_options(
    options: Option<GraspOptions>,
) -> Result<Option<GraspOptions>, ApiError> {
    if let Some(o) = &options {
        // any valid object will do to check the options
        let probe = crate::model::Shape::new(1.0, 1.0, 1.0, 0.0, 1.0, 1.0);
        o.request(probe, crate::model::Pose::IDENTITY, None)
            .map_err(invalid("invalid_grasp_options"))?;
    }
    Ok(options)
}

/// The grasps on a finished fit, its viewpoint the camera unless the options give one.
pub fn grasps_of_fit(fit: &FitReport, options: &GraspOptions) -> Result<GraspsOut, ApiError> {
    let [w, x, y, z] = fit.pose.quaternion_wxyz;
    let pose = crate::model::Pose::new(
        DQuat::from_xyzw(x, y, z, w),
        DVec3::from_array(fit.pose.translation),
    );
    let camera = fit.viewpoint.position.map(DVec3::from_array);
    options
        .plan(fit.shape, pose, camera)
        .map_err(invalid("invalid_grasp_options"))
}

/// Points of a fitted surface with normals, principal curvatures and directions.
///
/// On a grid of the parameters, at given parameters, or nearest to given points. At the
/// parametrisation's seams the quantities are taken beside them (`seam: true`).
#[utoipa::path(
    post, path = "/v1/surface",
    request_body(content((SurfaceRequest = "application/json"))),
    responses(
        (status = 200, body = SurfaceResponse),
        (status = 400, description = "malformed JSON", body = ErrorBody),
        (status = 413, description = "body over the limit", body = ErrorBody),
        (status = 415, description = "not JSON", body = ErrorBody),
        (status = 422, description = "a bad object or query", body = ErrorBody)
    )
)]
pub async fn surface(
    State(state): Shared,
    Extension(id): Extension<RequestId>,
    headers: HeaderMap,
    body: Body,
) -> Result<Json<SurfaceResponse>, ApiError> {
    json_only(&headers)?;
    let bytes = read_body(&state, body).await?;
    let request: SurfaceRequest = ApiError::parse_json(&bytes)?;
    let (shape, pose) = request
        .object
        .validated()
        .map_err(invalid("invalid_object"))?;
    // thousands of points take milliseconds to seconds: off the async workers
    let points = off_the_workers(move || surface_points(&request, &shape, &pose)).await??;
    // an object of extreme sizes or exponents overflows the surface's quantities: refused
    // rather than answered with nulls where numbers belong
    if let Some(p) = points.iter().find(|p| !p.is_finite()) {
        return Err(invalid("invalid_object")(format!(
            "the surface's quantities at eta {}, omega {} are not finite: the object's sizes or \
             exponents are out of the range this model can be evaluated in",
            p.eta, p.omega
        )));
    }
    Ok(Json(SurfaceResponse {
        request_id: id.0,
        points,
    }))
}

fn surface_points(
    request: &SurfaceRequest,
    shape: &crate::model::Shape,
    pose: &crate::model::Pose,
) -> Result<Vec<SurfacePoint>, ApiError> {
    let bad_query = invalid("invalid_query");
    match (&request.grid, &request.parameters, &request.points) {
        (Some([n_eta, n_omega]), None, None) => {
            let count = n_eta.saturating_mul(*n_omega);
            if count == 0 || count > MAX_SURFACE_POINTS {
                return Err(bad_query(format!(
                    "grid must have between 1 and {MAX_SURFACE_POINTS} points, got {n_eta} x {n_omega}"
                )));
            }
            Ok(surface::grid(shape, pose, *n_eta, *n_omega))
        }
        (None, Some(parameters), None) => {
            too_many(parameters.len(), MAX_SURFACE_POINTS)?;
            parameters
                .iter()
                .map(|[eta, omega]| surface::at_parameters(shape, pose, *eta, *omega))
                .collect::<Result<_, _>>()
                .map_err(bad_query)
        }
        (None, None, Some(points)) => {
            too_many(points.len(), MAX_NEAREST_POINTS)?;
            points
                .par_iter()
                .map(|p| surface::nearest(shape, pose, DVec3::from_array(*p)))
                .collect::<Result<_, _>>()
                .map_err(bad_query)
        }
        _ => Err(bad_query(
            "give exactly one of grid, parameters and points".into(),
        )),
    }
}

/// Runs CPU work of milliseconds to seconds on tokio's blocking pool, off the async
/// workers that serve every other request.
pub(super) async fn off_the_workers<T: Send + 'static>(
    work: impl FnOnce() -> T + Send + 'static,
) -> Result<T, ApiError> {
    tokio::task::spawn_blocking(work)
        .await
        .map_err(|e| ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, "internal", e.to_string()))
}

fn too_many(n: usize, limit: usize) -> Result<(), ApiError> {
    if n > limit {
        return Err(ApiError::unprocessable(
            "invalid_query",
            format!("at most {limit} points per request, got {n}"),
        ));
    }
    Ok(())
}

/// Parallel-jaw grasps for a fitted object and a gripper, best first.
///
/// Contacts on the fitted surface, checked against the friction cone, the opening, the
/// surface and the support plane (where given), never from behind the object as the
/// camera saw it; see `crate::grasp::plan` for the candidates and the score.
#[utoipa::path(
    post, path = "/v1/grasps",
    request_body(content((GraspsRequest = "application/json"))),
    responses(
        (status = 200, body = GraspsResponse),
        (status = 400, description = "malformed JSON", body = ErrorBody),
        (status = 413, description = "body over the limit", body = ErrorBody),
        (status = 415, description = "not JSON", body = ErrorBody),
        (status = 422, description = "a bad object or gripper", body = ErrorBody)
    )
)]
pub async fn grasps(
    State(state): Shared,
    Extension(id): Extension<RequestId>,
    headers: HeaderMap,
    body: Body,
) -> Result<Json<GraspsResponse>, ApiError> {
    json_only(&headers)?;
    let bytes = read_body(&state, body).await?;
    let request: GraspsRequest = ApiError::parse_json(&bytes)?;
    let (shape, pose) = request
        .object
        .object
        .validated()
        .map_err(invalid("invalid_object"))?;
    let camera = request
        .object
        .viewpoint
        .and_then(|v| v.position)
        .map(DVec3::from_array);
    let options = request.options;
    let grasps = off_the_workers(move || options.plan(shape, pose, camera))
        .await?
        .map_err(invalid("invalid_grasp_options"))?;
    Ok(Json(GraspsResponse {
        request_id: id.0,
        grasps,
    }))
}

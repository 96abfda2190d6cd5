//! Routes, request and response types, and content negotiation.
//!
//! Bodies are read with the configured limit (413 beyond) and parsed here rather than by
//! axum's extractors, so that every failure gets the JSON error body of [`ApiError`].

use super::AppState;
use super::error::{ApiError, ErrorBody, ErrorCode, ErrorDetail};
use super::fitter::{FitJob, Readiness};
use super::metrics::{CodeLabel, RouteLabel, RouteStatus};
use crate::eval::Backend;
use crate::fit::{FitOptions, FitReport, Viewpoint};
use crate::io::depth::{self, DepthOptions, PinholeIntrinsics, Roi};
use crate::io::{Format, ReadLimits};
use axum::body::{Body, Bytes};
use axum::extract::{FromRequest, MatchedPath, Multipart, Query, Request, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::middleware::{self, Next};
use axum::response::{Html, IntoResponse, Response};
use axum::routing::{get, post};
use axum::{Extension, Json, Router};
use base64::Engine;
use glam::DVec3;
use serde::{Deserialize, Serialize};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;
use utoipa::{IntoParams, OpenApi, ToSchema};

type Shared = State<Arc<AppState>>;

/// Fit options a request may give (all optional).
#[derive(Clone, Debug, Default, Deserialize, Serialize, ToSchema, IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct FitRequestOptions {
    /// seed of the random downsampling (default 0); the same seed gives the same fit
    pub seed: Option<u64>,
    /// auto (default: the service's evaluator), gpu, or cpu
    pub backend: Option<Backend>,
    /// prior: the hole axis [x, y, z] in the cloud's frame, e.g. [0, 0, 1] for "on a
    /// table, hole up" in a z-up frame
    /// (in a query string: `axis=0,0,1`)
    #[param(value_type = Option<Vec<f64>>)]
    #[serde(default, deserialize_with = "axis_from_array_or_text")]
    pub axis: Option<[f64; 3]>,
    /// prior: the section half-height a3 in the cloud's units (held fixed)
    pub a3: Option<f64>,
    /// prior: known shape parameters, held fixed: `{"a1": 0.05, "a4": 2.1}` (sizes in the
    /// cloud's units; a product's dimensions), or in a query string `known=a1:0.05,a4:2.1`
    #[param(value_type = Option<String>)]
    #[schema(value_type = Option<std::collections::BTreeMap<String, f64>>)]
    #[serde(default, deserialize_with = "known_from_object_or_text")]
    pub known: Option<[Option<f64>; 6]>,
    /// where the depth sensor was: [x, y, z] in the cloud's frame, "none" for a view from
    /// nowhere (a merged all-round cloud), or "auto" (the default): a PCD header's
    /// VIEWPOINT, else the frame's origin where the cloud is a view from it (as sensors
    /// write clouds), else none; depth frames use their camera. The fit keeps solid out
    /// of the space the sensor saw through (in a query string: `viewpoint=0,0,0`)
    #[param(value_type = Option<String>)]
    #[schema(schema_with = crate::fit::viewpoint::request_schema)]
    #[serde(default)]
    pub viewpoint: Option<Viewpoint>,
    /// time budget in milliseconds: no likelihood step of the search or the polish is
    /// taken past it; the least-squares rounds always complete (default: no budget; a
    /// stage cut short or left out is named in `timing_ms.over_budget`)
    pub time_budget_ms: Option<f64>,
    /// pipeline: default (one bounded search on the noise model) or paper (the paper's
    /// procedure, a baseline)
    pub method: Option<crate::fit::Method>,
    /// model: supertoroid (a4 free), superellipsoid (a4 = 0) or auto (both fitted, the
    /// lower BIC chosen; `model` in the answer gives both); default supertoroid, auto for
    /// depth frames (`/v1/fit/depth`, `/v1/scene`)
    pub model: Option<crate::fit::Model>,
    /// input format for raw bodies: xyz, pcd, ply, raw (default: sniffed)
    pub format: Option<Format>,
    /// plan parallel-jaw grasps on the fit (JSON bodies only): the gripper and the
    /// options of `/v1/grasps`; the fit's viewpoint is the camera unless one is given
    #[param(ignore)]
    pub grasps: Option<crate::grasp::GraspOptions>,
}

/// Known shape parameters as a JSON object `{"a1": 0.05}` or as text `"a1:0.05"`.
fn known_from_object_or_text<'de, D: serde::Deserializer<'de>>(
    d: D,
) -> Result<Option<[Option<f64>; 6]>, D::Error> {
    #[derive(Deserialize)]
    #[serde(untagged)]
    enum Known {
        Object(std::collections::BTreeMap<String, f64>),
        Text(String),
    }
    let text = match Option::<Known>::deserialize(d)? {
        None => return Ok(None),
        Some(Known::Text(t)) => t,
        Some(Known::Object(m)) => m
            .iter()
            .map(|(k, v)| format!("{k}={v:e}"))
            .collect::<Vec<_>>()
            .join(","),
    };
    crate::fit::parse_known_shape(&text)
        .map(Some)
        .map_err(serde::de::Error::custom)
}

/// The axis as a JSON array `[x, y, z]` or as text `"x,y,z"` (query strings).
fn axis_from_array_or_text<'de, D: serde::Deserializer<'de>>(
    d: D,
) -> Result<Option<[f64; 3]>, D::Error> {
    vector_from_array_or_text(d, "axis x,y,z")
}

fn vector_from_array_or_text<'de, D: serde::Deserializer<'de>>(
    d: D,
    what: &str,
) -> Result<Option<[f64; 3]>, D::Error> {
    #[derive(Deserialize)]
    #[serde(untagged)]
    enum Axis {
        Array([f64; 3]),
        Text(String),
    }
    match Option::<Axis>::deserialize(d)? {
        None => Ok(None),
        Some(Axis::Array(a)) => Ok(Some(a)),
        Some(Axis::Text(t)) => crate::model::parse_floats::<3>(&t, what)
            .map(Some)
            .map_err(serde::de::Error::custom),
    }
}

impl FitRequestOptions {
    pub(super) fn job(&self, points: Vec<DVec3>) -> Result<FitJob, ApiError> {
        let defaults = FitOptions::default();
        let known_axis = match self.axis {
            Some(a) => {
                let a = DVec3::from_array(a);
                if !a.is_finite() || a.length() == 0.0 {
                    return Err(ApiError::unprocessable(
                        "invalid_option",
                        "axis must be a finite non-zero vector",
                    ));
                }
                Some(a)
            }
            None => None,
        };
        Ok(FitJob {
            points,
            options: FitOptions {
                seed: self.seed.unwrap_or(0),
                known_axis,
                known_shape: crate::fit::known_with_a3(self.known.unwrap_or([None; 6]), self.a3)
                    .map_err(|m| ApiError::unprocessable("invalid_option", m))?,
                viewpoint: self.viewpoint.unwrap_or_default(),
                method: self.method.unwrap_or_default(),
                model: self.model.unwrap_or(defaults.model),
                time_budget_ms: self.time_budget_ms,
                ..defaults
            },
            backend: self.backend.unwrap_or(Backend::Auto),
        })
    }
}

/// A cloud as JSON.
#[derive(Clone, Debug, Deserialize, Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct FitRequest {
    /// [[x, y, z], ...] in any unit; the fit comes back in the same unit and frame
    #[schema(value_type = Vec<Vec<f64>>)]
    pub points: Vec<[f64; 3]>,
    #[serde(default)]
    pub options: FitRequestOptions,
}

/// `supertoroid fit`'s JSON plus the request id (and the grasps, where asked for).
#[derive(Serialize, ToSchema)]
pub struct FitResponse {
    pub request_id: String,
    #[serde(flatten)]
    pub fit: FitReport,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub grasps: Option<crate::grasp::GraspsOut>,
    /// depth frames: the table the object rests on (normal towards the camera), found in
    /// a box without a mask and taken away, or found around a mask's object
    #[serde(skip_serializing_if = "Option::is_none")]
    pub table: Option<crate::model::Plane>,
}

/// Many clouds in one request.
#[derive(Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct BatchRequest {
    pub clouds: Vec<FitRequest>,
}

/// One result per cloud, in order: `fit` or `error`.
#[derive(Serialize, ToSchema)]
pub struct BatchItem {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fit: Option<FitReport>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub grasps: Option<crate::grasp::GraspsOut>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<ErrorDetail>,
}

#[derive(Serialize, ToSchema)]
pub struct BatchResponse {
    pub request_id: String,
    pub results: Vec<BatchItem>,
}

/// A depth frame as JSON (or the `params` part of a multipart request, without the
/// base64 images).
#[derive(Clone, Debug, Default, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct DepthFitRequest {
    /// base64 of a 16-bit grayscale PNG
    pub depth_png: Option<String>,
    /// base64 of raw little-endian u16 depth, `width` x `height`
    pub depth_raw: Option<String>,
    /// image size: required for raw depth, checked against a PNG when given
    pub width: Option<u32>,
    pub height: Option<u32>,
    pub intrinsics: Option<PinholeIntrinsics>,
    /// metres per depth unit (default 0.001, RealSense D400)
    pub depth_scale: Option<f64>,
    pub roi: Option<Roi>,
    /// base64 of a mask PNG (1- to 16-bit grayscale, non-zero keeps the pixel)
    pub mask_png: Option<String>,
    /// keep depths in [min, max] (scaled units)
    #[schema(value_type = Option<Vec<f64>>)]
    pub depth_range: Option<[f64; 2]>,
    /// the largest plausible object, its bounding-box half-diagonal in the scaled unit
    /// (default 2: metres with a metres-per-unit `depth_scale`); a larger fit is refused
    /// (422 `implausible_size`): a wrong `depth_scale`, or no object in the pixels
    pub max_size: Option<f64>,
    #[serde(default)]
    pub options: FitRequestOptions,
}

#[derive(Serialize, ToSchema)]
pub struct Health {
    pub status: &'static str,
}

#[derive(OpenApi)]
#[openapi(
    info(
        title = "supertoroid",
        description = "Fits supertoroids (one-hole superquadrics) to point clouds and depth frames. \
            Shapes and poses as in the README: world = R·canonical + t, canonical z the hole axis."
    ),
    paths(
        fit_cloud,
        fit_depth,
        fit_batch,
        super::geometry::surface,
        super::geometry::grasps,
        super::scene::scene,
        super::exports::export,
        healthz,
        readyz,
        metrics,
        openapi,
        index
    ),
    components(schemas(
        FitRequest,
        FitRequestOptions,
        FitResponse,
        BatchRequest,
        BatchResponse,
        BatchItem,
        DepthFitRequest,
        super::geometry::SurfaceRequest,
        super::geometry::SurfaceResponse,
        super::geometry::GraspsRequest,
        super::geometry::GraspsResponse,
        super::scene::SceneRequest,
        super::scene::SceneResponse,
        ErrorBody,
        ErrorDetail,
        Readiness,
        Health
    ))
)]
pub struct ApiDoc;

pub fn router(state: Arc<AppState>) -> Router {
    Router::new()
        .route("/", get(index))
        .route("/healthz", get(healthz))
        .route("/readyz", get(readyz))
        .route("/metrics", get(metrics))
        .route("/openapi.json", get(openapi))
        .route("/v1/fit", post(fit_cloud))
        .route("/v1/fit/depth", post(fit_depth))
        .route("/v1/fit/batch", post(fit_batch))
        .route("/v1/surface", post(super::geometry::surface))
        .route("/v1/grasps", post(super::geometry::grasps))
        .route("/v1/scene", post(super::scene::scene))
        .route("/v1/scene/{id}/export", get(super::exports::export))
        .fallback(not_found)
        .layer(axum::extract::DefaultBodyLimit::max(
            state.config.body_limit,
        ))
        .layer(middleware::from_fn_with_state(state.clone(), observe))
        .layer(tower_http::catch_panic::CatchPanicLayer::custom(
            panic_response,
        ))
        .with_state(state)
}

fn panic_response(_: Box<dyn std::any::Any + Send + 'static>) -> Response {
    ApiError::new(
        StatusCode::INTERNAL_SERVER_ERROR,
        "internal",
        "internal error (a bug: please report it with the request)",
    )
    .into_response()
}

async fn not_found() -> ApiError {
    ApiError::new(
        StatusCode::NOT_FOUND,
        "not_found",
        "no such route (see /openapi.json)",
    )
}

/// The request id: the caller's `x-request-id` when it sends one, else generated.
#[derive(Clone, Debug)]
pub struct RequestId(pub String);

static NEXT_ID: AtomicU64 = AtomicU64::new(1);

/// Request ids, one log line per request, and the HTTP metrics.
async fn observe(State(state): Shared, mut request: Request, next: Next) -> Response {
    let start = Instant::now();
    let id = request
        .headers()
        .get("x-request-id")
        .and_then(|v| v.to_str().ok())
        .filter(|v| !v.is_empty() && v.len() <= 128)
        .map(str::to_owned)
        .unwrap_or_else(|| {
            format!(
                "{:08x}-{}",
                std::process::id(),
                NEXT_ID.fetch_add(1, Ordering::Relaxed)
            )
        });
    request.extensions_mut().insert(RequestId(id.clone()));
    let route = request
        .extensions()
        .get::<MatchedPath>()
        .map(|p| p.as_str().to_owned())
        .unwrap_or_else(|| "unmatched".into());
    let method = request.method().clone();
    let mut response = next.run(request).await;
    let status = response.status();
    let elapsed = start.elapsed();
    let m = &state.metrics;
    m.requests
        .get_or_create(&RouteStatus {
            route: route.clone(),
            status: status.as_u16(),
        })
        .inc();
    m.latency
        .get_or_create(&RouteLabel {
            route: route.clone(),
        })
        .observe(elapsed.as_secs_f64());
    if let Some(ErrorCode(code)) = response.extensions().get::<ErrorCode>() {
        m.errors
            .get_or_create(&CodeLabel {
                code: (*code).into(),
            })
            .inc();
    }
    m.queue_depth.set(state.fitter.queued() as i64);
    if let Ok(v) = HeaderValue::from_str(&id) {
        response.headers_mut().insert("x-request-id", v);
    }
    tracing::info!(
        request_id = %id,
        %method,
        route,
        status = status.as_u16(),
        ms = elapsed.as_secs_f64() * 1e3,
        "request"
    );
    response
}

pub(super) async fn read_body(state: &AppState, body: Body) -> Result<Bytes, ApiError> {
    axum::body::to_bytes(body, state.config.body_limit)
        .await
        .map_err(|e| {
            ApiError::new(
                StatusCode::PAYLOAD_TOO_LARGE,
                "body_too_large",
                format!(
                    "the body exceeds the limit of {} bytes ({e})",
                    state.config.body_limit
                ),
            )
        })
}

pub(super) fn content_type(headers: &HeaderMap) -> String {
    headers
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .map(|v| {
            v.split(';')
                .next()
                .unwrap_or("")
                .trim()
                .to_ascii_lowercase()
        })
        .unwrap_or_default()
}

fn limits(state: &AppState) -> ReadLimits {
    ReadLimits {
        max_points: state.config.max_points,
    }
}

fn points_from_json(state: &AppState, points: &[[f64; 3]]) -> Result<Vec<DVec3>, ApiError> {
    if points.len() > state.config.max_points {
        return Err(ApiError::new(
            StatusCode::PAYLOAD_TOO_LARGE,
            "too_many_points",
            format!(
                "{} points (the limit is {})",
                points.len(),
                state.config.max_points
            ),
        ));
    }
    Ok(points.iter().map(|p| DVec3::from_array(*p)).collect())
}

async fn fit_one(state: &AppState, job: FitJob) -> Result<FitReport, ApiError> {
    let report = state.fitter.run(vec![job]).await?.remove(0)?;
    state.metrics.record_fit(&report);
    Ok(report)
}

fn respond(
    id: RequestId,
    fit: FitReport,
    grasps: Option<&crate::grasp::GraspOptions>,
) -> Result<Json<FitResponse>, ApiError> {
    for warning in &fit.warnings {
        tracing::warn!(request_id = %id.0, "{warning}");
    }
    let grasps = grasps
        .map(|options| super::geometry::grasps_of_fit(&fit, options))
        .transpose()?;
    Ok(Json(FitResponse {
        request_id: id.0,
        fit,
        grasps,
        table: None,
    }))
}

/// Fit one cloud.
///
/// The body is JSON (`FitRequest`), or a cloud file as it is (PCD ascii / binary /
/// binary_compressed, PLY, XYZ/CSV text, raw float32 triples) with
/// `application/octet-stream` (or `text/plain`, `text/csv`), its format sniffed or given
/// as `?format=`; options then come in the query.
#[utoipa::path(
    post, path = "/v1/fit",
    params(FitRequestOptions),
    request_body(content(
        (FitRequest = "application/json"),
        (Vec<u8> = "application/octet-stream")
    )),
    responses(
        (status = 200, body = FitResponse),
        (status = 400, description = "malformed JSON or cloud", body = ErrorBody),
        (status = 413, description = "body or point count over the limit", body = ErrorBody),
        (status = 415, description = "unsupported content type or format", body = ErrorBody),
        (status = 422, description = "a cloud no fit can work on, or a bad option", body = ErrorBody),
        (status = 503, description = "queue full; see Retry-After", body = ErrorBody),
        (status = 504, description = "request timeout", body = ErrorBody)
    )
)]
async fn fit_cloud(
    State(state): Shared,
    Extension(id): Extension<RequestId>,
    query: Result<Query<FitRequestOptions>, axum::extract::rejection::QueryRejection>,
    headers: HeaderMap,
    body: Body,
) -> Result<Json<FitResponse>, ApiError> {
    let kind = content_type(&headers);
    let query = query
        .map_err(|e| ApiError::unprocessable("invalid_option", e.body_text()))?
        .0;
    let bytes = read_body(&state, body).await?;
    let mut grasps = None;
    let job = if kind == "application/json" {
        let request: FitRequest = ApiError::parse_json(&bytes)?;
        let points = points_from_json(&state, &request.points)?;
        grasps = super::geometry::checked_grasp_options(request.options.grasps.clone())?;
        request.options.job(points)?
    } else if matches!(
        kind.as_str(),
        "" | "application/octet-stream"
            | "text/plain"
            | "text/csv"
            | "application/x-pcd"
            | "application/ply"
            | "application/x-ply"
    ) {
        let points = crate::io::parse_cloud(&bytes, query.format, limits(&state))?;
        let mut job = query.job(points)?;
        if job.options.viewpoint == Viewpoint::Auto {
            job.options.viewpoint = crate::io::pcd::header_viewpoint(&bytes, query.format);
        }
        job
    } else {
        return Err(ApiError::new(
            StatusCode::UNSUPPORTED_MEDIA_TYPE,
            "unsupported_media_type",
            format!(
                "content type {kind:?}: send application/json or a cloud file as application/octet-stream"
            ),
        ));
    };
    respond(id, fit_one(&state, job).await?, grasps.as_ref())
}

/// Fit the object in a depth frame.
///
/// JSON (`DepthFitRequest`, images in base64), or `multipart/form-data` with a `depth`
/// file part (16-bit PNG, or raw u16 with width and height in `params`), an optional
/// `mask` PNG part, and a `params` JSON part (the JSON request's other fields). The pose
/// comes back in the camera's optical frame (x right, y down, z forward).
#[utoipa::path(
    post, path = "/v1/fit/depth",
    request_body(content(
        (DepthFitRequest = "application/json"),
        (Vec<u8> = "multipart/form-data")
    )),
    responses(
        (status = 200, body = FitResponse),
        (status = 400, description = "malformed JSON, base64 or image", body = ErrorBody),
        (status = 413, body = ErrorBody),
        (status = 415, body = ErrorBody),
        (status = 422, description = "bad intrinsics, sizes, or no valid depth", body = ErrorBody),
        (status = 503, body = ErrorBody)
    )
)]
async fn fit_depth(
    State(state): Shared,
    Extension(id): Extension<RequestId>,
    request: Request,
) -> Result<Json<FitResponse>, ApiError> {
    let (params, depth_bytes, mask_bytes) =
        read_depth_body::<DepthFitRequest>(&state, request).await?;
    let max_size = params.max_size.unwrap_or(DEFAULT_MAX_SIZE);
    if !(max_size.is_finite() && max_size > 0.0) {
        return Err(ApiError::unprocessable(
            "invalid_depth_options",
            format!("max_size must be positive and finite, not {max_size}"),
        ));
    }
    let DepthPoints {
        points,
        notes,
        table,
        field_of_view,
    } = depth_points(&state, &params, depth_bytes, mask_bytes)?;
    // (a depth frame is of things on a table, most without a hole: both models unless the
    // request names one, as `/v1/scene` does)
    let mut request_options = params.options.clone();
    request_options.model = Some(request_options.model.unwrap_or(crate::fit::Model::Auto));
    let mut job = request_options.job(points)?;
    // seen from the camera, within the image (or the box); resting on the table a box held
    job.options = crate::scene::fit::depth_options(&job.options, table.as_ref(), field_of_view);
    let mut fit = fit_one(&state, job).await?;
    if fit.shape.size() > max_size {
        return Err(ApiError::unprocessable(
            "implausible_size",
            format!(
                "the fitted object is {:.3} across (half-diagonal), more than max_size {max_size} \
                 in the depth's scaled unit: check depth_scale (metres per unit, 0.001 for \
                 RealSense) and that the pixels hold one object",
                fit.shape.size()
            ),
        ));
    }
    fit.warnings.extend(notes);
    let mut grasps = super::geometry::checked_grasp_options(params.options.grasps.clone())?;
    // the table found in the box keeps the hand above it
    if let Some(g) = grasps.as_mut() {
        g.plane = g.plane.or(table);
    }
    let mut response = respond(id, fit, grasps.as_ref())?;
    response.table = table;
    Ok(response)
}

/// A request whose body carries a depth frame: its images in base64 (JSON), taken out
/// of it by [`read_depth_body`].
pub(super) trait DepthImages {
    /// depth_png, depth_raw, mask_png
    fn take_images(&mut self) -> [Option<String>; 3];
}

impl DepthImages for DepthFitRequest {
    fn take_images(&mut self) -> [Option<String>; 3] {
        [
            self.depth_png.take(),
            self.depth_raw.take(),
            self.mask_png.take(),
        ]
    }
}

/// A depth frame's request as JSON (images in base64) or `multipart/form-data` (parts
/// `params`, `depth`, `mask`): its parameters, the depth image's bytes and the mask's.
pub(super) async fn read_depth_body<T: serde::de::DeserializeOwned + DepthImages>(
    state: &AppState,
    request: Request,
) -> Result<(T, DepthBytes, Option<Vec<u8>>), ApiError> {
    let kind = content_type(request.headers());
    Ok(if kind == "application/json" {
        let bytes = read_body(state, request.into_body()).await?;
        let mut params: T = ApiError::parse_json(&bytes)?;
        let [depth_png, depth_raw, mask_png] = params.take_images();
        let decode = |field: &str, v: &Option<String>| -> Result<Option<Vec<u8>>, ApiError> {
            v.as_ref()
                .map(|s| {
                    base64::engine::general_purpose::STANDARD
                        .decode(s.as_bytes())
                        .map_err(|e| {
                            ApiError::bad_request("malformed_base64", format!("{field}: {e}"))
                        })
                })
                .transpose()
        };
        let depth = match (
            decode("depth_png", &depth_png)?,
            decode("depth_raw", &depth_raw)?,
        ) {
            (Some(png), None) => DepthBytes::Png(png),
            (None, Some(raw)) => DepthBytes::Raw(raw),
            _ => {
                return Err(ApiError::unprocessable(
                    "invalid_request",
                    "give exactly one of depth_png and depth_raw",
                ));
            }
        };
        let mask = decode("mask_png", &mask_png)?;
        (params, depth, mask)
    } else if kind == "multipart/form-data" {
        // the router's DefaultBodyLimit bounds the multipart stream
        let mut multipart = Multipart::from_request(request, &())
            .await
            .map_err(|e| ApiError::bad_request("malformed_multipart", e.body_text()))?;
        let mut params = None;
        let mut depth = None;
        let mut mask = None;
        while let Some(field) = multipart.next_field().await.map_err(multipart_error)? {
            let name = field.name().unwrap_or("").to_owned();
            let data = field.bytes().await.map_err(multipart_error)?;
            match name.as_str() {
                "params" => params = Some(ApiError::parse_json::<T>(&data)?),
                "depth" => depth = Some(data.to_vec()),
                "mask" => mask = Some(data.to_vec()),
                other => {
                    return Err(ApiError::unprocessable(
                        "invalid_request",
                        format!("unknown part {other:?} (params, depth, mask)"),
                    ));
                }
            }
        }
        let params =
            params.ok_or_else(|| ApiError::unprocessable("invalid_request", "no params part"))?;
        let depth =
            depth.ok_or_else(|| ApiError::unprocessable("invalid_request", "no depth part"))?;
        let depth = if depth.starts_with(b"\x89PNG") {
            DepthBytes::Png(depth)
        } else {
            DepthBytes::Raw(depth)
        };
        (params, depth, mask)
    } else {
        return Err(ApiError::new(
            StatusCode::UNSUPPORTED_MEDIA_TYPE,
            "unsupported_media_type",
            format!("content type {kind:?}: send application/json or multipart/form-data"),
        ));
    })
}

/// The default `max_size` of a depth frame's object (metres with a metres-per-unit
/// depth scale): no table-top object is larger.
pub const DEFAULT_MAX_SIZE: f64 = 2.0;

/// A depth frame whose valid pixels, with no ROI or mask to pick the object, cover more
/// than this share of the image holds a scene, not an object.
pub const WHOLE_FRAME_SHARE: f64 = 0.6;

fn multipart_error(e: axum::extract::multipart::MultipartError) -> ApiError {
    let status = e.status();
    if status == StatusCode::PAYLOAD_TOO_LARGE {
        ApiError::new(status, "body_too_large", e.body_text())
    } else {
        ApiError::bad_request("malformed_multipart", e.body_text())
    }
}

pub(super) enum DepthBytes {
    Png(Vec<u8>),
    Raw(Vec<u8>),
}

/// What a request says of its depth frame, apart from the images.
pub(super) struct Frame {
    pub intrinsics: Option<PinholeIntrinsics>,
    pub depth_scale: Option<f64>,
    pub size: Option<(u32, u32)>,
    pub roi: Option<Roi>,
    pub depth_range: Option<[f64; 2]>,
}

impl Frame {
    /// The frame decoded and its selected pixels (ROI, mask, depth range) back-projected
    /// into the camera's optical frame; the image, and whether a mask was given.
    pub fn back_project(
        &self,
        state: &AppState,
        depth: DepthBytes,
        mask: Option<Vec<u8>>,
    ) -> Result<(crate::scene::table::Pixels, crate::synth::DepthImage, bool), ApiError> {
        let options = self.depth_options()?;
        let scale = options.depth_scale;
        let image = match depth {
            DepthBytes::Png(png) => depth::decode_depth_png(&png, scale, self.size, limits(state))?,
            DepthBytes::Raw(raw) => {
                let (w, h) = self.size.ok_or_else(|| {
                    ApiError::unprocessable(
                        "invalid_depth_options",
                        "raw depth needs width and height",
                    )
                })?;
                depth::decode_depth_raw(&raw, w, h, scale, limits(state))?
            }
        };
        let mask = mask
            .map(|m| depth::decode_mask_png(&m, image.width, image.height, limits(state)))
            .transpose()?;
        let selected = depth::back_project_pixels(&image, &options, mask.as_deref())?;
        Ok((selected, image, mask.is_some()))
    }

    /// How the frame's pixels are read (its intrinsics are required).
    pub fn depth_options(&self) -> Result<DepthOptions, ApiError> {
        let intrinsics = self.intrinsics.ok_or_else(|| {
            ApiError::unprocessable(
                "invalid_depth_options",
                "intrinsics {fx, fy, cx, cy} are required",
            )
        })?;
        Ok(DepthOptions {
            intrinsics,
            depth_scale: self.depth_scale.unwrap_or_else(depth::default_depth_scale),
            roi: self.roi,
            depth_range: self.depth_range,
        })
    }
}

/// A depth frame's object points, as [`depth_points`] reads them.
struct DepthPoints {
    points: Vec<DVec3>,
    /// for the report (an ROI clipped to the image)
    notes: Vec<String>,
    /// the table taken out of a box, or found beside a mask's object
    table: Option<crate::model::Plane>,
    /// the edges of the pixels read
    field_of_view: crate::fit::FieldOfView,
}

/// The frame's selected pixels back-projected ([`DepthPoints`]).
fn depth_points(
    state: &AppState,
    params: &DepthFitRequest,
    depth: DepthBytes,
    mask: Option<Vec<u8>>,
) -> Result<DepthPoints, ApiError> {
    let frame = Frame {
        intrinsics: params.intrinsics,
        depth_scale: params.depth_scale,
        size: params.width.zip(params.height),
        roi: params.roi,
        depth_range: params.depth_range,
    };
    let (selected, image, has_mask) = frame.back_project(state, depth, mask)?;
    let field_of_view = selected.field_of_view;
    let intrinsics = params.intrinsics.expect("checked by back_project");
    let mut notes: Vec<String> = Vec::new();
    // a box without a mask holds the table around the object: take it away; a mask's
    // object has its table around the mask
    use crate::scene::table::{DepthObject, Selection, depth_object};
    let selection = match (params.roi, has_mask) {
        (_, true) => Selection::Mask,
        (Some(_), false) => Selection::DetectorBox,
        (None, false) => Selection::Pixels,
    };
    let (pixels_read, window) = (selected.points.len(), selected.window);
    let seed = params.options.seed.unwrap_or(0);
    let DepthObject {
        points,
        pixels: object_pixels,
        table,
    } =
        depth_object(selected, &image, &frame.depth_options()?, selection, seed).map_err(
            |left| {
                ApiError::unprocessable(
                    "no_object_found",
                    format!(
                        "the box holds a plane (a table) and nothing on it: {left} of {pixels_read} points are off the plane"
                    ),
                )
            },
        )?;
    // an object the edge of the image (or of the box read) cuts is warned, as a scene's is
    notes.extend(crate::scene::fit::edge_warning(
        crate::scene::objects::pixels_on_edge(&object_pixels, window),
        object_pixels.len(),
    ));
    let pixels = image.width as f64 * image.height as f64;
    if params.roi.is_none() && !has_mask && points.len() as f64 > WHOLE_FRAME_SHARE * pixels {
        return Err(ApiError::unprocessable(
            "whole_frame",
            format!(
                "{:.0}% of the frame's pixels have depth and no roi or mask picks the object: \
                 give the object's box (roi) or mask",
                100.0 * points.len() as f64 / pixels
            ),
        ));
    }
    notes.extend(depth::intrinsics_note(
        &intrinsics,
        image.width,
        image.height,
    ));
    notes.extend(
        params
            .roi
            .and_then(|r| Some((r, r.clipped(image.width, image.height)?)))
            .filter(|(r, clipped)| r != clipped)
            .map(|(r, clipped)| {
                format!(
                    "roi clipped to the {}x{} image: ({r}) -> ({clipped})",
                    image.width, image.height
                )
            }),
    );
    Ok(DepthPoints {
        points,
        notes,
        table,
        field_of_view,
    })
}

/// Fit many clouds in one request; each gets its own result or error.
#[utoipa::path(
    post, path = "/v1/fit/batch",
    request_body(content((BatchRequest = "application/json"))),
    responses(
        (status = 200, body = BatchResponse),
        (status = 400, body = ErrorBody),
        (status = 413, body = ErrorBody),
        (status = 415, body = ErrorBody),
        (status = 422, body = ErrorBody),
        (status = 503, body = ErrorBody),
        (status = 504, body = ErrorBody)
    )
)]
async fn fit_batch(
    State(state): Shared,
    Extension(id): Extension<RequestId>,
    headers: HeaderMap,
    body: Body,
) -> Result<Json<BatchResponse>, ApiError> {
    let kind = content_type(&headers);
    if kind != "application/json" {
        return Err(ApiError::new(
            StatusCode::UNSUPPORTED_MEDIA_TYPE,
            "unsupported_media_type",
            "send application/json",
        ));
    }
    let bytes = read_body(&state, body).await?;
    let request: BatchRequest = ApiError::parse_json(&bytes)?;
    if request.clouds.is_empty() {
        return Err(ApiError::unprocessable(
            "invalid_request",
            "clouds is empty",
        ));
    }
    let total: usize = request.clouds.iter().map(|c| c.points.len()).sum();
    if total > state.config.max_points {
        return Err(ApiError::new(
            StatusCode::PAYLOAD_TOO_LARGE,
            "too_many_points",
            format!(
                "{total} points in all (the limit is {})",
                state.config.max_points
            ),
        ));
    }
    let mut jobs = Vec::new();
    let mut grasps = Vec::new();
    for cloud in &request.clouds {
        let points = points_from_json(&state, &cloud.points)?;
        grasps.push(super::geometry::checked_grasp_options(
            cloud.options.grasps.clone(),
        )?);
        jobs.push(cloud.options.job(points)?);
    }
    let results = state.fitter.run(jobs).await?;
    let error_item = |e: ApiError| BatchItem {
        fit: None,
        grasps: None,
        error: Some(ErrorDetail {
            code: e.code.into(),
            message: e.message,
        }),
    };
    let results = results
        .into_iter()
        .zip(&grasps)
        .map(|(r, options)| match r {
            Ok(fit) => {
                state.metrics.record_fit(&fit);
                let planned = options
                    .as_ref()
                    .map(|o| super::geometry::grasps_of_fit(&fit, o))
                    .transpose();
                match planned {
                    Ok(grasps) => BatchItem {
                        fit: Some(fit),
                        grasps,
                        error: None,
                    },
                    Err(e) => error_item(e),
                }
            }
            Err(e) => error_item(e),
        })
        .collect();
    Ok(Json(BatchResponse {
        request_id: id.0,
        results,
    }))
}

/// Alive (touches nothing).
#[utoipa::path(get, path = "/healthz", responses((status = 200, body = Health)))]
async fn healthz() -> Json<Health> {
    Json(Health { status: "ok" })
}

/// Ready: which evaluator fits run on, the adapter, and any degradation.
#[utoipa::path(get, path = "/readyz", responses((status = 200, body = Readiness)))]
async fn readyz(State(state): Shared) -> Json<Readiness> {
    Json(state.fitter.readiness())
}

/// Prometheus metrics (OpenMetrics text format).
#[utoipa::path(get, path = "/metrics", responses((status = 200, content_type = "application/openmetrics-text")))]
async fn metrics(State(state): Shared) -> impl IntoResponse {
    // the queue as it is now, not as the last response left it
    state.metrics.queue_depth.set(state.fitter.queued() as i64);
    (
        [(
            header::CONTENT_TYPE,
            "application/openmetrics-text; version=1.0.0; charset=utf-8",
        )],
        state.metrics.encode(),
    )
}

/// This document.
#[utoipa::path(get, path = "/openapi.json", responses((status = 200, content_type = "application/json")))]
async fn openapi() -> impl IntoResponse {
    Json(super::openapi::document())
}

/// A short page that says what the service is.
#[utoipa::path(get, path = "/", responses((status = 200, content_type = "text/html")))]
async fn index(State(state): Shared) -> Html<String> {
    Html(format!(
        "<!doctype html><html><head><meta charset=\"utf-8\"><title>supertoroid</title></head><body>\
<h1>supertoroid {}</h1>\
<p>Fits supertoroids (objects with one hole: mugs, rolls, gears, bearings, pots) and superellipsoids \
to point clouds and depth frames, for robot grasping.</p>\
<ul><li><code>POST /v1/fit</code>: a cloud (JSON, PCD, PLY, XYZ, float32)</li>\
<li><code>POST /v1/fit/depth</code>: a 16-bit depth frame with intrinsics</li>\
<li><code>POST /v1/fit/batch</code>: many clouds</li>\
<li><a href=\"/openapi.json\">OpenAPI document</a>, <a href=\"/readyz\">readiness</a>, \
<a href=\"/metrics\">metrics</a></li></ul>\
<p>Evaluator: {}</p></body></html>",
        env!("CARGO_PKG_VERSION"),
        html_escape(&state.fitter.describe())
    ))
}

fn html_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

//! `POST /v1/scene`: a whole depth frame split into its table and the objects on it,
//! every object fitted (model `auto` unless the request names one), in one batch on one
//! worker of the fitter (its queue, timeout and GPU as for the fit routes).

use super::AppState;
use super::api::{DepthImages, FitRequestOptions, Frame, RequestId, read_depth_body};
use super::error::{ApiError, ErrorBody};
use super::fitter::FitJob;
use crate::fit::Model;
use crate::io::depth::{PinholeIntrinsics, Roi};
use crate::scene::fit::{SceneReport, assemble, object_clouds, object_options};
use crate::scene::objects::{SceneError, SceneOptions, segment};
use axum::extract::{Request, State};
use axum::{Extension, Json};
use serde::{Deserialize, Serialize};
use std::sync::Arc;
use std::time::Instant;
use utoipa::ToSchema;

/// A depth frame of a table-top scene, as JSON (or the `params` part of a multipart
/// request, without the base64 images). The frame's fields are `DepthFitRequest`'s,
/// written out again: serde cannot flatten them into a struct that refuses unknown
/// fields.
#[derive(Clone, Debug, Default, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct SceneRequest {
    /// base64 of a 16-bit grayscale PNG
    pub depth_png: Option<String>,
    /// base64 of raw little-endian u16 depth, `width` x `height`
    pub depth_raw: Option<String>,
    pub width: Option<u32>,
    pub height: Option<u32>,
    pub intrinsics: Option<PinholeIntrinsics>,
    /// metres per depth unit (default 0.001, RealSense D400)
    pub depth_scale: Option<f64>,
    /// the part of the frame to look at (the workspace)
    pub roi: Option<Roi>,
    /// base64 of a workspace mask PNG (non-zero keeps the pixel)
    pub mask_png: Option<String>,
    /// keep depths in [min, max] (scaled units)
    #[schema(value_type = Option<Vec<f64>>)]
    pub depth_range: Option<[f64; 2]>,
    /// what makes an object (its fewest points, smallest and largest size) and how many
    /// a scene may hold
    #[serde(default)]
    pub scene: SceneOptions,
    /// the objects' fit options (`model` defaults to auto here)
    #[serde(default)]
    pub options: FitRequestOptions,
}

impl DepthImages for SceneRequest {
    fn take_images(&mut self) -> [Option<String>; 3] {
        [
            self.depth_png.take(),
            self.depth_raw.take(),
            self.mask_png.take(),
        ]
    }
}

#[derive(Serialize, ToSchema)]
pub struct SceneResponse {
    pub request_id: String,
    /// where to GET the fitted objects and the table as a simulator scene (a tar of
    /// MJCF, URDF and meshes); absent when no object was fitted
    #[serde(skip_serializing_if = "Option::is_none")]
    pub export: Option<String>,
    #[serde(flatten)]
    pub scene: SceneReport,
}

impl From<SceneError> for ApiError {
    fn from(e: SceneError) -> Self {
        let code = match e {
            SceneError::NoPlane { .. } => "no_table_found",
            SceneError::NoObject { .. } => "no_object_found",
            SceneError::TooManyObjects { .. } => "too_many_objects",
        };
        ApiError::unprocessable(code, e.to_string())
    }
}

/// Find the table in a depth frame and fit every object on it.
///
/// The frame as `/v1/fit/depth` takes it (JSON with base64 images, or multipart with
/// `depth`, optional `mask` and `params` parts); `roi` and `mask` pick the workspace.
/// The table's plane is found over the frame, the points above it are split into
/// objects by distance, and each object is fitted from the camera's viewpoint with
/// model `auto` (supertoroid or superellipsoid by BIC) unless `options.model` says
/// otherwise. Poses come back in the camera's optical frame (x right, y down, z forward).
/// With `options.grasps` each fitted object also gets its grasps, kept above the table.
/// `export` links the scene's simulator files (`GET /v1/scene/{id}/export`).
#[utoipa::path(
    post, path = "/v1/scene",
    request_body(content(
        (SceneRequest = "application/json"),
        (Vec<u8> = "multipart/form-data")
    )),
    responses(
        (status = 200, body = SceneResponse),
        (status = 400, description = "malformed JSON, base64 or image", body = ErrorBody),
        (status = 413, body = ErrorBody),
        (status = 415, body = ErrorBody),
        (status = 422, description = "bad intrinsics or options, no valid depth, no table (`no_table_found`), nothing on it (`no_object_found`), more objects than `max_objects` (`too_many_objects`)", body = ErrorBody),
        (status = 503, body = ErrorBody),
        (status = 504, body = ErrorBody)
    )
)]
pub async fn scene(
    State(state): State<Arc<AppState>>,
    Extension(id): Extension<RequestId>,
    request: Request,
) -> Result<Json<SceneResponse>, ApiError> {
    let start = Instant::now();
    let (params, depth, mask) = read_depth_body::<SceneRequest>(&state, request).await?;
    check_scene_options(&params.scene)?;
    let grasp_options = super::geometry::checked_grasp_options(params.options.grasps.clone())?;
    let frame = Frame {
        intrinsics: params.intrinsics,
        depth_scale: params.depth_scale,
        size: params.width.zip(params.height),
        roi: params.roi,
        depth_range: params.depth_range,
    };
    let (pixels, _, _) = frame.back_project(&state, depth, mask)?;
    let seed = params.options.seed.unwrap_or(0);
    let scene_options = params.scene;
    let segmentation =
        super::geometry::off_the_workers(move || segment(&pixels, &scene_options, seed)).await??;
    let segment_ms = start.elapsed().as_secs_f64() * 1e3;
    let mut options = params.options.clone();
    options.model = Some(options.model.unwrap_or(Model::Auto));
    let jobs = object_clouds(&segmentation)
        .into_iter()
        .zip(&segmentation.objects)
        .map(|(points, object)| {
            let mut job: FitJob = options.job(points)?;
            job.options = object_options(
                &job.options,
                &segmentation.plane,
                scene_options.table_prior,
                &object.seen_through,
                segmentation.field_of_view,
            );
            Ok(job)
        })
        .collect::<Result<Vec<_>, ApiError>>()?;
    let fits = state.fitter.run(jobs).await?;
    let fits = fits
        .into_iter()
        .map(|r| r.map_err(|e| format!("{}: {}", e.code, e.message)))
        .collect();
    let mut scene = assemble(segmentation, fits, segment_ms, start);
    // (after the scene's own warnings joined the fits')
    for fit in scene.objects.iter().filter_map(|o| o.fit.as_ref()) {
        state.metrics.record_fit(fit);
    }
    if let Some(options) = grasp_options {
        // the table found is the hand's floor unless the request gives another
        let options = crate::grasp::GraspOptions {
            plane: options.plane.or(Some(scene.plane)),
            ..options
        };
        for object in &mut scene.objects {
            if let Some(fit) = &object.fit {
                object.grasps = Some(super::geometry::grasps_of_fit(fit, &options)?);
            }
        }
    }
    for object in &scene.objects {
        for warning in object.fit.iter().flat_map(|f| &f.warnings) {
            tracing::warn!(request_id = %id.0, object = object.id, "{warning}");
        }
    }
    let objects: Vec<_> = scene
        .objects
        .iter()
        .filter_map(|o| o.fit.as_ref().map(|f| f.fitted))
        .collect();
    let export = (!objects.is_empty()).then(|| {
        state.scenes.keep(
            &id.0,
            super::exports::KeptScene {
                objects,
                plane: scene.plane,
            },
        );
        super::exports::export_path(&id.0)
    });
    Ok(Json(SceneResponse {
        request_id: id.0,
        export,
        scene,
    }))
}

fn check_scene_options(o: &SceneOptions) -> Result<(), ApiError> {
    let bad = |m: String| Err(ApiError::unprocessable("invalid_scene_options", m));
    if !(o.min_size.is_finite()
        && o.max_size.is_finite()
        && 0.0 <= o.min_size
        && o.min_size < o.max_size)
    {
        return bad(format!(
            "need 0 <= min_size < max_size, finite; got {} and {}",
            o.min_size, o.max_size
        ));
    }
    if o.max_objects == 0 || o.max_objects > MAX_OBJECTS {
        return bad(format!(
            "max_objects must be in 1..={MAX_OBJECTS}, not {}",
            o.max_objects
        ));
    }
    if o.min_points < crate::fit::MIN_POINTS {
        return bad(format!(
            "min_points must be at least {} (the fewest a fit takes), not {}",
            crate::fit::MIN_POINTS,
            o.min_points
        ));
    }
    Ok(())
}

/// The most objects a request may allow (each is a fit in one batch).
pub const MAX_OBJECTS: usize = 64;

//! `GET /v1/scene/{id}/export`: a recent scene's fitted objects and table as a simulator
//! scene (`scene.xml` for MuJoCo, `scene.urdf`, the meshes beside them) in one tar
//! archive. The service keeps the last [`KEPT_SCENES`] scenes' objects in memory, by
//! request id; each scene's answer links its archive.

use super::AppState;
use super::error::{ApiError, ErrorBody};
use crate::export::{DEFAULT_DENSITY, SceneExport, tar_archive};
use crate::model::{Plane, Pose, Shape};
use axum::extract::{Path, Query, State};
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use std::collections::VecDeque;
use std::sync::{Arc, Mutex};
use utoipa::IntoParams;

/// How many scenes' objects the service keeps for their exports (a few kB each).
pub const KEPT_SCENES: usize = 64;

/// What an export needs of a scene: the fitted objects and the table, camera frame.
#[derive(Clone, Debug)]
pub struct KeptScene {
    pub objects: Vec<(Shape, Pose)>,
    pub plane: Plane,
}

/// The last [`KEPT_SCENES`] scenes, oldest first.
#[derive(Default)]
pub struct SceneStore {
    scenes: Mutex<VecDeque<(String, KeptScene)>>,
}

impl SceneStore {
    /// Keeps a scene under its request id (a repeated id replaces the older scene).
    pub fn keep(&self, id: &str, scene: KeptScene) {
        let mut scenes = self.scenes.lock().unwrap_or_else(|e| e.into_inner());
        scenes.retain(|(kept, _)| kept != id);
        scenes.push_back((id.to_owned(), scene));
        while scenes.len() > KEPT_SCENES {
            scenes.pop_front();
        }
    }

    pub fn get(&self, id: &str) -> Option<KeptScene> {
        let scenes = self.scenes.lock().unwrap_or_else(|e| e.into_inner());
        scenes
            .iter()
            .find(|(kept, _)| kept == id)
            .map(|(_, s)| s.clone())
    }
}

/// The export's path for a scene's request id, percent-encoded (a caller's
/// `x-request-id` may hold any visible character).
pub fn export_path(id: &str) -> String {
    let mut path = String::from("/v1/scene/");
    for b in id.bytes() {
        if b.is_ascii_alphanumeric() || b"-._~".contains(&b) {
            path.push(b as char);
        } else {
            path.push_str(&format!("%{b:02X}"));
        }
    }
    path + "/export"
}

#[derive(Debug, Default, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
#[serde(deny_unknown_fields)]
pub struct ExportQuery {
    /// the objects' density in kg/m³ for their masses and inertias (default 500)
    #[param(minimum = 1.0, maximum = 100000.0)]
    pub density: Option<f64>,
    /// the world frame: the camera's position in it, `x,y,z` (default the camera's frame)
    pub world_translation: Option<String>,
    /// ... and its orientation, `w,x,y,z` (world = R·camera + t)
    pub world_quaternion: Option<String>,
}

/// A recent scene as a simulator scene: a tar archive of `scene.xml` (MJCF: free bodies
/// on the table plane under gravity along its normal), `scene.urdf` (objects fixed to
/// `world`, the table a box) and each object's visual OBJ and collision STL pieces, in
/// the camera's frame or the world frame the query gives. Objects whose fit failed are
/// left out. The service keeps the last 64 scenes; an older or unknown id is 404
/// `scene_not_found`.
#[utoipa::path(
    get, path = "/v1/scene/{id}/export",
    params(("id" = String, Path, description = "the scene's `request_id`"), ExportQuery),
    responses(
        (status = 200, description = "a tar archive", content_type = "application/x-tar", body = Vec<u8>),
        (status = 404, description = "no such scene kept (`scene_not_found`)", body = ErrorBody),
        (status = 422, description = "a bad density or a scene with no fitted object", body = ErrorBody)
    )
)]
pub async fn export(
    State(state): State<Arc<AppState>>,
    Path(id): Path<String>,
    query: Result<Query<ExportQuery>, axum::extract::rejection::QueryRejection>,
) -> Result<Response, ApiError> {
    let query = query
        .map_err(|e| ApiError::unprocessable("invalid_export_options", e.body_text()))?
        .0;
    let density = query.density.unwrap_or(DEFAULT_DENSITY);
    if !(density.is_finite() && (1.0..=1e5).contains(&density)) {
        return Err(ApiError::unprocessable(
            "invalid_export_options",
            format!("density must be in 1..=100000 kg/m³, not {density}"),
        ));
    }
    let world = match (&query.world_translation, &query.world_quaternion) {
        (None, None) => None,
        (t, q) => Some(
            Pose::parse(t.as_deref(), q.as_deref())
                .map_err(|e| ApiError::unprocessable("invalid_export_options", e))?,
        ),
    };
    let Some(scene) = state.scenes.get(&id) else {
        return Err(ApiError::new(
            StatusCode::NOT_FOUND,
            "scene_not_found",
            format!(
                "no scene {id:?} is kept: the service keeps the objects of its last {KEPT_SCENES} scenes"
            ),
        ));
    };
    let export = SceneExport::new(scene.objects, Some(scene.plane), world, density)
        .map_err(|e| ApiError::unprocessable("nothing_to_export", e))?;
    let archive = super::geometry::off_the_workers(move || tar_archive(&export)).await?;
    Ok((
        [
            (header::CONTENT_TYPE, "application/x-tar".to_owned()),
            (
                header::CONTENT_DISPOSITION,
                "attachment; filename=\"scene.tar\"".to_owned(),
            ),
        ],
        archive,
    )
        .into_response())
}

#[cfg(test)]
mod tests {
    #[test]
    fn an_id_with_reserved_characters_is_percent_encoded() {
        assert_eq!(super::export_path("a-1"), "/v1/scene/a-1/export");
        assert_eq!(super::export_path("a/b c"), "/v1/scene/a%2Fb%20c/export");
    }
}

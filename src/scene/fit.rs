//! A whole scene fitted: the frame segmented into its table and objects
//! ([`super::objects`]), then every object fitted in one batch (one lockstep solve for
//! all, one dispatch per solver iteration on the GPU), each seen from the camera (kept
//! above the table on request: the fit's `support`) and with the caller's model (`auto`
//! unless asked otherwise: cans and boxes beside rings).

use super::objects::{SceneError, SceneOptions, Segmentation, segment};
use super::table::Pixels;
use crate::eval::Evaluator;
use crate::fit::{
    FieldOfView, FitError, FitOptions, FitReport, Viewpoint, ViewpointSource, fit_batch,
};
use crate::model::{Plane, Pose, Shape};
use glam::DVec3;
use serde::Serialize;
use std::time::Instant;

/// The most points of an object handed to its fit (an even stride through them): a
/// close object has tens of thousands of pixels, and the fit's samples and final
/// refinement use a few thousand.
pub const MAX_OBJECT_POINTS: usize = 4000;

/// A fitted object may reach below the table by this share of its size before its
/// report says so (noise and a rounded bottom edge reach a little below).
pub const BELOW_TABLE_SHARE: f64 = 0.05;
/// A fitted object whose lowest point stays above the table by more than this share of
/// its size is warned too: an object resting on the table reaches down to it (the true
/// shapes of `bench scenes` within 0.7% of their size), and a fit that stopped on the
/// faces the camera saw does not. (An object standing on another is warned alike: the
/// warning says what the fit did, and why that is suspect on a table.)
pub const ABOVE_TABLE_SHARE: f64 = 0.05;

/// An object is warned as cut by the frame's edge (or the edge of the region the scene
/// was read from) where its pixels on that edge number at least this many times the
/// square root of its pixels: the chord the edge cuts, against the object's width. On a
/// disc that is a cut of about a tenth of it; on `bench scenes` (four sets, 347 objects)
/// objects with under 90% of their silhouette in the frame show 0.75-4, those with at
/// least 95% in it 0.7 or less. What lies past the edge the camera never saw: the fit's
/// extent there is a guess (`docs/scenes.md`: 63% of such objects right, against 96% of
/// those wholly in the frame).
pub const MIN_EDGE_CHORD: f64 = 0.8;

/// One object of a scene: where it is in the frame and its fit (or why it has none).
#[derive(Clone, Debug, Serialize, utoipa::ToSchema)]
pub struct SceneObject {
    /// its index in `objects` (largest first)
    pub id: usize,
    /// its points in the frame
    pub points: usize,
    /// [x, y, width, height] in pixels
    pub pixel_box: [u32; 4],
    /// its pixels (column, row) and their points in the camera's frame, in one order
    #[serde(skip)]
    pub pixels: Vec<(u32, u32)>,
    #[serde(skip)]
    pub cloud: Vec<DVec3>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fit: Option<FitReport>,
    /// why it could not be fitted
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// parallel-jaw grasps on the fit, where the request asked for them (the table is
    /// their support plane)
    #[serde(skip_serializing_if = "Option::is_none")]
    pub grasps: Option<crate::grasp::GraspsOut>,
}

#[derive(Clone, Debug, Default, Serialize, utoipa::ToSchema)]
pub struct SceneTiming {
    /// the table found and the objects split apart
    pub segment: f64,
    /// all objects' fits (one batch)
    pub fit: f64,
    pub total: f64,
}

/// A scene: its table, its objects, and where the time went (milliseconds).
#[derive(Clone, Debug, Serialize, utoipa::ToSchema)]
pub struct SceneReport {
    /// the table's plane in the camera's frame, its normal towards the camera
    pub plane: Plane,
    pub table_points: usize,
    pub objects: Vec<SceneObject>,
    /// clusters above the table dropped as too small or too large for an object
    pub dropped_clusters: usize,
    pub timing_ms: SceneTiming,
}

#[derive(Debug, thiserror::Error)]
pub enum SceneFitError {
    #[error(transparent)]
    Scene(#[from] SceneError),
    /// the evaluator failed (all objects at once)
    #[error(transparent)]
    Fit(#[from] FitError),
}

/// Segments a frame's back-projected pixels (camera frame) and fits every object.
pub fn fit_scene(
    evaluator: &mut dyn Evaluator,
    frame: &Pixels,
    scene: &SceneOptions,
    options: &FitOptions,
) -> Result<SceneReport, SceneFitError> {
    let start = Instant::now();
    let segmentation = segment(frame, scene, options.seed)?;
    let segment_ms = start.elapsed().as_secs_f64() * 1e3;
    let clouds = object_clouds(&segmentation);
    let options: Vec<FitOptions> = segmentation
        .objects
        .iter()
        .map(|o| {
            object_options(
                options,
                &segmentation.plane,
                scene.table_prior,
                &o.seen_through,
                segmentation.field_of_view,
            )
        })
        .collect();
    let batch: Vec<(&[DVec3], &FitOptions)> = clouds
        .iter()
        .zip(&options)
        .map(|(c, o)| (c.as_slice(), o))
        .collect();
    let fits = fit_batch(evaluator, &batch)?
        .into_iter()
        .map(|r| r.map_err(|e| e.to_string()))
        .collect();
    Ok(assemble(segmentation, fits, segment_ms, start))
}

/// Each object's points as its fit gets them: at most [`MAX_OBJECT_POINTS`], an even
/// stride through them.
pub fn object_clouds(segmentation: &Segmentation) -> Vec<Vec<DVec3>> {
    segmentation
        .objects
        .iter()
        .map(|o| {
            let step = o.points.len().div_ceil(MAX_OBJECT_POINTS).max(1);
            o.points.iter().step_by(step).copied().collect()
        })
        .collect()
}

/// An object's fit options: the camera (the origin of the frame) as the viewpoint and
/// the frame's edges as its field of view, unless the caller gave another viewpoint; the
/// free space the camera saw past it
/// ([`crate::scene::objects::Segment::seen_through`]: the table through a ring's hole
/// and beside it); the table it stands on (its axes and its reach down to the table
/// start the search); and with `table_prior` the table as the support it does not reach
/// below.
pub fn object_options(
    options: &FitOptions,
    table: &Plane,
    table_prior: bool,
    seen_through: &[DVec3],
    field_of_view: FieldOfView,
) -> FitOptions {
    FitOptions {
        seen_through: seen_through.to_vec(),
        support: table_prior.then_some(*table),
        resting_on: Some(*table),
        ..seen_from_camera(options, field_of_view)
    }
}

/// The fit options of a depth frame's pixels (`/v1/fit/depth`): seen from the camera
/// within the edges of the pixels read ([`seen_from_camera`]); where a table was taken
/// out of a detector's box, the object rests on it as a scene's object does
/// ([`object_options`], with the scene's default table prior).
pub fn depth_options(
    options: &FitOptions,
    table: Option<&Plane>,
    field_of_view: FieldOfView,
) -> FitOptions {
    match table {
        Some(table) => object_options(
            options,
            table,
            SceneOptions::default().table_prior,
            &[],
            field_of_view,
        ),
        None => seen_from_camera(options, field_of_view),
    }
}

/// A depth frame's points are in the camera's optical frame: unless the caller gave
/// another viewpoint, the sensor is the origin and saw nothing past the edges of the
/// pixels read (`field_of_view`).
fn seen_from_camera(options: &FitOptions, field_of_view: FieldOfView) -> FitOptions {
    match options.viewpoint {
        Viewpoint::Auto => FitOptions {
            viewpoint: Viewpoint::At(DVec3::ZERO, ViewpointSource::Camera),
            field_of_view: Some(field_of_view),
            ..options.clone()
        },
        _ => options.clone(),
    }
}

/// The scene's report from its segmentation and its objects' fits (in order), timed
/// from `start`.
pub fn assemble(
    segmentation: Segmentation,
    fits: Vec<Result<FitReport, String>>,
    segment_ms: f64,
    start: Instant,
) -> SceneReport {
    let Segmentation {
        plane,
        table_points,
        objects,
        dropped,
        window,
        ..
    } = segmentation;
    let (objects, fits) = super::pieces::join_pieces(objects, fits);
    let objects = objects
        .into_iter()
        .zip(fits)
        .enumerate()
        .map(|(id, (segment, fit))| {
            let (fit, error) = match fit {
                Ok(mut r) => {
                    r.warnings.extend(table_warning(&r.fitted, &plane));
                    r.warnings.extend(edge_warning(
                        segment.edge_pixels(window),
                        segment.pixels.len(),
                    ));
                    (Some(r), None)
                }
                Err(e) => (None, Some(e)),
            };
            SceneObject {
                id,
                points: segment.points.len(),
                pixel_box: segment.pixel_box(),
                pixels: segment.pixels,
                cloud: segment.points,
                fit,
                error,
                grasps: None,
            }
        })
        .collect();
    let total = start.elapsed().as_secs_f64() * 1e3;
    SceneReport {
        plane,
        table_points,
        objects,
        dropped_clusters: dropped,
        timing_ms: SceneTiming {
            segment: segment_ms,
            fit: total - segment_ms,
            total,
        },
    }
}

/// The warning of an object the frame's edge cuts ([`MIN_EDGE_CHORD`]): `edge_pixels` of
/// its `pixels` lie on the edge of the pixels read.
pub fn edge_warning(edge_pixels: usize, pixels: usize) -> Option<String> {
    (edge_pixels as f64 >= MIN_EDGE_CHORD * (pixels as f64).sqrt()).then(|| {
        format!(
            "cut by the frame's edge: {edge_pixels} of its {pixels} pixels lie on it, so \
             part of the object is out of view and its extent there is a guess — turn the \
             camera or widen the region to see all of it"
        )
    })
}

/// The height of a fitted surface's lowest point over the plane (negative below it),
/// from a grid of its surface points.
fn lowest_height(shape: &Shape, pose: &Pose, plane: &Plane) -> f64 {
    crate::grasp::surface::grid(shape, pose, 24, 48)
        .iter()
        .map(|q| plane.signed_distance(DVec3::from(q.point)))
        .fold(f64::INFINITY, f64::min)
}

/// The warning of a fit that reaches through the table ([`BELOW_TABLE_SHARE`]) or stops
/// above it ([`ABOVE_TABLE_SHARE`]).
fn table_warning(fitted: &(Shape, Pose), plane: &Plane) -> Option<String> {
    let lowest = lowest_height(&fitted.0, &fitted.1, plane);
    let share = lowest / fitted.0.size();
    if -share > BELOW_TABLE_SHARE {
        Some(format!(
            "through the table: the fitted surface reaches {:.3} below the table's plane \
             ({:.0}% of its size); an object on the table does not, so its hidden side is \
             likely off",
            -lowest,
            -100.0 * share
        ))
    } else if share > ABOVE_TABLE_SHARE {
        Some(format!(
            "above the table: the fitted surface stops {lowest:.3} above the table's plane \
             ({:.0}% of its size); an object resting on the table reaches down to it, so its \
             hidden side is likely cut short",
            100.0 * share
        ))
    } else {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A box resting on the table is not warned; one that stops above it (the fit of its
    /// seen faces alone) or reaches through it is, each by its own warning.
    #[test]
    fn a_fit_that_does_not_rest_on_the_table_is_warned() {
        let table = Plane::through(DVec3::ZERO, DVec3::Z);
        // a box 4 cm tall (a3 = 0.02) with its axis up
        let shape = Shape::new(0.03, 0.02, 0.02, 0.0, 0.2, 0.2);
        let at = |height: f64| (shape, Pose::new(glam::DQuat::IDENTITY, DVec3::Z * height));
        assert_eq!(table_warning(&at(0.02), &table), None);
        let above = table_warning(&at(0.03), &table).expect("a warning");
        assert!(above.starts_with("above the table"), "{above}");
        let through = table_warning(&at(0.01), &table).expect("a warning");
        assert!(through.starts_with("through the table"), "{through}");
    }

    /// An object the frame's edge cuts shows a run of pixels on it as long as a good
    /// part of its width; a rim grazing the edge shows a few.
    #[test]
    fn an_object_on_the_frames_edge_is_warned_by_the_chord_it_shows() {
        use crate::scene::objects::Segment;
        let window = [0, 0, 640, 480];
        // a disc of radius 40 pixels centred `from` pixels right of the left edge
        let disc = |from: i64| Segment {
            points: Vec::new(),
            pixels: (-40i64..=40)
                .flat_map(|x| (-40i64..=40).map(move |y| (x, y)))
                .filter(|(x, y)| x * x + y * y <= 1600)
                .map(|(x, y)| (x + from, y + 240))
                .filter(|&(u, _)| u >= 0)
                .map(|(u, v)| (u as u32, v as u32))
                .collect(),
            seen_through: Vec::new(),
        };
        let warned = |from: i64| {
            let segment = disc(from);
            edge_warning(segment.edge_pixels(window), segment.pixels.len()).is_some()
        };
        // wholly in the frame, grazing it (one pixel on the edge), a seventh of it cut
        // (its centre 24 pixels in) and half of it
        assert!(!warned(100));
        assert!(!warned(40));
        assert!(warned(24));
        assert!(warned(0));
    }
}

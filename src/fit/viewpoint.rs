//! Where the sensor that saw a cloud was: given by the caller (the request, a PCD
//! header's `VIEWPOINT`, a depth frame's camera), or inferred. Sensors and ROS drivers
//! write clouds in the camera's own frame, so a cloud with no viewpoint given is taken to
//! be a view from the origin of its frame when it looks like one, and a view from
//! nowhere (a merged all-round cloud, an origin inside the object) when it does not.
//!
//! A view from the origin has every point in front of the origin, outside the cloud.
//! That does not tell a view from an all-round cloud seen from outside: the fit does, by
//! searching the cloud in both readings and keeping the likelier under the noise model
//! (`fit_batch_searched` in `fit::search::batch`).

use super::FitOptions;
use glam::DVec3;
use serde::Serialize;

/// The caller's knowledge of the viewpoint ([`super::FitOptions::viewpoint`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum Viewpoint {
    /// the frame's origin where the cloud is consistent with a view from it
    /// ([`view_from_origin`]), otherwise none
    #[default]
    Auto,
    /// a view from nowhere: the fit has no free space to respect
    None,
    /// the sensor's position in the cloud's frame, and who said so
    At(DVec3, ViewpointSource),
}

impl Viewpoint {
    /// The position the fit uses: `Auto` counts as none until [`resolve`] has run.
    pub fn position(&self) -> Option<DVec3> {
        match self {
            Viewpoint::At(p, _) => Some(*p),
            _ => None,
        }
    }

    /// A position the caller gave.
    pub fn given(position: DVec3) -> Self {
        Viewpoint::At(position, ViewpointSource::Request)
    }
}

impl From<Option<DVec3>> for Viewpoint {
    /// A position given, or explicitly none.
    fn from(v: Option<DVec3>) -> Self {
        v.map_or(Viewpoint::None, Viewpoint::given)
    }
}

/// Where the viewpoint a fit used came from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum ViewpointSource {
    /// the request's `viewpoint` or the CLI's `--viewpoint`
    Request,
    /// the PCD file's `VIEWPOINT` header
    PcdHeader,
    /// a depth frame's camera
    Camera,
    /// not given: the cloud is consistent with a view from its frame's origin
    FrameOrigin,
    /// no viewpoint: said so, or the cloud is not a view from its frame's origin
    #[default]
    None,
}

/// The viewpoint a fit used, in the report: where it was, who said so, and why.
#[derive(Clone, Debug, Default, PartialEq, Serialize, utoipa::ToSchema)]
pub struct ViewpointUsed {
    /// in the cloud's frame; absent for a view from nowhere
    #[serde(skip_serializing_if = "Option::is_none")]
    pub position: Option<[f64; 3]>,
    pub source: ViewpointSource,
    pub reason: String,
}

impl ViewpointUsed {
    /// The viewpoint dropped for a view from nowhere, `why` added to the reason.
    pub fn dropped(&self, why: &str) -> Self {
        Self {
            position: None,
            source: ViewpointSource::None,
            reason: format!("{}, but {why}", self.reason),
        }
    }
}

/// Points the test of [`view_from_origin`] looks at (an even stride through the cloud).
const TEST_POINTS: usize = 4000;
/// Share of the points that may lie beside or behind the origin (outliers).
const MAX_BESIDE: f64 = 0.02;
/// Whether `points` are consistent with a view from the origin of their frame: Ok with
/// what was measured, Err with why not.
pub fn view_from_origin(points: &[DVec3]) -> Result<String, String> {
    let stride = points.len().div_ceil(TEST_POINTS).max(1);
    let sample: Vec<DVec3> = points.iter().step_by(stride).copied().collect();
    let n = sample.len();
    if n < super::MIN_POINTS {
        return Err("too few points to tell".into());
    }
    let centroid = sample.iter().sum::<DVec3>() / n as f64;
    let radius = (sample
        .iter()
        .map(|p| p.distance_squared(centroid))
        .sum::<f64>()
        / n as f64)
        .sqrt();
    let distance = centroid.length();
    if distance <= radius {
        return Err(format!(
            "the frame's origin lies within the cloud ({:.2} of its radius from its centre)",
            distance / radius.max(f64::MIN_POSITIVE)
        ));
    }
    let forward = centroid / distance;
    // every point of a view lies in front of its camera
    let beside = sample
        .iter()
        .filter(|p| p.dot(forward) <= 1e-3 * distance)
        .count() as f64
        / n as f64;
    if beside > MAX_BESIDE {
        return Err(format!(
            "{:.0}% of the points lie beside or behind the frame's origin",
            100.0 * beside
        ));
    }
    Ok(format!(
        "not given; the cloud lies in front of its frame's origin, {:.1} of its radii \
         away, as a sensor's view does",
        distance / radius
    ))
}

/// The caller's viewpoint made definite for one cloud: `Auto` becomes the origin or none
/// ([`view_from_origin`]); what the report says of it comes along.
pub fn resolve(viewpoint: Viewpoint, points: &[DVec3]) -> (Viewpoint, ViewpointUsed) {
    match viewpoint {
        Viewpoint::At(p, source) => (
            viewpoint,
            ViewpointUsed {
                position: Some(p.to_array()),
                source,
                reason: match source {
                    ViewpointSource::Request => "given",
                    ViewpointSource::PcdHeader => "the PCD header's VIEWPOINT",
                    ViewpointSource::Camera => "the depth frame's camera",
                    ViewpointSource::FrameOrigin => "the cloud's frame origin",
                    ViewpointSource::None => "given",
                }
                .into(),
            },
        ),
        Viewpoint::None => (
            viewpoint,
            ViewpointUsed {
                position: None,
                source: ViewpointSource::None,
                reason: "said to be none: a view from nowhere".into(),
            },
        ),
        Viewpoint::Auto => match view_from_origin(points) {
            Ok(reason) => (
                Viewpoint::At(DVec3::ZERO, ViewpointSource::FrameOrigin),
                ViewpointUsed {
                    position: Some([0.0; 3]),
                    source: ViewpointSource::FrameOrigin,
                    reason,
                },
            ),
            Err(why) => (
                Viewpoint::None,
                ViewpointUsed {
                    position: None,
                    source: ViewpointSource::None,
                    reason: format!("not given, and not the frame's origin: {why}"),
                },
            ),
        },
    }
}

/// Parses the text form of a viewpoint: `auto`, `none`, or `x,y,z`.
pub fn parse(text: &str) -> Result<Viewpoint, String> {
    match text.trim().to_ascii_lowercase().as_str() {
        "auto" => Ok(Viewpoint::Auto),
        "none" => Ok(Viewpoint::None),
        _ => {
            let p = DVec3::from_array(crate::model::parse_floats::<3>(
                text,
                "viewpoint x,y,z (or auto, none)",
            )?);
            if p.is_finite() {
                Ok(Viewpoint::given(p))
            } else {
                Err("viewpoint must be finite".into())
            }
        }
    }
}

impl<'de> serde::Deserialize<'de> for Viewpoint {
    /// `[x, y, z]`, or text: `"auto"`, `"none"`, `"x,y,z"` ([`parse`]).
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        #[derive(serde::Deserialize)]
        #[serde(untagged)]
        enum Given {
            Array([f64; 3]),
            Text(String),
        }
        match Given::deserialize(d)? {
            Given::Array(a) if DVec3::from_array(a).is_finite() => {
                Ok(Viewpoint::given(DVec3::from_array(a)))
            }
            Given::Array(_) => Err(serde::de::Error::custom("viewpoint must be finite")),
            Given::Text(t) => parse(&t).map_err(serde::de::Error::custom),
        }
    }
}

impl Serialize for Viewpoint {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            Viewpoint::Auto => s.serialize_str("auto"),
            Viewpoint::None => s.serialize_str("none"),
            Viewpoint::At(p, _) => p.to_array().serialize(s),
        }
    }
}

/// The text forms [`parse`] reads, as a regular expression for the OpenAPI document
/// (numbers of at most 15 digits and a two-digit exponent: finite whatever they are).
pub const TEXT_PATTERN: &str = r"^ *([Aa][Uu][Tt][Oo]|[Nn][Oo][Nn][Ee]|[-+]?([0-9]{1,15}\.?[0-9]{0,15}|\.[0-9]{1,15})([eE][-+]?[0-9]{1,2})? *, *[-+]?([0-9]{1,15}\.?[0-9]{0,15}|\.[0-9]{1,15})([eE][-+]?[0-9]{1,2})? *, *[-+]?([0-9]{1,15}\.?[0-9]{0,15}|\.[0-9]{1,15})([eE][-+]?[0-9]{1,2})?) *$";

/// The OpenAPI schema of a request's viewpoint: `[x, y, z]` or `"auto"`, `"none"`,
/// `"x,y,z"`.
pub fn request_schema() -> utoipa::openapi::RefOr<utoipa::openapi::schema::Schema> {
    use utoipa::openapi::schema::{ArrayBuilder, ObjectBuilder, OneOfBuilder, Schema, Type};
    let one_of = OneOfBuilder::new()
        .item(
            ArrayBuilder::new()
                .items(ObjectBuilder::new().schema_type(Type::Number))
                .min_items(Some(3))
                .max_items(Some(3)),
        )
        .item(
            ObjectBuilder::new()
                .schema_type(Type::String)
                .pattern(Some(TEXT_PATTERN)),
        )
        .description(Some(
            "[x, y, z] in the cloud's frame, or \"auto\", \"none\", \"x,y,z\"",
        ))
        .build();
    Schema::OneOf(one_of).into()
}

/// Each cloud's options with its viewpoint resolved ([`viewpoint::resolve`]), and what
/// was used and why.
pub(super) fn resolve_viewpoints(
    clouds: &[(&[DVec3], &FitOptions)],
) -> Vec<(FitOptions, ViewpointUsed)> {
    clouds
        .iter()
        .map(|(points, o)| {
            let (viewpoint, used) = resolve(o.viewpoint, points);
            (
                FitOptions {
                    viewpoint,
                    ..(*o).clone()
                },
                used,
            )
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::suite::ground_truth::make_case;

    /// A suite case's single view in its camera's optical frame.
    fn in_camera_frame(seed: u64, noise: f64, outliers: f64) -> Vec<DVec3> {
        make_case(seed, true, noise, outliers)
            .in_camera_frame()
            .unwrap()
            .0
    }

    #[test]
    fn views_in_their_cameras_frame_are_views_from_the_origin() {
        for (k, (noise, outliers)) in [(0.0, 0.0), (0.01, 0.05), (0.02, 0.1)]
            .into_iter()
            .enumerate()
        {
            for seed in 0..4 {
                let points = in_camera_frame(300 + 10 * k as u64 + seed, noise, outliers);
                let (viewpoint, used) = resolve(Viewpoint::Auto, &points);
                assert_eq!(
                    viewpoint,
                    Viewpoint::At(DVec3::ZERO, ViewpointSource::FrameOrigin),
                    "{}",
                    used.reason
                );
            }
        }
    }

    #[test]
    fn a_cloud_around_its_origin_is_no_view_from_it() {
        // a full cloud, and the same view, centred on the frame's origin
        for partial in [false, true] {
            let case = make_case(7, partial, 0.01, 0.05);
            let centre = case.points.iter().sum::<DVec3>() / case.points.len() as f64;
            let centred: Vec<DVec3> = case.points.iter().map(|p| *p - centre).collect();
            let (viewpoint, used) = resolve(Viewpoint::Auto, &centred);
            assert_eq!(viewpoint, Viewpoint::None);
            assert_eq!(used.source, ViewpointSource::None);
            assert!(used.reason.contains("within the cloud"), "{}", used.reason);
        }
    }

    #[test]
    fn points_on_both_sides_of_the_origin_are_no_view_from_it() {
        let mut points = in_camera_frame(1, 0.0, 0.0);
        let mirrored: Vec<DVec3> = points
            .iter()
            .map(|p| *p * DVec3::new(1.0, 1.0, -0.2))
            .collect();
        points.extend(mirrored);
        let (viewpoint, used) = resolve(Viewpoint::Auto, &points);
        assert_eq!(viewpoint, Viewpoint::None, "{}", used.reason);
    }

    #[test]
    fn given_viewpoints_are_kept_as_given() {
        let points = in_camera_frame(3, 0.0, 0.0);
        let at = Viewpoint::At(DVec3::new(1.0, 2.0, 3.0), ViewpointSource::PcdHeader);
        let (viewpoint, used) = resolve(at, &points);
        assert_eq!(viewpoint, at);
        assert_eq!(used.position, Some([1.0, 2.0, 3.0]));
        assert_eq!(used.source, ViewpointSource::PcdHeader);
        let (viewpoint, used) = resolve(Viewpoint::None, &points);
        assert_eq!(viewpoint, Viewpoint::None);
        assert_eq!(used.position, None);
    }

    #[test]
    fn viewpoints_parse_from_text_and_json() {
        assert_eq!(parse("auto"), Ok(Viewpoint::Auto));
        assert_eq!(parse(" None "), Ok(Viewpoint::None));
        assert_eq!(
            parse("1,2,-3"),
            Ok(Viewpoint::given(DVec3::new(1.0, 2.0, -3.0)))
        );
        assert!(parse("1,2").is_err());
        assert!(parse("inf,0,0").is_err());
        let json = |t: &str| serde_json::from_str::<Viewpoint>(t).map_err(|e| e.to_string());
        assert_eq!(json("[0, 0, 0]"), Ok(Viewpoint::given(DVec3::ZERO)));
        assert_eq!(json("\"none\""), Ok(Viewpoint::None));
        assert_eq!(
            json("\"0.5,0,1\""),
            Ok(Viewpoint::given(DVec3::new(0.5, 0.0, 1.0)))
        );
        assert!(json("[1, 2]").is_err());
        assert!(json("\"sideways\"").unwrap_err().contains("viewpoint"));
        assert_eq!(serde_json::to_string(&Viewpoint::None).unwrap(), "\"none\"");
    }
}

//! The OpenAPI document as the server takes requests: utoipa's document from the
//! handlers' annotations, with what utoipa cannot say from the Rust types added, so that
//! a client (or a fuzzer: `scripts/api-fuzz` runs schemathesis) that keeps to the
//! document is never refused for the form of its request: fixed array lengths (`[f64;
//! 3]` is an array of any length to utoipa), integers' ranges, the known shape's names,
//! the text forms of query options, the depth routes' one depth image and their
//! multipart parts.

use crate::fit::SHAPE_NAMES;
use crate::fit::viewpoint::TEXT_PATTERN as VIEWPOINT_TEXT;
use serde_json::{Value, json};
use utoipa::OpenApi;

/// (schema, property, lengths: the property's own, then its items'; 0 leaves one free)
const FIXED_LENGTHS: &[(&str, &str, &[u64])] = &[
    ("FitRequest", "points", &[0, 3]),
    ("FitRequestOptions", "axis", &[3]),
    ("DepthFitRequest", "depth_range", &[2]),
    ("SceneRequest", "depth_range", &[2]),
    ("SceneObject", "pixel_box", &[4]),
    ("PoseIn", "translation", &[3]),
    ("PoseIn", "quaternion_wxyz", &[4]),
    ("PoseOut", "translation", &[3]),
    ("PoseOut", "quaternion_wxyz", &[4]),
    ("PoseOut", "rotation", &[3, 3]),
    ("Plane", "normal", &[3]),
    ("ViewpointIn", "position", &[3]),
    ("ViewpointUsed", "position", &[3]),
    ("GraspOptions", "viewpoint", &[3]),
    ("SurfaceRequest", "grid", &[2]),
    ("SurfaceRequest", "parameters", &[0, 2]),
    ("SurfaceRequest", "points", &[0, 3]),
    ("SurfacePoint", "point", &[3]),
    ("SurfacePoint", "normal", &[3]),
    ("SurfacePoint", "curvatures", &[2]),
    ("SurfacePoint", "directions", &[2, 3]),
    ("Grasp", "position", &[3]),
    ("Grasp", "approach", &[3]),
    ("Grasp", "closing", &[3]),
    ("Grasp", "binormal", &[3]),
    ("Grasp", "rotation", &[3, 3]),
    ("Grasp", "quaternion_wxyz", &[4]),
    ("Grasp", "contacts", &[2, 3]),
    ("Grasp", "normals", &[2, 3]),
];

/// The served document, built once.
pub fn document() -> &'static Value {
    static DOCUMENT: std::sync::LazyLock<Value> = std::sync::LazyLock::new(build);
    &DOCUMENT
}

fn build() -> Value {
    let mut doc = serde_json::to_value(super::api::ApiDoc::openapi())
        .expect("the OpenAPI document serialises");
    let schemas = &mut doc["components"]["schemas"];
    for (schema, property, lengths) in FIXED_LENGTHS {
        let field = &mut schemas[*schema]["properties"][*property];
        assert!(field.is_object(), "no {schema}.{property} in the document");
        fix_lengths(field, lengths);
    }
    schemas["BatchRequest"]["properties"]["clouds"]["minItems"] = json!(1);
    let known = &mut schemas["FitRequestOptions"]["properties"]["known"];
    let names: serde_json::Map<String, Value> = SHAPE_NAMES
        .iter()
        .map(|n| (n.to_string(), json!({"type": "number"})))
        .collect();
    *known = json!({
        "type": ["object", "null"],
        "description": known["description"].clone(),
        "properties": names,
        "additionalProperties": false
    });
    for (request, path) in [
        ("DepthFitRequest", "/v1/fit/depth"),
        ("SceneRequest", "/v1/scene"),
    ] {
        depth_frame_request(&mut doc, request, path);
    }
    let scene = &mut doc["components"]["schemas"]["SceneOptions"]["properties"];
    for (field, least, most) in [
        ("min_points", crate::fit::MIN_POINTS as u64, u32::MAX as u64),
        ("max_objects", 1, super::scene::MAX_OBJECTS as u64),
    ] {
        let f = &mut scene[field];
        assert!(f.is_object(), "no SceneOptions.{field} in the document");
        f["minimum"] = json!(least);
        f["maximum"] = json!(most);
        if let Some(f) = f.as_object_mut() {
            f.remove("format");
        }
    }
    // query options in their text forms: `axis=0,0,1`, `viewpoint=auto`, `known=a1:0.05`
    if let Some(parameters) = doc["paths"]["/v1/fit"]["post"]["parameters"].as_array_mut() {
        for p in parameters.iter_mut() {
            match p["name"].as_str() {
                Some("axis") => {
                    fix_lengths(&mut p["schema"], &[3]);
                    p["style"] = json!("form");
                    p["explode"] = json!(false);
                }
                Some("viewpoint") => p["schema"]["pattern"] = json!(VIEWPOINT_TEXT),
                Some("known") => p["schema"]["pattern"] = json!(known_text_pattern()),
                _ => {}
            }
        }
    }
    // the scene export's archive is bytes, not an array of numbers; its world frame is
    // text
    let export = &mut doc["paths"]["/v1/scene/{id}/export"]["get"];
    export["responses"]["200"]["content"]["application/x-tar"]["schema"] =
        json!({"type": "string", "format": "binary"});
    if let Some(parameters) = export["parameters"].as_array_mut() {
        for p in parameters.iter_mut() {
            match p["name"].as_str() {
                Some("world_translation") => p["schema"]["pattern"] = json!(numbers_pattern(3)),
                Some("world_quaternion") => p["schema"]["pattern"] = json!(numbers_pattern(4)),
                _ => {}
            }
        }
    }
    bound_integers(&mut doc);
    doc
}

/// A depth frame's request: exactly one depth image, as a string (a null one is no
/// image), and its multipart form's parts.
fn depth_frame_request(doc: &mut Value, request: &str, path: &str) {
    let schemas = &mut doc["components"]["schemas"];
    schemas[request]["oneOf"] = json!([
        {"required": ["depth_png"], "properties": {"depth_png": {"type": "string"}}},
        {"required": ["depth_raw"], "properties": {"depth_raw": {"type": "string"}}}
    ]);
    let params = multipart_params(&schemas[request]);
    let content = &mut doc["paths"][path]["post"]["requestBody"]["content"];
    assert!(
        content.is_object(),
        "no request body for {path} in the document"
    );
    content["multipart/form-data"] = json!({
        "schema": {
            "type": "object",
            "required": ["depth", "params"],
            "additionalProperties": false,
            "properties": {
                "depth": {"type": "string", "format": "binary",
                          "description": "16-bit grayscale PNG, or raw little-endian u16 with width and height in params"},
                "mask": {"type": "string", "format": "binary",
                         "description": "mask PNG (1- to 16-bit grayscale, non-zero keeps the pixel)"},
                "params": params
            }
        },
        "encoding": {"params": {"contentType": "application/json"}}
    });
}

/// `known=a1:0.05,a4:2.1` (or `=`) in a query string.
/// A number as the text options write it.
const NUMBER: &str = r"[-+]?([0-9]{1,15}\.?[0-9]{0,15}|\.[0-9]{1,15})([eE][-+]?[0-9]{1,2})?";

/// `count` comma-separated numbers.
fn numbers_pattern(count: usize) -> String {
    format!("^ *{NUMBER}( *, *{NUMBER}){{{}}} *$", count - 1)
}

fn known_text_pattern() -> String {
    let number = NUMBER;
    let pair = format!("({}) *[:=] *{number}", SHAPE_NAMES.join("|"));
    format!("^ *{pair}( *, *{pair})* *$")
}

/// Every integer gets the range of the Rust type that reads it: utoipa says `minimum: 0`
/// for an unsigned one and nothing of its top (`int32` is u32 or i32, the rest 64-bit).
/// An unsigned one loses its format, which OpenAPI defines as signed (a u32 of 2^31 is
/// no `int32`).
fn bound_integers(value: &mut Value) {
    match value {
        Value::Object(fields) => {
            let integer = match &fields.get("type") {
                Some(Value::String(t)) => t == "integer",
                Some(Value::Array(types)) => types.iter().any(|t| t == "integer"),
                _ => false,
            };
            if integer && !fields.contains_key("maximum") {
                let unsigned = fields.get("minimum").and_then(Value::as_i64) == Some(0);
                let narrow = fields.get("format").and_then(Value::as_str) == Some("int32");
                let (bottom, top) = match (unsigned, narrow) {
                    (true, true) => (json!(0), json!(u32::MAX)),
                    (true, false) => (json!(0), json!(u64::MAX)),
                    (false, true) => (json!(i32::MIN), json!(i32::MAX)),
                    (false, false) => (json!(i64::MIN), json!(i64::MAX)),
                };
                fields.insert("minimum".into(), bottom);
                fields.insert("maximum".into(), top);
                if unsigned {
                    fields.remove("format");
                }
            }
            fields.values_mut().for_each(bound_integers);
        }
        Value::Array(items) => items.iter_mut().for_each(bound_integers),
        _ => {}
    }
}

/// Sets minItems = maxItems on the array schema (or its array variant) and its items.
fn fix_lengths(schema: &mut Value, lengths: &[u64]) {
    let Some((&first, rest)) = lengths.split_first() else {
        return;
    };
    let array = if is_array(schema) {
        schema
    } else {
        let variants = ["oneOf", "anyOf"]
            .into_iter()
            .find(|k| schema.get(*k).is_some_and(Value::is_array))
            .unwrap_or_else(|| panic!("not an array schema: {schema}"));
        schema[variants]
            .as_array_mut()
            .and_then(|v| v.iter_mut().find(|v| is_array(v)))
            .expect("an array variant")
    };
    if first > 0 {
        array["minItems"] = json!(first);
        array["maxItems"] = json!(first);
    }
    fix_lengths(&mut array["items"], rest);
}

fn is_array(schema: &Value) -> bool {
    match &schema["type"] {
        Value::String(t) => t == "array",
        Value::Array(types) => types.iter().any(|t| t == "array"),
        _ => false,
    }
}

/// The multipart request's `params` part: the JSON request's fields but its images.
fn multipart_params(json_request: &Value) -> Value {
    let mut params = json_request.clone();
    if let Some(object) = params.as_object_mut() {
        object.remove("oneOf");
    }
    if let Some(properties) = params["properties"].as_object_mut() {
        for image in ["depth_png", "depth_raw", "mask_png"] {
            properties.remove(image);
        }
    }
    params
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fixed_arrays_have_their_lengths_and_the_depth_route_its_parts() {
        let doc = document();
        let schemas = &doc["components"]["schemas"];
        let points = &schemas["FitRequest"]["properties"]["points"];
        assert_eq!(points["items"]["minItems"], 3);
        assert_eq!(points["items"]["maxItems"], 3);
        assert_eq!(
            schemas["PoseIn"]["properties"]["quaternion_wxyz"]["maxItems"],
            4
        );
        let multipart =
            &doc["paths"]["/v1/fit/depth"]["post"]["requestBody"]["content"]["multipart/form-data"];
        assert_eq!(
            multipart["schema"]["properties"]["depth"]["format"],
            "binary"
        );
        assert!(multipart["schema"]["properties"]["params"]["properties"]["depth_png"].is_null());
    }
}

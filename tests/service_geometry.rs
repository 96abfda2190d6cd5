//! The routes on a fitted object (`/v1/surface`, `/v1/grasps`) and the fit's
//! `options.grasps`, over real HTTP on loopback.

use glam::DVec3;
use serde_json::{Value, json};
use supertoroid::eval::Backend;
use supertoroid::model::{Pose, Shape, meridian_distance};
use supertoroid::service::ServiceConfig;

mod common;
use common::{Server, client};

fn server() -> Server {
    Server::start(ServiceConfig {
        backend: Backend::Cpu,
        ..Default::default()
    })
}

fn post(s: &Server, path: &str, body: &Value) -> (u16, Value) {
    let r = client().post(s.url(path)).json(body).send().unwrap();
    (r.status().as_u16(), r.json().unwrap())
}

fn gripper() -> Value {
    json!({"max_opening": 0.08, "finger_depth": 0.045, "finger_width": 0.02})
}

/// The shape and pose of a fit's JSON.
fn object_of(fit: &Value) -> (Shape, Pose) {
    let object: supertoroid::model::FittedObject = serde_json::from_value(fit.clone()).unwrap();
    object.validated().unwrap()
}

/// A ring in metres, seen from the origin (the camera).
fn ring_cloud() -> Vec<[f64; 3]> {
    let shape = Shape::new(0.015, 0.015, 0.008, 2.5, 1.0, 1.0);
    let pose = Pose::new(
        glam::DQuat::from_rotation_x(2.2),
        DVec3::new(0.02, -0.01, 0.55),
    );
    let mut rng = supertoroid::synth::rng(11);
    supertoroid::synth::sample_surface(&shape, &pose, 3000, &mut rng)
        .iter()
        .map(|p| p.to_array())
        .collect()
}

#[test]
fn a_fit_with_grasps_answers_them_on_its_surface_and_the_grasps_route_agrees() {
    let s = server();
    let body = json!({
        "points": ring_cloud(),
        "options": {"viewpoint": "none", "grasps": {"gripper": gripper(), "graspnet": true}}
    });
    let (status, fit) = post(&s, "/v1/fit", &body);
    assert_eq!(status, 200, "{fit}");
    let (shape, pose) = object_of(&fit);
    let grasps = fit["grasps"]["grasps"].as_array().unwrap();
    assert!(
        !grasps.is_empty() && grasps.len() <= 10,
        "{}",
        fit["grasps"]
    );
    for g in grasps {
        for c in g["contacts"].as_array().unwrap() {
            let p: [f64; 3] = serde_json::from_value(c.clone()).unwrap();
            let d = meridian_distance(&shape, pose.to_canonical(DVec3::from_array(p))).distance;
            assert!(d < 1e-6 * shape.size());
        }
    }
    assert_eq!(
        fit["grasps"]["graspnet"].as_array().unwrap().len(),
        grasps.len()
    );
    assert_eq!(fit["grasps"]["graspnet"][0].as_array().unwrap().len(), 17);
    // the fit's answer posted as it is gives the same grasps
    let (status, answer) = post(
        &s,
        "/v1/grasps",
        &json!({"object": fit, "options": {"gripper": gripper()}}),
    );
    assert_eq!(status, 200, "{answer}");
    assert!(answer["candidates"].as_u64().unwrap() > 0);
    // (the same grasps to rounding: the pose comes back through its JSON quaternion, and a
    // round ring's grasps all round its axis tie in score, so which of the tied ones make
    // the list may differ; the scores and kinds, and every contact on the surface, agree)
    let again = answer["grasps"].as_array().unwrap();
    assert_eq!(again.len(), grasps.len());
    let ranked = |gs: &[Value]| -> Vec<(f64, String)> {
        gs.iter()
            .map(|g| (g["score"].as_f64().unwrap(), g["kind"].to_string()))
            .collect()
    };
    for ((a, ka), (b, kb)) in ranked(again).iter().zip(ranked(grasps)) {
        assert!(
            (a - b).abs() < 1e-9 && *ka == kb,
            "{a} {ka} against {b} {kb}"
        );
    }
    for g in again {
        for c in g["contacts"].as_array().unwrap() {
            let p: [f64; 3] = serde_json::from_value(c.clone()).unwrap();
            let d = meridian_distance(&shape, pose.to_canonical(DVec3::from_array(p))).distance;
            assert!(d < 1e-6 * shape.size());
        }
    }
}

#[test]
fn the_surface_route_answers_grids_parameters_and_nearest_points() {
    let s = server();
    let object = json!({
        "shape": {"a1": 1.0, "a2": 1.0, "a3": 1.0, "a4": 0.0, "eps1": 1.0, "eps2": 1.0},
        "pose": {"translation": [0.0, 0.0, 5.0], "quaternion_wxyz": [1.0, 0.0, 0.0, 0.0]}
    });
    let (status, grid) = post(
        &s,
        "/v1/surface",
        &json!({"object": object, "grid": [4, 8]}),
    );
    assert_eq!(status, 200, "{grid}");
    let points = grid["points"].as_array().unwrap();
    assert_eq!(points.len(), 32);
    for p in points {
        // a unit sphere at z = 5: curvature 1, the normal from the centre
        let k: [f64; 2] = serde_json::from_value(p["curvatures"].clone()).unwrap();
        assert!((k[0] - 1.0).abs() < 1e-6 && (k[1] - 1.0).abs() < 1e-6);
        let x: [f64; 3] = serde_json::from_value(p["point"].clone()).unwrap();
        let n: [f64; 3] = serde_json::from_value(p["normal"].clone()).unwrap();
        let radial = (DVec3::from_array(x) - DVec3::new(0.0, 0.0, 5.0)).normalize();
        assert!(radial.dot(DVec3::from_array(n)) > 1.0 - 1e-9);
    }
    let (_, at) = post(
        &s,
        "/v1/surface",
        &json!({"object": object, "parameters": [[0.0, 0.0]]}),
    );
    assert_eq!(at["points"][0]["point"], json!([1.0, 0.0, 5.0]));
    let (_, near) = post(
        &s,
        "/v1/surface",
        &json!({"object": object, "points": [[0.0, 3.0, 5.0]]}),
    );
    let p: [f64; 3] = serde_json::from_value(near["points"][0]["point"].clone()).unwrap();
    assert!((DVec3::from_array(p) - DVec3::new(0.0, 1.0, 5.0)).length() < 1e-9);
}

/// An object whose sizes and exponents overflow the surface's quantities (found by
/// schemathesis) is refused with its code, never answered with nulls for numbers.
#[test]
fn an_object_whose_surface_overflows_is_refused() {
    let s = server();
    let object = json!({
        "shape": {"a1": 7.6e15, "a2": 3.2e16, "a3": 4.8e16, "a4": 4.8e16,
                  "eps1": 2.8e-264, "eps2": 3.6e-283},
        "pose": {"translation": [0.0, 0.0, -3.7e16], "quaternion_wxyz": [0.16, 0.66, 0.5, 0.5]}
    });
    let points = json!([
        [0.0, 0.0, 0.0],
        [-4.3e16, -2.4e245, -7.1e59],
        [-2.6e16, -2.3e16, -6.8e16]
    ]);
    let (status, body) = post(
        &s,
        "/v1/surface",
        &json!({"object": object, "points": points}),
    );
    assert!(status == 422, "{status}: {body}");
    assert_eq!(body["error"]["code"], "invalid_object", "{body}");
}

#[test]
fn bad_objects_queries_and_grippers_get_their_own_codes() {
    let s = server();
    let object = json!({
        "shape": {"a1": 0.02, "a2": 0.02, "a3": 0.01, "a4": 0.5, "eps1": 1.0, "eps2": 1.0},
        "pose": {"translation": [0.0, 0.0, 0.5], "quaternion_wxyz": [1.0, 0.0, 0.0, 0.0]}
    });
    let mut bad_shape = object.clone();
    bad_shape["shape"]["a1"] = json!(-1.0);
    let mut zero_q = object.clone();
    zero_q["pose"]["quaternion_wxyz"] = json!([0.0, 0.0, 0.0, 0.0]);
    let cases = [
        (
            "/v1/surface",
            json!({"object": bad_shape, "grid": [2, 2]}),
            422,
            "invalid_object",
        ),
        (
            "/v1/surface",
            json!({"object": zero_q, "grid": [2, 2]}),
            422,
            "invalid_object",
        ),
        (
            "/v1/surface",
            json!({"object": object, "grid": [2, 2], "points": [[0, 0, 0]]}),
            422,
            "invalid_query",
        ),
        (
            "/v1/surface",
            json!({"object": object}),
            422,
            "invalid_query",
        ),
        (
            "/v1/surface",
            json!({"object": object, "grid": [0, 5]}),
            422,
            "invalid_query",
        ),
        (
            "/v1/surface",
            json!({"object": object, "grid": [100000, 100000]}),
            422,
            "invalid_query",
        ),
        // an apple (a4 < 1) has no surface at eta = 3
        (
            "/v1/surface",
            json!({"object": object, "parameters": [[3.0, 0.0]]}),
            422,
            "invalid_query",
        ),
        (
            "/v1/surface",
            json!({"object": object, "grid": [2, 2], "extra": 1}),
            422,
            "invalid_request",
        ),
        (
            "/v1/grasps",
            json!({"object": object, "options": {"gripper": {"max_opening": -1, "finger_depth": 0.04, "finger_width": 0.02}}}),
            422,
            "invalid_grasp_options",
        ),
        (
            "/v1/grasps",
            json!({"object": object, "options": {"gripper": gripper(), "friction": 0}}),
            422,
            "invalid_grasp_options",
        ),
        (
            "/v1/grasps",
            json!({"object": object, "options": {"gripper": gripper(), "max_grasps": 5000}}),
            422,
            "invalid_grasp_options",
        ),
        (
            "/v1/grasps",
            json!({"object": object, "options": {"gripper": gripper(), "plane": {"normal": [0, 0, 0], "offset": 0}}}),
            422,
            "invalid_grasp_options",
        ),
        (
            "/v1/grasps",
            json!({"object": object}),
            422,
            "invalid_request",
        ),
        // checked before the fit runs
        (
            "/v1/fit",
            json!({"points": ring_cloud(), "options": {"grasps": {"gripper": {"max_opening": 0.05, "min_opening": 0.06, "finger_depth": 0.04, "finger_width": 0.02}}}}),
            422,
            "invalid_grasp_options",
        ),
    ];
    for (path, body, status, code) in cases {
        let (got, answer) = post(&s, path, &body);
        assert_eq!(got, status, "{path} {body}: {answer}");
        assert_eq!(answer["error"]["code"], code, "{path}: {answer}");
        assert!(!answer["error"]["message"].as_str().unwrap().is_empty());
    }
    let c = client();
    let r = c
        .post(s.url("/v1/grasps"))
        .header("content-type", "text/plain")
        .body("x")
        .send()
        .unwrap();
    assert_eq!(r.status().as_u16(), 415);
    let r = c
        .post(s.url("/v1/surface"))
        .header("content-type", "application/json")
        .body("{")
        .send()
        .unwrap();
    assert_eq!(r.status().as_u16(), 400);
    // both routes are in the OpenAPI document
    let doc: Value = c
        .get(s.url("/openapi.json"))
        .send()
        .unwrap()
        .json()
        .unwrap();
    assert!(doc["paths"]["/v1/surface"]["post"].is_object());
    assert!(doc["paths"]["/v1/grasps"]["post"].is_object());
}

//! The one error body of the API: `{"error": {"code": "...", "message": "..."}}`, with
//! the status that fits the problem (4xx for the caller's input, 503/504 for load, 500
//! for our own failures).

use crate::fit::FitError;
use crate::io::CloudError;
use axum::Json;
use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::Serialize;

#[derive(Debug, Clone)]
pub struct ApiError {
    pub status: StatusCode,
    pub code: &'static str,
    pub message: String,
}

#[derive(Serialize, utoipa::ToSchema)]
pub struct ErrorBody {
    pub error: ErrorDetail,
}

#[derive(Serialize, utoipa::ToSchema)]
pub struct ErrorDetail {
    /// machine-readable class, e.g. `too_few_points`, `malformed_json`, `overloaded`
    pub code: String,
    /// what was wrong, for people
    pub message: String,
}

impl ApiError {
    pub fn new(status: StatusCode, code: &'static str, message: impl Into<String>) -> Self {
        Self {
            status,
            code,
            message: message.into(),
        }
    }

    pub fn bad_request(code: &'static str, message: impl Into<String>) -> Self {
        Self::new(StatusCode::BAD_REQUEST, code, message)
    }

    pub fn unprocessable(code: &'static str, message: impl Into<String>) -> Self {
        Self::new(StatusCode::UNPROCESSABLE_ENTITY, code, message)
    }

    pub fn overloaded() -> Self {
        Self::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "overloaded",
            "the fit queue is full; retry shortly",
        )
    }

    /// A request body as JSON. A whole number written with a fraction (`640.0`, as
    /// numpy and JavaScript clients write them; JSON Schema's integer allows it) is taken
    /// where the request wants an integer: tried only when the body does not read as it
    /// is, so the usual request pays nothing for it.
    pub fn parse_json<T: serde::de::DeserializeOwned>(bytes: &[u8]) -> Result<T, ApiError> {
        serde_json::from_slice(bytes).or_else(|first: serde_json::Error| {
            if first.classify() != serde_json::error::Category::Data {
                return Err(Self::from_json(first));
            }
            let mut value: serde_json::Value =
                serde_json::from_slice(bytes).map_err(Self::from_json)?;
            if !integral_floats_to_integers(&mut value) {
                return Err(Self::from_json(first));
            }
            serde_json::from_value(value).map_err(|_| Self::from_json(first))
        })
    }

    /// From a JSON (de)serialisation failure: syntax is 400, the wrong shape is 422.
    pub fn from_json(e: serde_json::Error) -> Self {
        use serde_json::error::Category;
        match e.classify() {
            Category::Data => Self::unprocessable("invalid_request", e.to_string()),
            _ => Self::bad_request("malformed_json", e.to_string()),
        }
    }
}

/// Rewrites each float with a whole value within u64 or i64 as that integer; true where
/// one was.
fn integral_floats_to_integers(value: &mut serde_json::Value) -> bool {
    use serde_json::Value;
    match value {
        Value::Number(n) if n.is_f64() => {
            let read = n.as_f64().unwrap_or(f64::NAN);
            // serde_json reads a long decimal to within an ulp or so of its value
            let f = read.round();
            let whole = (read - f).abs() <= 4.0 * f64::EPSILON * f.abs();
            // (the casts are exact: a whole double in range is that integer)
            if whole && (0.0..18_446_744_073_709_551_616.0).contains(&f) {
                *value = Value::from(f as u64);
            } else if whole && (-9_223_372_036_854_775_808.0..0.0).contains(&f) {
                *value = Value::from(f as i64);
            } else {
                return false;
            }
            true
        }
        Value::Array(items) => items
            .iter_mut()
            .fold(false, |any, v| integral_floats_to_integers(v) | any),
        Value::Object(fields) => fields
            .values_mut()
            .fold(false, |any, v| integral_floats_to_integers(v) | any),
        _ => false,
    }
}

impl From<CloudError> for ApiError {
    fn from(e: CloudError) -> Self {
        let status = match &e {
            CloudError::Parse { .. } | CloudError::Malformed { .. } => StatusCode::BAD_REQUEST,
            CloudError::TooLarge { .. } => StatusCode::PAYLOAD_TOO_LARGE,
            CloudError::UnsupportedFormat(_) => StatusCode::UNSUPPORTED_MEDIA_TYPE,
            CloudError::Io(_) => StatusCode::INTERNAL_SERVER_ERROR,
            _ => StatusCode::UNPROCESSABLE_ENTITY,
        };
        Self::new(status, e.code(), e.to_string())
    }
}

impl From<FitError> for ApiError {
    fn from(e: FitError) -> Self {
        let code = match &e {
            FitError::TooFewPoints(_) => "too_few_points",
            FitError::NonFinite(_) => "non_finite",
            FitError::Degenerate(_) => "degenerate_cloud",
            FitError::NoObject(_) => "no_object_found",
            FitError::InvalidOption(_) => "invalid_option",
            FitError::Evaluator(_) => "evaluator_failed",
        };
        let status = match e {
            FitError::Evaluator(_) => StatusCode::INTERNAL_SERVER_ERROR,
            _ => StatusCode::UNPROCESSABLE_ENTITY,
        };
        Self::new(status, code, e.to_string())
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let body = ErrorBody {
            error: ErrorDetail {
                code: self.code.to_string(),
                message: self.message,
            },
        };
        let mut response = (self.status, Json(body)).into_response();
        if self.status == StatusCode::SERVICE_UNAVAILABLE {
            response
                .headers_mut()
                .insert(header::RETRY_AFTER, HeaderValue::from_static("1"));
        }
        // lets the metrics layer count errors by kind
        response.extensions_mut().insert(ErrorCode(self.code));
        response
    }
}

/// The error code of a response, for metrics.
#[derive(Clone, Copy, Debug)]
pub struct ErrorCode(pub &'static str);

#[cfg(test)]
mod json_tests {
    use super::*;

    #[derive(serde::Deserialize, Debug)]
    struct Size {
        width: u32,
        scale: f64,
    }

    #[test]
    fn a_whole_number_with_a_fraction_reads_as_an_integer_and_a_fraction_does_not() {
        let size: Size = ApiError::parse_json(br#"{"width": 640.0, "scale": 1.5}"#).unwrap();
        assert_eq!((size.width, size.scale), (640, 1.5));
        let refused = ApiError::parse_json::<Size>(br#"{"width": 640.5, "scale": 1}"#).unwrap_err();
        assert_eq!(refused.code, "invalid_request");
        let refused = ApiError::parse_json::<Size>(br#"{"width": 640.0"#).unwrap_err();
        assert_eq!(refused.code, "malformed_json");
    }
}

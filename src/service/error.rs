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

    /// From a JSON (de)serialisation failure: syntax is 400, the wrong shape is 422.
    pub fn from_json(e: serde_json::Error) -> Self {
        use serde_json::error::Category;
        match e.classify() {
            Category::Data => Self::unprocessable("invalid_request", e.to_string()),
            _ => Self::bad_request("malformed_json", e.to_string()),
        }
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

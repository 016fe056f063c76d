//! Access control: optional bearer tokens on `/v1` and, unless opened, on
//! `/metrics`; `/healthz`, `/readyz` and the dashboard's static files stay open (the page asks
//! for a token and sends it itself). Tokens come from `--auth-token-file` (one per line) and
//! are kept only as SHA-256 digests; a presented token is hashed and compared with every
//! digest in constant time, so neither its content nor its length nor which token matched
//! shows in the timing. Tokens never reach a log line: nothing here logs the header.

use std::path::Path;
use std::sync::Arc;

use axum::extract::{Request, State};
use axum::http::{header, HeaderValue};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use sha2::{Digest, Sha256};

use super::error::ApiError;
use super::AppState;
use crate::error::{ErrorCode, JobError};

/// The accepted tokens (as digests) and whether `/metrics` needs one too.
pub struct Auth {
    digests: Vec<[u8; 32]>,
    pub metrics_open: bool,
}

impl Auth {
    /// Reads tokens from `path`: one per line; blank lines and `#` comments are skipped.
    pub fn from_file(path: &Path, metrics_open: bool) -> anyhow::Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| anyhow::anyhow!("cannot read the token file {}: {e}", path.display()))?;
        let tokens: Vec<&str> = text.lines().map(str::trim).filter(|l| !l.is_empty() && !l.starts_with('#')).collect();
        anyhow::ensure!(!tokens.is_empty(), "the token file {} holds no token", path.display());
        anyhow::ensure!(tokens.iter().all(|t| t.len() >= 16), "every token must be at least 16 characters long");
        Ok(Self::new(&tokens, metrics_open))
    }

    pub fn new(tokens: &[&str], metrics_open: bool) -> Self {
        Self { digests: tokens.iter().map(|t| Sha256::digest(t.as_bytes()).into()).collect(), metrics_open }
    }

    /// Whether an `Authorization` header carries one of the tokens.
    pub fn allows(&self, authorization: Option<&HeaderValue>) -> bool {
        let Some(token) = authorization.and_then(|v| v.to_str().ok()).and_then(|v| v.strip_prefix("Bearer ")) else {
            return false;
        };
        let presented: [u8; 32] = Sha256::digest(token.trim().as_bytes()).into();
        // Every digest is compared in full, whatever matched before.
        self.digests.iter().fold(false, |found, digest| found | constant_time_eq(digest, &presented))
    }
}

/// Equality of two digests in time independent of where they differ.
fn constant_time_eq(a: &[u8; 32], b: &[u8; 32]) -> bool {
    std::hint::black_box(a.iter().zip(b).fold(0u8, |diff, (x, y)| diff | (x ^ y))) == 0
}

/// Middleware: passes requests with a valid token (or every request when no tokens are
/// configured); answers 401 `unauthorized` with `WWW-Authenticate: Bearer` otherwise.
pub async fn require_token(State(state): State<Arc<AppState>>, request: Request, next: Next) -> Response {
    match &state.auth {
        Some(auth) if !auth.allows(request.headers().get(header::AUTHORIZATION)) => {
            let error = JobError::new(ErrorCode::Unauthorized, "this server needs a bearer token: Authorization: Bearer TOKEN");
            let mut response = ApiError(error).into_response();
            response.headers_mut().insert(header::WWW_AUTHENTICATE, HeaderValue::from_static("Bearer realm=\"penumbra\""));
            response
        }
        _ => next.run(request).await,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_configured_bearer_tokens_pass() {
        let auth = Auth::new(&["first-token-0123456789", "second-token-0123456789"], false);
        let header = |v: &str| HeaderValue::from_str(v).unwrap();
        assert!(auth.allows(Some(&header("Bearer first-token-0123456789"))));
        assert!(auth.allows(Some(&header("Bearer second-token-0123456789"))));
        assert!(!auth.allows(Some(&header("Bearer first-token-012345678"))), "a prefix is not the token");
        assert!(!auth.allows(Some(&header("first-token-0123456789"))), "the Bearer scheme is required");
        assert!(!auth.allows(Some(&header("Basic Zmlyc3Q="))));
        assert!(!auth.allows(None));
    }
}

//! Uploads (contract §3): `POST` a scene or light image for its content id, `PUT` it under
//! the SHA-256 a client computed, `HEAD` to ask whether it is held, `DELETE` to drop it; and,
//! with a shared store, fetching an upload another replica received.

use super::*;

/// `POST /v1/scenes`: a glTF (JSON with `data:` buffers) or GLB body → its content id. 201
/// when stored now, 200 when the same bytes were already there.
pub(super) async fn upload_scene(State(state): State<Arc<AppState>>, body: Result<Bytes, BytesRejection>) -> Response {
    upload(state, body, Kind::Scene).await
}

/// `POST /v1/lights`: a PNG or EXR body → its content id.
pub(super) async fn upload_light(State(state): State<Arc<AppState>>, body: Result<Bytes, BytesRejection>) -> Response {
    upload(state, body, Kind::Light).await
}

pub(super) async fn upload(state: Arc<AppState>, body: Result<Bytes, BytesRejection>, kind: Kind) -> Response {
    let bytes = match body {
        Ok(bytes) => bytes,
        Err(rejection) => return ApiError(body_error(&state, rejection, ErrorCode::InvalidAsset)).into_response(),
    };
    let engine = state.engine.clone();
    let shared = state.shared_store().cloned();
    // Decoding a large scene takes a while: off the async workers. A shared store keeps the
    // bytes once for every replica (after they decoded: a bad file is refused, not shared).
    let stored = move || {
        let receipt = engine.upload(kind, &bytes)?;
        if let Some(store) = shared {
            store.call_blocking(|s| s.put_upload(kind, &receipt.id, &bytes)).map_err(store_error)?;
        }
        Ok(receipt)
    };
    match tokio::task::spawn_blocking(stored).await {
        Ok(Ok(receipt)) => {
            let status = if receipt.created { StatusCode::CREATED } else { StatusCode::OK };
            (status, Json(receipt)).into_response()
        }
        Ok(Err(error)) => ApiError(error).into_response(),
        Err(_) => ApiError(JobError::new(ErrorCode::Internal, "the upload failed")).into_response(),
    }
}

/// `PUT`, `HEAD` and `DELETE` on `/v1/scenes/{id}` or `/v1/lights/{id}`.
pub(super) fn upload_routes(kind: Kind) -> axum::routing::MethodRouter<Arc<AppState>> {
    axum::routing::put(move |state: State<Arc<AppState>>, id: Path<String>, body: Result<Bytes, BytesRejection>| {
        put_upload(kind, state, id, body)
    })
    .head(move |state: State<Arc<AppState>>, id: Path<String>, headers: HeaderMap| head_upload(kind, state, id, headers))
    .delete(move |state: State<Arc<AppState>>, id: Path<String>| delete_upload(kind, state, id))
}

/// `HEAD /v1/scenes/{id}`, `HEAD /v1/lights/{id}`: 200 when held here or in a shared store,
/// with the upload's SHA-256 (its id) as `ETag` and its length; 304 for an `If-None-Match`
/// that names it; 404 when not held.
pub(super) async fn head_upload(kind: Kind, State(state): State<Arc<AppState>>, Path(id): Path<String>, headers: HeaderMap) -> Response {
    let size = match state.engine.upload_size(kind, &id) {
        Some(size) => Some(size),
        None => match state.shared_store().cloned() {
            Some(store) => {
                let shared_id = id.clone();
                match store.call(move |s| s.upload_size(kind, &shared_id)).await {
                    Ok(size) => size,
                    Err(_) => return StatusCode::SERVICE_UNAVAILABLE.into_response(),
                }
            }
            None => None,
        },
    };
    let Some(size) = size else { return StatusCode::NOT_FOUND.into_response() };
    let etag = format!("\"{id}\"");
    if not_modified(&headers, &etag) {
        return unchanged(&etag);
    }
    immutable(([(header::CONTENT_LENGTH, HeaderValue::from(size))]).into_response(), &etag)
}

/// `PUT /v1/scenes/{id}`, `PUT /v1/lights/{id}`: an idempotent upload under the id the client
/// computed (the SHA-256 of the body, checked here); 201 when stored now, 200 when held.
pub(super) async fn put_upload(
    kind: Kind,
    State(state): State<Arc<AppState>>,
    Path(id): Path<String>,
    body: Result<Bytes, BytesRejection>,
) -> Response {
    if !is_content_id(&id) {
        let message = "an upload id is the lowercase hex SHA-256 of the bytes (64 digits)";
        return ApiError(JobError::field(ErrorCode::InvalidField, "id", message)).into_response();
    }
    let bytes = match body {
        Ok(bytes) => bytes,
        Err(rejection) => return ApiError(body_error(&state, rejection, ErrorCode::InvalidAsset)).into_response(),
    };
    let actual = content_id(&bytes);
    if actual != id {
        let message = format!("the body's SHA-256 is {actual}, not the id in the path");
        return ApiError(JobError::field(ErrorCode::InvalidField, "id", message)).into_response();
    }
    upload(state, Ok(bytes), kind).await
}

/// `DELETE /v1/scenes/{id}`, `DELETE /v1/lights/{id}`: 204, or 404 when there was none.
pub(super) async fn delete_upload(kind: Kind, State(state): State<Arc<AppState>>, Path(id): Path<String>) -> Response {
    let mut deleted = state.engine.delete_upload(kind, &id);
    if let Some(store) = state.shared_store().cloned() {
        let shared_id = id.clone();
        deleted |= matches!(store.call(move |s| s.delete_upload(kind, &shared_id)).await, Ok(true));
    }
    if deleted {
        StatusCode::NO_CONTENT.into_response()
    } else {
        ApiError(JobError::field(ErrorCode::NotUploaded, "id", format!("no uploaded asset with id `{id}`"))).into_response()
    }
}

/// Loads into the engine's cache the uploads a job names that this replica does not hold but
/// the shared store does (another replica received them).
pub(super) fn fetch_shared_uploads(engine: &Engine, store: Option<&Store>, job: &Job) -> Result<(), JobError> {
    let Some(store) = store.filter(|s| s.shared()) else { return Ok(()) };
    let light = job.light.image.as_ref();
    for (kind, asset) in [(Kind::Scene, Some(&job.scene.asset)), (Kind::Light, light)] {
        let Some(crate::job::AssetRef::Id(id)) = asset else { continue };
        if engine.holds_upload(kind, id) {
            continue;
        }
        match store.call_blocking(|s| s.get_upload(kind, id)) {
            Ok(Some(bytes)) => {
                engine.upload(kind, &bytes)?;
            }
            Ok(None) => {} // The render reports `not_uploaded` for the field.
            Err(error) => tracing::warn!(%error, "cannot read a shared upload"),
        }
    }
    Ok(())
}

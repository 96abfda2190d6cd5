"""schemathesis hooks for scripts/api-fuzz: the document and the server agree on the
form of a request. A request generated from the document (positive mode) that the
server refuses as malformed in form is a mismatch between them."""
import schemathesis

# the codes the server gives a request whose form it cannot read: JSON that does not
# deserialise into the request type, or a multipart stream it cannot split
FORM_CODES = {"invalid_request", "malformed_json", "malformed_multipart"}


@schemathesis.check
def document_and_server_agree_on_form(ctx, response, case):
    meta = case.meta
    if meta is None or not meta.generation.mode.is_positive:
        return None
    if response.status_code not in (400, 422):
        return None
    try:
        code = response.json()["error"]["code"]
    except Exception:
        raise AssertionError(f"error without a JSON error body: {response.text[:200]}")
    if code in FORM_CODES:
        raise AssertionError(
            f"a request that keeps to the document was refused as {code}: {response.text[:300]}"
        )
    return None

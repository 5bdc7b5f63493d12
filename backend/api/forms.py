"""Multipart uploads, read the one bounded way (the vision and weather-file routes).

The body is read in chunks and refused (413) past ``limit`` bytes whatever
Content-Length says; then starlette parses it with caps on files and fields,
whose breach is a 422 naming ``files`` or ``form``; a malformed body is a 400.
"""

from __future__ import annotations

from typing import Any, TypeVar

from fastapi import HTTPException, Request
from pydantic import BaseModel, ValidationError
from starlette.datastructures import FormData

M = TypeVar("M", bound=BaseModel)

_TRUE = {"1", "true", "yes", "on"}
_FALSE = {"0", "false", "no", "off"}


async def read_form(request: Request, limit: int, expected: str, max_files: int,
                    max_fields: int = 256, limit_name: str = "HELIOTWIN_MAX_UPLOAD_BYTES",
                    files_field: str = "file") -> FormData:
    """The multipart form of ``request``; ``expected`` says what the 415 asks for,
    ``limit_name`` the setting a 413 names (the one ``limit`` comes from) and
    ``files_field`` the field of the files that a 413 for a body over ``limit`` and a 422
    for too many files name (the files are what makes a body that large)."""
    ctype = request.headers.get("content-type", "")
    if not ctype.lower().startswith("multipart/form-data"):
        raise HTTPException(415, f"send multipart/form-data ({expected})")
    length = request.headers.get("content-length")
    if length is not None and length.isdigit() and int(length) > limit:
        raise HTTPException(413, f"{files_field}: body of {length} bytes; the limit is "
                                 f"{limit} bytes ({limit_name})")
    chunks: list[bytes] = []
    size = 0
    async for chunk in request.stream():
        size += len(chunk)
        if size > limit:
            raise HTTPException(413, f"{files_field}: body over {limit} bytes ({limit_name})")
        chunks.append(chunk)
    body = b"".join(chunks)

    async def receive() -> dict[str, Any]:
        return {"type": "http.request", "body": body, "more_body": False}

    try:
        return await Request(request.scope, receive).form(
            max_files=max_files, max_fields=max_fields, max_part_size=limit)
    except Exception as exc:  # starlette's HTTPException(400) for a malformed body or limits
        text = str(getattr(exc, "detail", exc))
        if "Too many files" in text:
            raise HTTPException(422, f"{files_field}: at most {max_files} files per "
                                     "request") from None
        if "Too many fields" in text:
            raise HTTPException(422, f"form: at most {max_fields} fields per request") from None
        raise HTTPException(400, f"malformed multipart body: {text}") from None


def form_text(form: FormData, name: str) -> str | None:
    """A text field of ``form``; None when absent or a file."""
    value = form.get(name)
    return value if isinstance(value, str) else None


def form_flag(value: str | None, name: str, default: bool = False) -> bool:
    """A boolean form field (true/false, 1/0, yes/no, on/off); anything else a 422 naming it."""
    if value is None or not value.strip():
        return default
    v = value.strip().lower()
    if v in _TRUE | _FALSE:
        return v in _TRUE
    raise HTTPException(422, f"{name}: {value!r} is not a boolean (true or false)")


def form_model(model: type[M], form: FormData, skip: tuple[str, ...]) -> M:
    """The text fields of ``form`` but ``skip`` (the file, the flags read by
    :func:`form_flag`) validated by ``model`` (form fields are text: not strict); a 422
    naming each field at fault, an unknown one included when ``model`` forbids extras."""
    fields = {k: v for k, v in form.multi_items() if k not in skip and isinstance(v, str)}
    try:
        return model.model_validate(fields, strict=False)
    except ValidationError as exc:
        problems = "; ".join(f"{'.'.join(str(x) for x in e['loc'])}: {e['msg']}"
                             for e in exc.errors())
        raise HTTPException(422, problems) from None

"""The one exception service code raises for bad input, whatever the caller.

Service functions (``backend/<concept>/``) are called by HTTP routes and by the
CLI alike, so they raise :class:`InputError` with the HTTP status the problem
deserves and a message naming the field; the app turns it into
``{"detail": message}`` with that status, the CLI prints the message.

Also here, for every caller of the web layer and the ingest path alike: the
bounded form of validation problems (:func:`bounded_errors`) and the detection of
JSON keys given twice (:func:`load_json_pairs`, :func:`repeated_keys`).
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator, Mapping, Sequence
from typing import Any


class Refusal(Exception):  # noqa: N818 - an answer, not an error of the service
    """An ordinary answer to a caller (no such token, no such site), raised in a writer
    call: the writer hands it back without logging it as a failed write."""


class SetupError(RuntimeError):
    """What the service was given cannot be used (a database a newer heliotwin migrated,
    or one that cannot be connected to):
    the message says what and what to do, so the CLI prints it alone on one line and exits
    1 (``backend.cli.main``) — no traceback, which hid it."""


class InputError(ValueError):
    """Bad input: ``status_code`` (4xx) and a message that names the field and the problem."""

    def __init__(self, status_code: int, message: str) -> None:
        super().__init__(message)
        self.status_code = status_code
        self.detail = message


# ---------------------------------------------------------------- bounded error answers

#: Problems listed in one 422 answer, and characters of an echoed input or message.
MAX_LISTED = 20
_MAX_ECHO = 80
_INT64 = 2**63
#: Characters of an error answer's ``detail`` message: a message may quote what was sent
#: (a weather file's 5 MB header line came back whole in its 422).
MAX_DETAIL = 1000


def _clip(text: str, limit: int) -> str:
    """``text`` cut to ``limit`` characters, a lone surrogate (JSON may escape one, and no
    UTF-8 encodes it: orjson failed with a 500) written as its escape."""
    text = text if len(text) <= limit else text[: limit - 3] + "..."
    return text.encode("utf-8", "backslashreplace").decode("utf-8")


def bounded_detail(detail: Any) -> Any:
    """An error answer's ``detail``: a message cut to :data:`MAX_DETAIL` characters (a list
    of problems is :func:`bounded_errors`' already)."""
    return _clip(detail, MAX_DETAIL) if isinstance(detail, str) else detail


def _echo(value: Any) -> Any:
    """An input value safe and small to send back: JSON scalars as they are (integers
    within 64 bits, finite floats, short strings), anything else as a cut ``repr``."""
    if value is None or isinstance(value, bool):
        return value
    if isinstance(value, int):
        return value if -_INT64 <= value < _INT64 else _clip(repr(value), _MAX_ECHO)
    if isinstance(value, float):
        return value if math.isfinite(value) else repr(value)
    if isinstance(value, str):
        return _clip(value, _MAX_ECHO)
    return _clip(repr(value), _MAX_ECHO)


def bounded_errors(errors: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Validation problems (pydantic's ``errors()``) as a small JSON-safe list.

    Each entry keeps ``loc``, ``msg``, ``type`` and a cut ``input``; at most
    :data:`MAX_LISTED` are listed and one closing entry counts the rest. No input
    can make the answer large or unserialisable (an integer beyond 64 bits once
    made the 422 handler fail with a 500).
    """
    out: list[dict[str, Any]] = []
    for e in errors[:MAX_LISTED]:
        loc = [x if isinstance(x, int) and not isinstance(x, bool) else _clip(str(x), 40)
               for x in list(e.get("loc", ()))[:8]]
        item: dict[str, Any] = {"loc": loc, "msg": _clip(str(e.get("msg", "")), 300),
                                "type": _clip(str(e.get("type", "value_error")), 40)}
        if "input" in e:
            item["input"] = _echo(e["input"])
        out.append(item)
    if len(errors) > MAX_LISTED:
        out.append({"loc": ["body"], "type": "too_many_errors",
                    "msg": f"{len(errors) - MAX_LISTED} more problems not listed"})
    return out


# ---------------------------------------------------------------- repeated JSON keys


class _Pairs(dict):  # type: ignore[type-arg]
    """A JSON object that remembers the first key it was given twice (else ``None``)."""

    repeated: str | None = None


def _pairs_hook(pairs: list[tuple[str, Any]]) -> _Pairs:
    obj = _Pairs(pairs)
    if len(obj) != len(pairs):
        seen: set[str] = set()
        for key, _ in pairs:
            if key in seen:
                obj.repeated = key
                break
            seen.add(key)
    return obj


def load_json_pairs(body: bytes | str) -> Any:
    """Parse JSON keeping track of repeated keys (see :func:`repeated_keys`).

    Raises ``ValueError`` for invalid JSON (``json.JSONDecodeError``) and for what
    Python will not read (an integer of over 4300 digits).
    """
    return json.loads(body, object_pairs_hook=_pairs_hook)


def repeated_keys(doc: Any, path: tuple[str | int, ...] = ()
                  ) -> Iterator[tuple[tuple[str | int, ...], str]]:
    """``(path of the object, key)`` for every object of :func:`load_json_pairs`'s
    ``doc`` that was given a key twice, in document order (most JSON readers,
    Python's and orjson, silently keep the last)."""
    stack: list[tuple[tuple[str | int, ...], Any]] = [(path, doc)]
    while stack:
        where, node = stack.pop()
        if isinstance(node, _Pairs):
            if node.repeated is not None:
                yield where, node.repeated
            stack.extend((where + (k,), v) for k, v in reversed(list(node.items())))
        elif isinstance(node, list):
            stack.extend((where + (j,), v) for j, v in reversed(list(enumerate(node))))

"""One rule for the short texts people type and others read back: a token's label, an
alert's acknowledgement note. Both are stored (PostgreSQL refuses a NUL; a lone surrogate
is no UTF-8, and the driver failed on it with a 500) and shown on one line (the
dashboard, a webhook's one-line ``text``)."""

from __future__ import annotations

import unicodedata


def one_line_problem(text: str) -> str | None:
    """Why ``text`` is not one line of printable text, or None: a control character (C0,
    DEL, C1: Unicode category Cc), a line or paragraph separator (U+2028, U+2029), a lone
    surrogate, or a bidirectional control."""
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        return "holds a lone surrogate (not valid Unicode text)"
    if any(unicodedata.category(c) == "Cc" or c in "\u2028\u2029" for c in text):
        return ("holds a control character or a line break (a NUL, a tab, a newline…); "
                "write it on one line without")
    if any(c in _BIDI_CONTROLS for c in text):
        return ("holds a bidirectional control (U+202A-U+202E, U+2066-U+2069), which can "
                "show the text around it reordered; write it without")
    return None


#: Embeddings, overrides and isolates (Unicode 15, UAX #9): a label shown as who
#: acknowledged an alert could read as another name (a reviewer's finding)
_BIDI_CONTROLS = frozenset("\u202a\u202b\u202c\u202d\u202e\u2066\u2067\u2068\u2069")


def one_line(text: str) -> str:
    """``text`` if :func:`one_line_problem` finds nothing, else a ``ValueError`` saying what
    (pydantic's ``AfterValidator``: a 422 naming the field)."""
    problem = one_line_problem(text)
    if problem is not None:
        raise ValueError(problem)
    return text

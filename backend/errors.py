"""The one exception service code raises for bad input, whatever the caller.

Service functions (``backend/<concept>/``) are called by HTTP routes and by the
CLI alike, so they raise :class:`InputError` with the HTTP status the problem
deserves and a message naming the field; the app turns it into
``{"detail": message}`` with that status, the CLI prints the message.
"""

from __future__ import annotations


class InputError(ValueError):
    """Bad input: ``status_code`` (4xx) and a message that names the field and the problem."""

    def __init__(self, status_code: int, message: str) -> None:
        super().__init__(message)
        self.status_code = status_code
        self.detail = message

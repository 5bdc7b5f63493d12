"""Helpers shared by the ``bench_*.py`` scripts (each is run as a script from this folder)."""

from __future__ import annotations

import socket
import sys


def log(msg: str) -> None:
    """Progress on stderr: stdout carries only the Markdown section."""
    print(msg, file=sys.stderr, flush=True)


def free_port() -> int:
    """A TCP port on 127.0.0.1 that is free right now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])

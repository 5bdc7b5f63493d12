"""Helpers shared by the ``bench_*.py`` scripts (each is run as a script from this folder)."""

from __future__ import annotations

import socket
import sys
from pathlib import Path

from docs_figures import marked, verdict_text


def log(msg: str) -> None:
    """Progress on stderr: stdout carries only the Markdown section."""
    print(msg, file=sys.stderr, flush=True)


def free_port() -> int:
    """A TCP port on 127.0.0.1 that is free right now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def heliotwin_cmd() -> list[str]:
    """The ``heliotwin`` console script of this interpreter's venv (``python -m backend``
    where it is not installed)."""
    exe = Path(sys.executable).parent / "heliotwin"
    return [str(exe)] if exe.exists() else [sys.executable, "-m", "backend"]


class Figures:
    """The figures of one bench section, for ``benchmarks/results.json``.

    Each figure has a dotted name (``"sim.speedup_vs_modelchain"``), a value,
    a unit, the text shown for it, and optionally a target and whether it is
    met. :meth:`add` returns the text wrapped in a ``<!-- fig:NAME -->`` marker,
    so the section printed to RESULTS.md carries the same markers as the docs
    and ``benchmarks/docs_figures.py`` can check and rewrite both. :meth:`write`
    saves them to the file named by ``HELIOTWIN_BENCH_FIGURES`` (set by
    ``benchmarks/run.py``; a bench run alone only prints).
    """

    def __init__(self, section: str) -> None:
        self.section = section
        self.figures: dict[str, dict] = {}

    def add(
        self,
        name: str,
        value: float,
        unit: str,
        text: str,
        target: str | None = None,
        met: bool | None = None,
    ) -> str:
        """Record a figure; returns its text in a marker, for the Markdown section."""
        full = f"{self.section}.{name}"
        if full in self.figures:
            raise ValueError(f"figure {full!r} recorded twice")
        self.figures[full] = {
            "section": self.section,
            "value": float(value),
            "unit": unit,
            "text": text,
            "target": target,
            "met": None if met is None else bool(met),  # a numpy bool is not JSON
        }
        return marked(full, text)

    def verdict(self, name: str) -> str:
        """``"met"`` / ``"not met"`` of a figure with a target, as a marker."""
        full = f"{self.section}.{name}"
        return marked(f"{full}:verdict", verdict_text(self.figures[full]))

    def write(self) -> None:
        import json
        import os

        path = os.environ.get("HELIOTWIN_BENCH_FIGURES")
        if path:
            with open(path, "w", encoding="utf-8") as f:
                json.dump(self.figures, f, indent=1, ensure_ascii=False)

"""Rewrite the figures in the docs from ``benchmarks/results.json``.

The benchmarks (``benchmarks/run.py``) write every figure they measure to
``benchmarks/results.json`` — one entry per figure: ``value``, ``unit``, the
``text`` shown, ``target`` and ``met`` — with a date and machine stamp per
section. A document quotes a figure through a marker, never by hand::

    the sun is <!-- fig:sim.spa_speedup -->16×<!-- /fig --> faster

and this script replaces what stands between the markers with the figure's
text. ``<!-- fig:NAME:verdict -->`` gives ``met`` / ``**not met**`` against its
target, ``<!-- fig:NAME:target -->`` the target. It runs over ``docs/*.md``,
``README.md`` and ``benchmarks/RESULTS.md`` (whose sections carry the same markers).

    python benchmarks/docs_figures.py          # rewrite
    python benchmarks/docs_figures.py --check  # exit 1 if a marker is unknown or stale
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
RESULTS_JSON = HERE / "results.json"

MARKER = re.compile(r"<!-- fig:([A-Za-z0-9_.\-]+?)(?::(verdict|target))? -->(.*?)<!-- /fig -->")


def marked(name: str, text: str) -> str:
    """``<!-- fig:NAME -->text<!-- /fig -->``."""
    return f"<!-- fig:{name} -->{text}<!-- /fig -->"


def verdict_text(fig: dict) -> str:
    """How a figure stands against its target: ``met``, ``**not met**`` or ``—`` (no target)."""
    if fig.get("met") is None:
        return "—"
    return "met" if fig["met"] else "**not met**"


def load_figures(path: Path = RESULTS_JSON) -> dict[str, dict]:
    """``{name: figure}`` from results.json (empty when it does not exist yet)."""
    if not path.exists():
        return {}
    return dict(json.loads(path.read_text(encoding="utf-8"))["figures"])


def render(name: str, part: str | None, figures: dict[str, dict]) -> str:
    fig = figures[name]
    if part == "verdict":
        return verdict_text(fig)
    if part == "target":
        return fig.get("target") or "—"
    return str(fig["text"])


def rewrite(text: str, figures: dict[str, dict]) -> tuple[str, list[str]]:
    """``text`` with every known marker filled in, and the names of unknown ones."""
    missing: list[str] = []

    def sub(m: re.Match[str]) -> str:
        name, part = m.group(1), m.group(2)
        if name not in figures:
            missing.append(name)
            return m.group(0)
        suffix = f":{part}" if part else ""
        return marked(name + suffix, render(name, part, figures))

    return MARKER.sub(sub, text), missing


def documents(root: Path = ROOT) -> list[Path]:
    """The files whose markers are kept up to date."""
    return [*sorted((root / "docs").glob("*.md")), root / "README.md",
            root / "benchmarks" / "RESULTS.md"]


def main(argv: list[str]) -> int:
    check = "--check" in argv
    figures = load_figures()
    problems = 0
    for path in documents():
        if not path.exists():
            continue
        old = path.read_text(encoding="utf-8")
        new, missing = rewrite(old, figures)
        for name in missing:
            print(f"{path.relative_to(ROOT)}: no figure {name!r} in results.json", file=sys.stderr)
        problems += len(missing)
        if new != old:
            if check:
                print(f"{path.relative_to(ROOT)}: figures out of date", file=sys.stderr)
                problems += 1
            else:
                path.write_text(new, encoding="utf-8")
                print(f"rewrote figures in {path.relative_to(ROOT)}", file=sys.stderr)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

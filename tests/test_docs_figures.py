"""Every figure quoted in the docs comes from benchmarks/results.json, and is up to date with it."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def docs_figures():  # noqa: ANN201
    spec = importlib.util.spec_from_file_location(
        "docs_figures", ROOT / "benchmarks" / "docs_figures.py"
    )
    assert spec and spec.loader
    module = importlib.util.module_from_spec(spec)
    sys.modules["docs_figures"] = module
    spec.loader.exec_module(module)
    return module


def test_results_json_figures_are_complete(docs_figures) -> None:
    figures = docs_figures.load_figures()
    assert figures, "benchmarks/results.json is missing: run `make bench`"
    for name, fig in figures.items():
        assert name.startswith(fig["section"] + "."), name
        assert {"value", "unit", "text", "target", "met"} <= set(fig), name
        # a figure with a target says whether it is met, and one without says nothing
        assert (fig["target"] is None) == (fig["met"] is None), name


def test_every_document_with_markers_is_rewritten(docs_figures) -> None:
    """A marker in a Markdown file that docs_figures.py does not rewrite would go stale."""
    rewritten = set(docs_figures.documents())
    tops = [ROOT] + [d for d in ROOT.iterdir() if d.is_dir() and not d.name.startswith(".")
                     and d.name not in {"node_modules", "heliotwin.egg-info"}]
    files = {p for d in tops for p in (d.glob("*.md") if d == ROOT else d.rglob("*.md"))}
    marked = {p for p in files if docs_figures.MARKER.search(p.read_text(encoding="utf-8"))}
    assert marked <= rewritten, sorted(str(p.relative_to(ROOT)) for p in marked - rewritten)


@pytest.mark.parametrize("path", [
    *sorted((ROOT / "docs").glob("*.md")), ROOT / "README.md", ROOT / "benchmarks" / "RESULTS.md",
], ids=lambda p: p.name)
def test_doc_markers_have_figures_and_are_up_to_date(docs_figures, path: Path) -> None:
    text = path.read_text(encoding="utf-8")
    new, missing = docs_figures.rewrite(text, docs_figures.load_figures())
    assert not missing, f"{path.name}: no figure in results.json for {sorted(set(missing))}"
    assert new == text, (
        f"{path.name} is out of date with results.json: run python benchmarks/docs_figures.py"
    )


def test_rewrite_fills_markers_and_verdicts(docs_figures) -> None:
    figs = {
        "x.rate": {
            "section": "x",
            "value": 990.0,
            "unit": "req/s",
            "text": "990 req/s",
            "target": "≥ 1,000 req/s",
            "met": False,
        },
    }
    text = "rate <!-- fig:x.rate -->old<!-- /fig --> (<!-- fig:x.rate:verdict -->met<!-- /fig -->)"
    new, missing = docs_figures.rewrite(text, figs)
    assert missing == []
    assert new == (
        "rate <!-- fig:x.rate -->990 req/s<!-- /fig --> "
        "(<!-- fig:x.rate:verdict -->**not met**<!-- /fig -->)"
    )
    _, missing = docs_figures.rewrite("<!-- fig:x.nope -->1<!-- /fig -->", figs)
    assert missing == ["x.nope"]


def test_the_bench_runner_refuses_a_section_it_does_not_have() -> None:
    """``benchmarks/run.py dashbord`` (or ``--help``) ran no bench, said "wrote RESULTS.md"
    and exited 0: now a typo is refused naming the sections, and nothing is written."""
    results = ROOT / "benchmarks" / "RESULTS.md"
    before = results.stat().st_mtime_ns
    p = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "run.py"), "dashbord"],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 2, p.stderr
    assert "no section dashbord" in p.stderr and " dashboard " in p.stderr
    assert results.stat().st_mtime_ns == before

"""Run ``benchmarks/bench_*.py``; write ``benchmarks/RESULTS.md`` and ``benchmarks/results.json``.

Each bench script is a standalone program that measures its figures as ratios
against a baseline run in the same process and prints one Markdown section
(starting with ``## <name>``, the script's name without ``bench_``) to stdout;
progress goes to stderr. A script that records its figures with
``_common.Figures`` also writes them to the file named by
``HELIOTWIN_BENCH_FIGURES``, which this runner sets.

This runner stamps each section it ran with the date, the machine, the commit
and the load average before and after, and replaces in RESULTS.md and
results.json only the sections it ran: a partial run leaves the others, with
their own stamps, as they were (both files are read after the scripts ran, so a
section another run wrote meanwhile is kept). A script that fails leaves its previous section
and figures in place (the exit status says it failed). Finally it runs
``docs_figures.py``, which rewrites the ``<!-- fig:NAME -->`` markers in
``docs/*.md`` and RESULTS.md from results.json.

    python benchmarks/run.py            # all of them
    python benchmarks/run.py sim vision # only bench_sim.py and bench_vision.py
"""

from __future__ import annotations

import datetime as dt
import json
import os
import platform
import re
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import docs_figures  # noqa: E402

RESULTS_MD = HERE / "RESULTS.md"
HEADER = (
    "# Benchmark results\n\nWritten by `make bench` (`benchmarks/run.py`); the figures are also in "
    "`benchmarks/results.json`, from which `benchmarks/docs_figures.py` fills the "
    "`<!-- fig:… -->` markers here and in `docs/`. Every figure is a ratio against a baseline "
    "measured in the same run, or an absolute time on the machine named in its section's stamp. "
    "A figure with a target says whether it is met.\n"
)
STAMP = re.compile(r"^_Measured .*_$", re.M)


def _git(*args: str) -> str:
    try:
        return subprocess.run(
            ["git", *args], capture_output=True, text=True, cwd=HERE, check=False
        ).stdout.strip()
    except OSError:
        return ""


def machine() -> dict[str, object]:
    """What the figures were measured on."""
    cpu = platform.processor() or platform.machine()
    cpuinfo = Path("/proc/cpuinfo")
    for line in cpuinfo.read_text().splitlines() if cpuinfo.exists() else []:
        if line.startswith("model name"):
            cpu = line.split(":", 1)[1].strip()
            break
    return {
        "cores": os.cpu_count(),
        "cpu": cpu,
        "python": platform.python_version(),
        "commit": _git("rev-parse", "--short", "HEAD") or "?",
        "uncommitted_changes": bool(_git("status", "--porcelain", "--untracked-files=no")),
    }


def stamp_text(stamp: dict) -> str:
    """The one line under a section's heading that says when and where it was measured."""
    m = stamp["machine"]
    tree = " with uncommitted changes in the tree" if m["uncommitted_changes"] else ""
    return (
        f"_Measured {stamp['measured_utc']} UTC on {m['cores']} cores ({m['cpu']}), "
        f"Python {m['python']}, commit {m['commit']}{tree}; load average (1 min) "
        f"{stamp['load_1min_start']:.1f} at the start, {stamp['load_1min_end']:.1f} at the end._"
    )


def split_sections(text: str) -> dict[str, str]:
    """``{name: section}`` of a RESULTS.md; the name is the heading's first word."""
    out: dict[str, str] = {}
    for chunk in ("\n" + text).split("\n## ")[1:]:
        name = chunk.split(maxsplit=1)[0]
        out[name] = "## " + chunk.rstrip() + "\n"
    return out


def with_stamp(section: str, stamp_line: str) -> str:
    """The section with ``stamp_line`` under its heading (replacing an older stamp)."""
    heading, _, body = section.partition("\n")
    body = STAMP.sub("", body, count=1).strip("\n")
    return f"{heading}\n\n{stamp_line}\n\n{body}\n"


def run_one(script: Path) -> tuple[str | None, dict, dict]:
    """Run one bench script: (its section or None if it failed, its figures, its stamp)."""
    with tempfile.TemporaryDirectory() as d:
        fig_path = Path(d) / "figures.json"
        env = {**os.environ, "HELIOTWIN_BENCH_FIGURES": str(fig_path)}
        load0 = os.getloadavg()[0]
        started = dt.datetime.now(dt.UTC)
        proc = subprocess.run(
            [sys.executable, str(script)], stdout=subprocess.PIPE, text=True, env=env
        )
        stamp = {
            "measured_utc": f"{started:%Y-%m-%d %H:%M}",
            "machine": machine(),
            "load_1min_start": load0,
            "load_1min_end": os.getloadavg()[0],
        }
        try:
            figures = json.loads(fig_path.read_text()) if fig_path.exists() else {}
        except json.JSONDecodeError:  # the script died writing them: it failed
            figures = None
    if proc.returncode != 0 or figures is None:
        print(f"{script.name} FAILED (exit {proc.returncode})", file=sys.stderr)
        return None, {}, stamp
    return proc.stdout.strip() + "\n", figures, stamp


def load_sections() -> dict[str, str]:
    """The sections of RESULTS.md as it is now, each with its stamp."""
    old_text = RESULTS_MD.read_text() if RESULTS_MD.exists() else ""
    sections = split_sections(old_text)
    # sections written before per-section stamps carry the file's old global one
    legacy = re.search(r"^Measured (.*)$", old_text.split("\n## ", 1)[0], re.M)
    for name, sec in sections.items():
        if legacy and not STAMP.search(sec):
            sections[name] = with_stamp(sec, f"_Measured {legacy.group(1).rstrip('.')}._")
    return sections


def load_store() -> dict:
    """results.json as it is now."""
    if docs_figures.RESULTS_JSON.exists():
        return json.loads(docs_figures.RESULTS_JSON.read_text())
    return {"sections": {}, "figures": {}}


def main(argv: list[str]) -> int:
    scripts = sorted(HERE.glob("bench_*.py"))
    names = [s.stem.removeprefix("bench_") for s in scripts]
    if {"-h", "--help"} & set(argv):
        print(__doc__.strip() + "\n\nsections: " + " ".join(names))
        return 0
    if unknown := [a for a in argv if a not in names]:
        # a typo ran nothing and said "wrote RESULTS.md"
        print(f"run.py: no section {', '.join(unknown)}; the sections: {' '.join(names)}",
              file=sys.stderr)
        return 2
    if argv:
        scripts = [s for s in scripts if s.stem.removeprefix("bench_") in argv]
    failed = []
    ran: dict[str, tuple[str, dict, dict]] = {}
    for script in scripts:
        name = script.stem.removeprefix("bench_")
        print(f"== {script.name}", file=sys.stderr, flush=True)
        section, figures, stamp = run_one(script)
        if section is None:
            failed.append(script.name)
            continue
        if not section.startswith(f"## {name}"):
            section = f"## {name}\n\n" + section
        print(section)
        ran[name] = (with_stamp(section, stamp_text(stamp)), figures, stamp)
    # read the files only now: other sessions may have run other sections meanwhile
    sections, store = load_sections(), load_store()
    for name, (section, figures, stamp) in ran.items():
        sections[name] = section
        store["sections"][name] = stamp
        store["figures"] = {
            k: v for k, v in store["figures"].items() if v.get("section") != name
        } | figures
    store["figures"] = dict(sorted(store["figures"].items()))
    store["sections"] = dict(sorted(store["sections"].items()))
    docs_figures.RESULTS_JSON.write_text(json.dumps(store, indent=1, ensure_ascii=False) + "\n")
    RESULTS_MD.write_text(HEADER + "\n" + "\n".join(sections[k] for k in sorted(sections)))
    print(f"wrote {RESULTS_MD} and {docs_figures.RESULTS_JSON}", file=sys.stderr)
    docs_figures.main([])
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

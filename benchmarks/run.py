"""Run every ``benchmarks/bench_*.py`` and write ``benchmarks/RESULTS.md``.

Each bench script is a standalone program that measures its figures as ratios
against a baseline run in the same process and prints one Markdown section
(starting with ``## ``) to stdout; progress goes to stderr. This runner only
collects the sections, notes the machine, and writes the file.

    python benchmarks/run.py            # all of them
    python benchmarks/run.py sim vision # only bench_sim.py and bench_vision.py
"""

from __future__ import annotations

import datetime as dt
import os
import platform
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def machine_note() -> str:
    """One line that says on what the figures were measured."""
    try:
        commit = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, cwd=HERE
        ).stdout.strip()
    except OSError:
        commit = "?"
    cpu = platform.processor() or platform.machine()
    cpuinfo = Path("/proc/cpuinfo")
    for line in cpuinfo.read_text().splitlines() if cpuinfo.exists() else []:
        if line.startswith("model name"):
            cpu = line.split(":", 1)[1].strip()
            break
    return (
        f"Measured {dt.datetime.now(dt.UTC):%Y-%m-%d %H:%M} UTC on {os.cpu_count()} cores "
        f"({cpu}), Python {platform.python_version()}, commit {commit or '?'}."
    )


def main(argv: list[str]) -> int:
    scripts = sorted(HERE.glob("bench_*.py"))
    if argv:
        scripts = [s for s in scripts if s.stem.removeprefix("bench_") in argv]
    sections, failed = [], []
    for script in scripts:
        print(f"== {script.name}", file=sys.stderr, flush=True)
        proc = subprocess.run([sys.executable, str(script)], stdout=subprocess.PIPE, text=True)
        if proc.returncode != 0:
            failed.append(script.name)
            sections.append(f"## {script.stem}\n\nFAILED (exit {proc.returncode}).\n")
        else:
            sections.append(proc.stdout.strip() + "\n")
        print(sections[-1])
    out = HERE / "RESULTS.md"
    if argv and out.exists():  # partial run: replace only the sections that ran
        old = out.read_text().split("\n## ")
        kept = {s.split("\n", 1)[0]: "## " + s for s in old[1:]}
        for sec in sections:
            kept[sec.split("\n", 1)[0].removeprefix("## ")] = sec
        sections = [kept[k].rstrip() + "\n" for k in kept]
    header = (
        "# Benchmark results\n\nWritten by `make bench` (`benchmarks/run.py`). "
        "Every figure is a ratio against a baseline measured in the same run, or an "
        "absolute time on the machine named here.\n\n" + machine_note() + "\n"
    )
    out.write_text(header + "\n" + "\n".join(s.rstrip() + "\n" for s in sections))
    print(f"wrote {out}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

"""The order of the suite (the modules that hold a long test run first), and the
``heliotwin_cli`` fixture (a CLI command run in this process).

``make test`` spreads the modules over two pytest-xdist workers (``--dist loadfile``), each
module whole on one worker, handed out in collection order (``--no-loadscope-reorder``).
The browser modules (``tests/e2e/``) go out together, as one unit, to one worker: their
session fixtures (a ``heliotwin serve`` back-filled with three days, Chromium) then start
once, not once per worker. A long unit handed out last keeps one worker busy while the
other has nothing left to do, so the browser unit goes first, then the modules holding a
test marked ``slow`` (more than a few seconds); the rest keep their order and fill in
behind them. The order of the tests inside a module does not change. Every worker collects
the same order, as xdist requires; a run without xdist is left in pytest's own order.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import pytest

#: the markers of a test that takes long
LONG = ("slow", "browser")
#: the browser modules' folder: one xdist work unit
BROWSER_UNIT = "tests/e2e/"


def _is_long(item: pytest.Item) -> bool:
    return any(item.get_closest_marker(name) is not None for name in LONG)


def _module(nodeid: str) -> str:
    return nodeid.split("::", 1)[0]


@pytest.hookimpl(trylast=True)  # after the hooks that add markers (tests/e2e/conftest.py)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """In an xdist worker, move the browser unit to the front, then the modules that hold a
    long test (a stable sort: otherwise in collection order). A plain pytest keeps its
    order (``--ff``…)."""
    if not hasattr(config, "workerinput"):
        return
    long_modules = {_module(item.nodeid) for item in items if _is_long(item)}
    items.sort(key=lambda item: (not item.nodeid.startswith(BROWSER_UNIT),
                                 _module(item.nodeid) not in long_modules))


@pytest.hookimpl(optionalhook=True)  # a run with -p no:xdist has no such hook
def pytest_xdist_make_scheduler(config: pytest.Config, log: Any) -> Any:
    """Under ``--dist loadfile``, xdist's file scheduling with ``tests/e2e/`` as one unit."""
    if config.getoption("dist", None) != "loadfile":
        return None
    from xdist.scheduler import LoadFileScheduling

    class BrowserUnitScheduling(LoadFileScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return BROWSER_UNIT if nodeid.startswith(BROWSER_UNIT) else _module(nodeid)

    return BrowserUnitScheduling(config, log)


@dataclass
class CliRun:
    """What a ``heliotwin`` command left: its exit code and what it printed."""

    returncode: int
    stdout: str
    stderr: str


@pytest.fixture
def heliotwin_cli(capsys: pytest.CaptureFixture[str],
                  monkeypatch: pytest.MonkeyPatch) -> Callable[..., CliRun]:
    """``heliotwin ARGS`` in this process: ``backend.cli.main`` (the console script's
    function: same parser, dispatch, error line and exit code), its stdout and stderr
    captured. ``env`` gives the ``HELIOTWIN_*`` settings the command sees (none of this
    run's others), as the environment of a subprocess would. A process costs about a
    second of imports, so the CLI tests keep one or two real processes (the entry point, a
    terminal, a closed pipe) and run the rest here."""
    from backend.cli import main

    def run(*args: str, env: Mapping[str, str] | None = None) -> CliRun:
        with monkeypatch.context() as m:
            if env is not None:
                for name in [k for k in os.environ if k.startswith("HELIOTWIN_")]:
                    m.delenv(name)
                for name, value in env.items():
                    if name.startswith("HELIOTWIN_"):
                        m.setenv(name, value)
            capsys.readouterr()  # what the test printed before is not the command's
            try:
                code = main(list(args))
            except SystemExit as exc:  # argparse's usage errors exit 2
                code = exc.code if isinstance(exc.code, int) else int(exc.code is not None)
            out = capsys.readouterr()
        return CliRun(code, out.out, out.err)

    return run

"""The order of the suite: the modules that hold a long test run first.

``make test`` spreads the modules over two pytest-xdist workers (``--dist loadfile``), each
module whole on one worker, handed out in collection order (``--no-loadscope-reorder``).
A long module handed out last keeps one worker busy while the other has nothing left to
do, so the modules holding a test marked ``slow`` (more than a few seconds) or ``browser``
(a real Chromium) go first; the rest keep their order and fill in behind them. The order
of the tests inside a module does not change. Every worker collects the same order, as
xdist requires; a run without xdist is left in pytest's own order.
"""

from __future__ import annotations

import pytest

#: the markers of a test that takes long
LONG = ("slow", "browser")


def _is_long(item: pytest.Item) -> bool:
    return any(item.get_closest_marker(name) is not None for name in LONG)


@pytest.hookimpl(trylast=True)  # after the hooks that add markers (tests/e2e/conftest.py)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """In an xdist worker, move the modules that hold a long test to the front (a stable
    sort: otherwise in collection order). A plain pytest keeps its order (``--ff``…)."""
    if not hasattr(config, "workerinput"):
        return
    long_modules = {item.nodeid.split("::", 1)[0] for item in items if _is_long(item)}
    items.sort(key=lambda item: item.nodeid.split("::", 1)[0] not in long_modules)

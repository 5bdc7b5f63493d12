"""Imports go one way: backend -> sim -> vision (DESIGN.md, "Layout")."""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FORBIDDEN = {"vision": {"sim", "backend"}, "sim": {"backend"}}


def _imported_packages(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.add(node.module.split(".")[0])
    return found


@pytest.mark.parametrize("package", sorted(FORBIDDEN))
def test_import_direction(package: str) -> None:
    offenders = []
    for path in sorted((ROOT / package).rglob("*.py")):
        bad = _imported_packages(path) & FORBIDDEN[package]
        if bad:
            offenders.append(f"{path.relative_to(ROOT)} imports {sorted(bad)}")
    assert not offenders, "\n".join(offenders)


def test_sim_and_vision_do_no_web_or_database() -> None:
    web = {"fastapi", "sqlalchemy", "uvicorn", "starlette", "httpx", "viser"}
    offenders = [
        f"{p.relative_to(ROOT)} imports {sorted(_imported_packages(p) & web)}"
        for pkg in ("sim", "vision")
        for p in sorted((ROOT / pkg).rglob("*.py"))
        if _imported_packages(p) & web
    ]
    assert not offenders, "\n".join(offenders)

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


# backend by concept (docs/architecture.md): the web layer (api/, app.py) and the CLI sit on
# top; the concept packages below never import them or the web framework, so the CLI and
# the routes call the same service functions.
WEB_LAYER = {"backend.api", "backend.app", "backend.cli"}
WEB_FRAMEWORK = {"fastapi", "starlette", "uvicorn"}
CONCEPTS = ("storage", "measurements", "twin", "vision", "plants")
LEAF_MODULES = ("auth.py", "sites.py", "timestamps.py", "errors.py", "settings.py",
                "context.py")


def _imported_modules(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.add(node.module)
    return found


def _service_modules() -> list[Path]:
    out = [p for c in CONCEPTS for p in sorted((ROOT / "backend" / c).rglob("*.py"))]
    return out + [ROOT / "backend" / m for m in LEAF_MODULES]


def test_services_do_not_import_the_web_layer() -> None:
    offenders = []
    for path in _service_modules():
        mods = _imported_modules(path)
        bad = {m for m in mods if m.split(".")[0] in WEB_FRAMEWORK
               or any(m == w or m.startswith(w + ".") for w in WEB_LAYER)}
        if bad:
            offenders.append(f"{path.relative_to(ROOT)} imports {sorted(bad)}")
    assert not offenders, "\n".join(offenders)


def test_storage_is_the_bottom_of_backend() -> None:
    offenders = []
    for path in sorted((ROOT / "backend" / "storage").rglob("*.py")):
        ours = {m for m in _imported_modules(path) if m.startswith("backend.")}
        bad = {m for m in ours if not m.startswith(("backend.storage", "backend.settings"))}
        if bad:
            offenders.append(f"{path.relative_to(ROOT)} imports {sorted(bad)}")
    assert not offenders, "\n".join(offenders)


def test_tables_are_declared_in_one_module() -> None:
    declaring = [p.relative_to(ROOT).as_posix() for pkg in ("backend",)
                 for p in sorted((ROOT / pkg).rglob("*.py"))
                 if "__tablename__" in p.read_text() and "migrations" not in p.parts]
    assert declaring == ["backend/storage/tables.py"]

"""Imports go one way: backend -> sim -> vision (DESIGN.md, "Layout"); inside backend the
concept packages never reach up to the web layer (docs/architecture.md).

Every module of every package is read, found by walking the folders (a package added
later is covered without editing this file), and every import is resolved to an absolute
module name: ``from . import x`` and ``from ..storage import tables`` count as much as
``import backend.storage.tables``, and ``from backend import api`` names ``backend.api``.
"""

import ast
import re
from functools import cache
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("backend", "sim", "vision")
FORBIDDEN = {"vision": {"sim", "backend"}, "sim": {"backend"}}


def module_name(path: Path) -> str:
    """``backend/storage/tables.py`` -> ``backend.storage.tables`` (a package: its folder)."""
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports_of(source: str, module: str, is_package: bool = False) -> set[str]:
    """Every module ``source`` (the text of ``module``) imports, as absolute names;
    ``from M import n`` gives ``M`` and ``M.n`` (n may be a submodule). Relative imports
    are resolved against the module's package (the module itself when ``is_package``)."""
    package = module.split(".") if is_package else module.split(".")[:-1]
    found: set[str] = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[:len(package) - (node.level - 1)]
                assert base, f"{module}: a relative import above the top package"
                parts = base + (node.module.split(".") if node.module else [])
            else:
                parts = node.module.split(".") if node.module else []
            name = ".".join(parts)
            found.add(name)
            found.update(f"{name}.{alias.name}" for alias in node.names if alias.name != "*")
    return found


@cache
def imported_modules(path: Path) -> frozenset[str]:
    """:func:`imports_of` one file of ours."""
    return frozenset(imports_of(path.read_text(), module_name(path), path.name == "__init__.py"))


def modules_of(package: str) -> list[Path]:
    return sorted((ROOT / package).rglob("*.py"))


def test_relative_imports_are_resolved() -> None:
    assert module_name(ROOT / "backend" / "storage" / "__init__.py") == "backend.storage"
    assert module_name(ROOT / "backend" / "storage" / "tables.py") == "backend.storage.tables"
    source = ("from . import tables\nfrom ..settings import Settings\n"
              "from .engine import make_engine\nfrom backend import api\n")
    assert imports_of(source, "backend.storage.rows") == {
        "backend.storage", "backend.storage.tables", "backend.settings",
        "backend.settings.Settings", "backend.storage.engine",
        "backend.storage.engine.make_engine", "backend", "backend.api"}
    # in a package's __init__, "." is the package itself
    assert imports_of("from .api import deps\n", "backend", is_package=True) == {
        "backend.api", "backend.api.deps"}
    with pytest.raises(AssertionError, match="above the top package"):
        imports_of("from ... import x\n", "vision.cameras")


@pytest.mark.parametrize("package", sorted(FORBIDDEN))
def test_import_direction(package: str) -> None:
    offenders = []
    for path in modules_of(package):
        bad = {m.split(".")[0] for m in imported_modules(path)} & FORBIDDEN[package]
        if bad:
            offenders.append(f"{path.relative_to(ROOT)} imports {sorted(bad)}")
    assert not offenders, "\n".join(offenders)


def test_sim_and_vision_do_no_web_or_database() -> None:
    web = {"fastapi", "sqlalchemy", "uvicorn", "starlette", "httpx", "viser"}
    offenders = [
        f"{p.relative_to(ROOT)} imports {sorted(bad)}"
        for pkg in ("sim", "vision")
        for p in modules_of(pkg)
        if (bad := {m.split(".")[0] for m in imported_modules(p)} & web)
    ]
    assert not offenders, "\n".join(offenders)


# backend by concept (docs/architecture.md): the web layer (api/, app.py) and the CLI sit on
# top; the concept packages and the top-level modules below them never import them or the
# web framework, so the CLI and the routes call the same service functions.
WEB_LAYER = {"backend.api", "backend.app", "backend.cli", "backend.__main__"}
WEB_FRAMEWORK = {"fastapi", "starlette", "uvicorn"}


def concept_packages() -> list[str]:
    """Every package of backend/ that is not the web layer or the CLI."""
    return sorted(p.parent.name for p in (ROOT / "backend").glob("*/__init__.py")
                  if f"backend.{p.parent.name}" not in WEB_LAYER)


def service_modules() -> list[Path]:
    """The concept packages' modules and backend's top-level modules under the web layer."""
    out = [p for c in concept_packages() for p in modules_of(f"backend/{c}")]
    return out + [p for p in sorted((ROOT / "backend").glob("*.py"))
                  if module_name(p) not in WEB_LAYER]


def test_every_concept_package_is_checked() -> None:
    # the packages of docs/architecture.md; a new one is checked without being listed here
    assert set(concept_packages()) >= {"alerts", "diagnosis", "measurements", "mqtt",
                                       "plants", "storage", "twin", "vision"}
    checked = {module_name(p) for p in service_modules()}
    assert {"backend.auth", "backend.context", "backend.settings", "backend.sites",
            "backend.limits"} <= checked
    assert not any(m == w or m.startswith(w + ".") for m in checked for w in WEB_LAYER)


def test_services_do_not_import_the_web_layer() -> None:
    offenders = []
    for path in service_modules():
        mods = imported_modules(path)
        bad = {m for m in mods if m.split(".")[0] in WEB_FRAMEWORK
               or any(m == w or m.startswith(w + ".") for w in WEB_LAYER)}
        if bad:
            offenders.append(f"{path.relative_to(ROOT)} imports {sorted(bad)}")
    assert not offenders, "\n".join(offenders)


def test_storage_is_the_bottom_of_backend() -> None:
    """Storage imports only itself, the settings and ``backend.errors`` — a leaf beneath it
    (the error types every layer raises, the standard library alone: checked here), so
    that storage can raise a ``SetupError`` the CLI prints in one line."""
    offenders = []
    for path in modules_of("backend/storage"):
        ours = {m for m in imported_modules(path) if m == "backend" or m.startswith("backend.")}
        bad = {m for m in ours if not m.startswith(("backend.storage", "backend.settings"))
               and m.split(".")[:2] != ["backend", "errors"]}
        if bad:
            offenders.append(f"{path.relative_to(ROOT)} imports {sorted(bad)}")
    assert not offenders, "\n".join(offenders)
    leaf = {m for m in imported_modules(ROOT / "backend" / "errors.py")
            if m.split(".")[0] in ("backend", "sim", "vision")}
    assert not leaf, f"backend/errors.py imports {sorted(leaf)}: it must stay a leaf"


def test_tables_are_declared_in_one_module() -> None:
    declaring = [p.relative_to(ROOT).as_posix() for p in modules_of("backend")
                 if re.search(r"__tablename__\s*=", p.read_text())
                 and "migrations" not in p.parts]
    assert declaring == ["backend/storage/tables.py"]

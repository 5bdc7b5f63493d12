"""Every name the docs point at exists: files, Python objects, test functions and HTTP routes.

The docs (``docs/*.md``, ``README.md``) name code in backticks: repository paths
(``sim/twin.py``, ``tests/sim/test_sun.py::test_x``), dotted names rooted at our
packages (``sim.twin.simulate``), short ``module.attribute`` forms
(``kinematics.tracking_angles``), ``Class.attribute`` forms (``TwinResult.series``),
signatures (``solar_position(times, …)``), test names (``test_twin_on_…``) and
routes (``GET /api/v1/sites/{site_id}``). A rename that leaves the doc behind
fails here, with the doc and the name.

Only what is clearly a reference to this repository is checked: a name rooted
elsewhere (``pvlib.…``, ``np.clip``, ``Plotly.react``), a placeholder (``<plant_id>``,
``…``) or a JSON field (``sky.source``) is not.
"""

from __future__ import annotations

import ast
import importlib
import re
from collections.abc import Iterator
from functools import cache
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = [*sorted((ROOT / "docs").glob("*.md")), ROOT / "README.md"]
PACKAGES = ("sim", "vision", "backend")
PATH_ROOTS = (*PACKAGES, "frontend", "data", "tests", "benchmarks", "docs", ".ci")
# paths a doc names that the repository holds only at run time (git-ignored)
RUNTIME_PATHS = {"data/heliotwin.sqlite", "data/user-sites/", "test-artifacts/"}
# drift in files this test's author does not own, reported to their owners: listed
# here so the rest is guarded today; an entry that no longer fails must be removed
KNOWN_DRIFT: dict[tuple[str, str], str] = {}
PLACEHOLDER = re.compile(r"[<>{}*…|\[\]]")
FENCE = re.compile(r"^```.*?^```", re.S | re.M)
TICKED = re.compile(r"`([^`\n]+)`")
DOTTED = re.compile(r"(?<![\w./-])((?:sim|vision|backend)(?:\.[A-Za-z_]\w*)+)")
SHORT = re.compile(r"^([a-z_]\w*)\.([A-Za-z_]\w*)(\(.*\))?$")
CLASS_ATTR = re.compile(r"^([A-Z]\w*)\.([A-Za-z_]\w*)")
# a signature as the docs write one: `name(args) -> type` or `name(..., x=None)`;
# a bare call (`configure_default_lights(cast_shadow=False)`) may be a library's
SIGNATURE = re.compile(r"^([a-z]\w*_\w*)\((?=.*(?:->|\.\.\.))")
TEST_NAME = re.compile(r"^(test_\w+)$")
ROUTE = re.compile(r"^((?:GET|POST|PUT|DELETE|PATCH)(?:/(?:GET|POST|PUT|DELETE|PATCH))*) (/\S+)")


def ticked(doc: Path) -> Iterator[str]:
    """The inline backticked spans of a Markdown file (fenced code blocks left out)."""
    text = FENCE.sub("", doc.read_text(encoding="utf-8"))
    for m in TICKED.finditer(text):
        yield m.group(1).strip()


def _rel(doc: Path) -> str:
    return str(doc.relative_to(ROOT))


@cache
def our_modules() -> dict[str, list[str]]:
    """``{last name: [dotted module names]}`` for every module of our packages."""
    out: dict[str, list[str]] = {}
    for pkg in PACKAGES:
        for path in (ROOT / pkg).rglob("*.py"):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out.setdefault(parts[-1], []).append(".".join(parts))
    return out


@cache
def _defs() -> tuple[dict[str, list[str]], set[str]]:
    """Classes (``{name: [module]}``) and function names defined anywhere in our packages."""
    classes: dict[str, list[str]] = {}
    functions: set[str] = set()
    for modules in our_modules().values():
        for module in modules:
            path = ROOT / Path(*module.split("."))
            path = path / "__init__.py" if path.is_dir() else path.with_suffix(".py")
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                if isinstance(node, ast.ClassDef):
                    classes.setdefault(node.name, []).append(module)
                elif isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                    functions.add(node.name)
    return classes, functions


@cache
def defined_tests() -> set[str]:
    """Names of the test functions under ``tests/``."""
    names: set[str] = set()
    for path in (ROOT / "tests").rglob("test_*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                names.add(node.name)
    return names


def has_attribute(obj: Any, name: str) -> bool:
    """``name`` is an attribute of ``obj``, or a field of a dataclass / pydantic model."""
    if hasattr(obj, name):
        return True
    if name in getattr(obj, "__dataclass_fields__", {}) or name in getattr(
        obj, "model_fields", {}
    ):
        return True
    return any(name in getattr(k, "__annotations__", {}) for k in getattr(obj, "__mro__", ()))


def resolve(dotted: str) -> bool:
    """Whether ``a.b.c`` is an importable module, or an attribute chain below one."""
    parts = dotted.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj: Any = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        for name in parts[i:]:
            if not has_attribute(obj, name):
                return False
            obj = getattr(obj, name, None)
        return True
    return False


def python_names(doc: Path) -> Iterator[tuple[str, str]]:
    """(what the doc wrote, the fully qualified candidates joined by ``|``) to resolve."""
    classes, _ = _defs()
    for span in ticked(doc):
        if "…" in span:
            continue
        for dotted in DOTTED.findall(span):
            yield span, dotted
        short = SHORT.match(span)
        # `module.attribute` is a code reference when the module is ours and the
        # attribute looks like code (an underscore, a capital, or called), not a JSON field
        if short and short.group(1) not in PACKAGES and short.group(1) in our_modules():
            attr = short.group(2)
            if "_" in attr or attr != attr.lower() or short.group(3) is not None:
                yield span, "|".join(f"{m}.{attr}" for m in our_modules()[short.group(1)])
        cls = CLASS_ATTR.match(span)
        if cls and cls.group(1) in classes:
            name, attr = cls.groups()
            yield span, "|".join(f"{m}.{name}.{attr}" for m in classes[name])


def assert_none_missing(what: str, missing: list[tuple[Path, str, str]]) -> None:
    """Fail on every (doc, span, why) in ``missing`` but the known drift, which must still fail."""
    lines, known = [], set()
    for doc, span, why in missing:
        key = next((k for k in KNOWN_DRIFT if k[0] == _rel(doc) and span.startswith(k[1])), None)
        if key is None:
            lines.append(f"{_rel(doc)}: `{span}` {why}")
        known.add(key)
    assert not lines, f"docs name {what} that do not exist:\n" + "\n".join(lines)
    fixed = {k for k, w in KNOWN_DRIFT.items() if w == what} - known
    assert not fixed, f"fixed in the docs: remove {sorted(fixed)} from KNOWN_DRIFT"


def test_named_files_exist() -> None:
    missing = []
    for doc in DOCS:
        for span in ticked(doc):
            path, _, test = span.split(" ")[0].partition("::")
            if not path.startswith(tuple(r + "/" for r in PATH_ROOTS)) or PLACEHOLDER.search(path):
                continue
            if path in RUNTIME_PATHS:
                continue
            if not (ROOT / path).exists():
                missing.append((doc, span, ""))
            elif test and not re.search(
                rf"^\s*(async )?def {re.escape(test)}\b", (ROOT / path).read_text(), re.M
            ):
                missing.append((doc, span, f"(no such function in {path})"))
    assert_none_missing("files or tests", missing)


def test_named_python_objects_exist() -> None:
    missing = [
        (doc, span, f"({candidates})")
        for doc in DOCS
        for span, candidates in python_names(doc)
        if not any(resolve(c) for c in candidates.split("|"))
    ]
    assert_none_missing("Python objects", missing)


def test_named_functions_and_tests_exist() -> None:
    _, functions = _defs()
    tests = defined_tests()
    missing = []
    for doc in DOCS:
        for span in ticked(doc):
            sig, name = SIGNATURE.match(span), TEST_NAME.match(span)
            if sig and sig.group(1) not in functions:
                missing.append((doc, span, f"(no function {sig.group(1)})"))
            if name and name.group(1) not in tests:
                missing.append((doc, span, f"(no test {name.group(1)})"))
    assert_none_missing("functions or tests", missing)


def route_key(method: str, path: str) -> tuple[str, str]:
    """A route with its parameters' names erased: ``GET /api/v1/sites/{}``."""
    return method.upper(), re.sub(r"\{[^}]*\}", "{}", path.rstrip("/") or "/")


@pytest.fixture(scope="module")
def app_routes(tmp_path_factory: pytest.TempPathFactory) -> set[tuple[str, str]]:
    """Every (method, path) the application declares, in its router or its OpenAPI."""
    from backend.app import create_app
    from backend.settings import Settings

    db = tmp_path_factory.mktemp("names") / "names.sqlite"
    app = create_app(Settings(database_url=f"sqlite:///{db}"))
    routes = {
        route_key(method, route.path)
        for route in app.routes
        for method in getattr(route, "methods", None) or ()
    }
    for path, item in app.openapi()["paths"].items():
        routes |= {route_key(method, path) for method in item}
    return routes


def doc_routes(span: str) -> list[tuple[str, str]]:
    """The (method, path) pairs a span like ``GET/PUT /api/v1/x[/{id}]?a=`` names."""
    m = ROUTE.match(span)
    if not m or not m.group(2).startswith("/api/"):
        return []
    path = re.split(r"\[\?|[?\s]", m.group(2))[0]
    optional = re.search(r"\[(/[^\]]*)\]", path)
    paths = (
        [path[: optional.start()], path[: optional.start()] + optional.group(1)]
        if optional
        else [path]
    )
    return [route_key(method, p) for method in m.group(1).split("/") for p in paths]


def test_doc_routes_parse() -> None:
    assert doc_routes("GET/PUT /api/v1/sites/{site}/arrays/{array}/calibration") == [
        ("GET", "/api/v1/sites/{}/arrays/{}/calibration"),
        ("PUT", "/api/v1/sites/{}/arrays/{}/calibration"),
    ]
    assert doc_routes("GET /api/v1/vision/calibrations[/{id}]") == [
        ("GET", "/api/v1/vision/calibrations"),
        ("GET", "/api/v1/vision/calibrations/{}"),
    ]
    assert doc_routes("GET /api/v1/tokens[?site_id=]") == [("GET", "/api/v1/tokens")]
    assert doc_routes("GET …/diagnosis") == []


def test_named_routes_exist(app_routes: set[tuple[str, str]]) -> None:
    assert ("GET", "/healthz") in app_routes  # the fixture sees the application's routes
    missing = [
        f"{_rel(doc)}: `{span}`"
        for doc in DOCS
        for span in ticked(doc)
        for key in doc_routes(span)
        if key not in app_routes
    ]
    assert not missing, "docs name routes the application does not have:\n" + "\n".join(missing)


def test_the_checks_have_teeth(tmp_path: Path) -> None:
    doc = tmp_path / "x.md"
    doc.write_text(
        "`sim.twin.simulate` `sim.twin.no_such` `kinematics.no_such_fn` `TwinResult.nope`"
        " `sky.source`\n```\n`sim.not_checked_in_a_fence`\n```\n",
        encoding="utf-8",
    )
    bad = [c for _, c in python_names(doc) if not any(resolve(x) for x in c.split("|"))]
    assert bad == ["sim.twin.no_such", "sim.kinematics.no_such_fn", "sim.twin.TwinResult.nope"]


# a command line: the span or the code line starts with it (a prompt or a path may come first)
CLI_LINE = re.compile(r"^\s*(?:\$ )?(?:\S*/)?heliotwin((?: [a-z][a-z-]*)+)(.*)")


def cli_mentions(doc: Path) -> Iterator[str]:
    """Every ``heliotwin …`` command line a doc shows, inline or in a code block."""
    text = doc.read_text(encoding="utf-8")
    # a code block's command may continue on the next line after a backslash
    lines = [line for block in FENCE.findall(text)
             for line in block.replace("\\\n", " ").splitlines()]
    for span in [*ticked(doc), *lines]:
        if m := CLI_LINE.match(span):
            yield "heliotwin" + m.group(1) + m.group(2)


def cli_problems(line: str, parser: Any) -> list[str]:
    """What in ``heliotwin …`` the CLI does not have: an unknown command or option."""
    m = CLI_LINE.match(line)
    assert m
    words, rest = m.group(1).split(), m.group(2)
    sub = parser
    for i, word in enumerate(words):
        choices = next((a.choices for a in sub._actions if a.choices and isinstance(
            a.choices, dict)), None)
        if not choices:  # a positional argument's value, e.g. `token revoke TOKEN`
            rest = " ".join(words[i:]) + rest
            break
        if word not in choices:
            return [f"no command {' '.join(words[: i + 1])!r}"]
        sub = choices[word]
    known = set(sub._option_string_actions)
    return [f"no option {flag}" for flag in re.findall(r"(?<![\w-])--[a-z0-9][a-z0-9-]*", rest)
            if flag not in known]


def test_named_cli_commands_and_options_exist() -> None:
    from backend.cli import build_parser

    parser = build_parser()
    assert cli_problems("heliotwin simulate --site x --no-such-flag", parser) == [
        "no option --no-such-flag"]
    assert cli_problems("heliotwin nope", parser) == ["no command 'nope'"]
    missing = [
        (doc, line, "; ".join(problems))
        for doc in DOCS
        for line in cli_mentions(doc)
        if (problems := cli_problems(line, parser))
    ]
    assert_none_missing("CLI commands or options", missing)


SETTING = re.compile(r"\bHELIOTWIN_[A-Z0-9_]*[A-Z0-9]\b")
# environment variables of the tests and benchmarks, and docker-compose.yml's published
# ports, not of the service
NOT_SETTINGS = {"HELIOTWIN_REQUIRE_SERVICES", "HELIOTWIN_TEST_PG_URL", "HELIOTWIN_BENCH_FIGURES",
                "HELIOTWIN_PUBLISH_PORT", "HELIOTWIN_PUBLISH_VISER_PORT",
                "HELIOTWIN_TOKEN"}  # the posting commands' token (backend.cli.TOKEN_ENV)


def test_named_settings_are_in_the_readme_table() -> None:
    """A setting a doc names is one the README's settings table lists (which
    tests/backend/test_settings.py keeps equal to ``backend/settings.py``)."""
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    table = {m.group(1) for m in re.finditer(r"^\| `(HELIOTWIN_[A-Z0-9_]+)` \|", readme, re.M)}
    assert len(table) > 20, "the README's settings table was not found"
    missing = [
        (doc, name, "(not in the README's settings table)")
        for doc in DOCS
        for name in sorted(set(SETTING.findall(doc.read_text(encoding="utf-8"))))
        if name not in table | NOT_SETTINGS
    ]
    assert_none_missing("settings", missing)


def test_the_readme_lists_every_docs_page() -> None:
    """The README's "Documentation" list names every page of docs/ (five were found only
    by a search) and none that is gone."""
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    section = readme.split("## Documentation", 1)[1]
    listed = set(re.findall(r"^- `docs/([a-z0-9_-]+\.md)`", section, re.M))
    pages = {p.name for p in (ROOT / "docs").glob("*.md")}
    assert listed == pages, (sorted(pages - listed), sorted(listed - pages))

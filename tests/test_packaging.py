"""``pip install .`` (not editable) gives a service that serves every feature (issue 21).

The wheel is built from a copy of the sources, installed into a fresh venv and started as
``heliotwin serve`` from a folder outside the repository, so every file it reads at run
time must come from the installed packages: the dashboard (``frontend/`` shipped as
``backend/frontend``), the built-in sites and plants (``sim/data``), the migrations and
the vision model (``vision/confidence.json``). No network: the wheel is built with the
setuptools of the dev extras (``--no-build-isolation``) and the fresh venv borrows the
dependencies already installed for this test run through a ``.pth`` file.
"""

from __future__ import annotations

import os
import re
import shutil
import socket
import subprocess
import sys
import sysconfig
import time
import tomllib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import httpx
import numpy as np
import pytest
from packaging.requirements import Requirement
from packaging.version import Version

ROOT = Path(__file__).resolve().parents[1]
#: What the build reads (pyproject.toml and setup.py say what goes into the wheel).
SOURCES = ("pyproject.toml", "setup.py", "README.md", "backend", "sim", "vision", "frontend")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _run(args: list[str], cwd: Path, env: dict[str, str] | None = None) -> str:
    out = subprocess.run(args, cwd=cwd, env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, f"{args}\n{out.stdout}\n{out.stderr}"
    return out.stdout


def _clean_env(home: Path) -> dict[str, str]:
    """This run's environment less our settings and import paths, with a throw-away home."""
    env = {k: v for k, v in os.environ.items()
           if not k.startswith(("HELIOTWIN_", "PYTHON", "VIRTUAL_ENV", "XDG_DATA_HOME"))}
    env["HOME"] = str(home)
    return env


@dataclass
class Installed:
    """The fresh venv with the wheel, the throw-away home it runs with, the served URL."""

    venv: Path
    home: Path
    base_url: str


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Installed]:
    tmp = tmp_path_factory.mktemp("packaging")
    src, dist, venv, home, run = (tmp / n for n in ("src", "dist", "venv", "home", "run"))
    for d in (src, home, run):
        d.mkdir()
    for name in SOURCES:
        path = ROOT / name
        if path.is_dir():
            shutil.copytree(path, src / name,
                            ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
        else:
            shutil.copy2(path, src / name)
    env = _clean_env(home)
    _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation",
          "--no-index", "-q", "-w", str(dist), str(src)], cwd=tmp, env=env)
    (wheel,) = dist.glob("heliotwin-*.whl")
    _run([sys.executable, "-m", "venv", "--without-pip", str(venv)], cwd=tmp, env=env)
    python = venv / "bin" / "python"
    _run([sys.executable, "-m", "pip", "--python", str(python), "install", "--no-deps",
          "--no-index", "-q", str(wheel)], cwd=tmp, env=env)
    # the dependencies of this test run, after the venv's own site-packages (the wheel wins)
    site = Path(_run([str(python), "-c", "import sysconfig; print(sysconfig.get_path("
                      "'purelib'))"], cwd=run, env=env).strip())
    deps = {sysconfig.get_path("purelib"), sysconfig.get_path("platlib")}
    (site / "_test_dependencies.pth").write_text("\n".join(sorted(deps)) + "\n")

    port = _free_port()
    serve_env = {**env, "HELIOTWIN_VISER": "false", "HELIOTWIN_LIVE_TWIN": "false"}
    log = (tmp / "serve.log").open("wb")
    proc = subprocess.Popen([str(venv / "bin" / "heliotwin"), "serve", "--no-demo",
                             "--port", str(port), "--viser-port", str(_free_port())],
                            cwd=run, env=serve_env, stdout=log, stderr=subprocess.STDOUT)
    base_url = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 120
        while True:
            try:
                if httpx.get(base_url + "/healthz", timeout=2).status_code == 200:
                    break
            except httpx.TransportError:
                pass
            if proc.poll() is not None or time.monotonic() > deadline:
                pytest.fail("heliotwin serve did not come up:\n"
                            + (tmp / "serve.log").read_text(errors="replace")[-4000:])
            time.sleep(0.3)
        yield Installed(venv, home, base_url)
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        log.close()


@pytest.mark.slow
def test_the_code_runs_from_the_venv_not_from_the_checkout(installed: Installed) -> None:
    out = subprocess.run(
        [str(installed.venv / "bin" / "python"), "-c",
         "import backend, sim, vision; print(backend.__file__, sim.__file__, vision.__file__)"],
        cwd=installed.home, env=_clean_env(installed.home), capture_output=True, text=True,
        check=True)
    for path in out.stdout.split():
        assert Path(path).is_relative_to(installed.venv), path


@pytest.mark.slow
def test_the_database_goes_to_the_user_data_folder(installed: Installed) -> None:
    # not a checkout: the SQLite file is in ~/.local/share/heliotwin (sim.paths.user_data_dir)
    assert (installed.home / ".local" / "share" / "heliotwin" / "heliotwin.sqlite").is_file()


@pytest.mark.slow
def test_dashboard_page_script_and_plotly(installed: Installed) -> None:
    with httpx.Client(base_url=installed.base_url, timeout=30) as c:
        page = c.get("/")
        assert page.status_code == 200 and "/static/js/main.js" in page.text
        # the Plotly URL carries the vendored version read from package.json, not "missing"
        version = re.search(r"/vendor/plotly\.min\.js\?v=([^\"]+)\"", page.text)
        assert version and version.group(1) != "missing", page.text[:2000]
        js = c.get("/static/js/main.js")
        assert js.status_code == 200
        assert js.content == (ROOT / "frontend" / "js" / "main.js").read_bytes()
        assert c.get("/static/css/app.css").status_code == 200
        plotly = c.get("/vendor/plotly.min.js", headers={"Accept-Encoding": "identity"})
        assert plotly.status_code == 200
        assert len(plotly.content) == (ROOT / "frontend/vendor/plotly/plotly.min.js").stat().st_size


@pytest.mark.slow
def test_health_sites_and_plants(installed: Installed) -> None:
    with httpx.Client(base_url=installed.base_url, timeout=30) as c:
        assert c.get("/healthz").json() == {"status": "ok"}
        site = c.get("/api/v1/sites/tehuantepec")
        assert site.status_code == 200, site.text
        assert site.json()["site_id"] == "tehuantepec"
        ids = {s["site_id"] for s in c.get("/api/v1/sites").json()}
        assert {"tehuantepec", "guadalajara_fisheye"} <= ids
        plant = c.get("/api/v1/plants/penarroya")
        assert plant.status_code == 200, plant.text
        assert plant.json()["plant_id"] == "penarroya"


@pytest.mark.slow
def test_vision_detection_uses_the_shipped_confidence_model(installed: Installed) -> None:
    img = np.full((480, 640, 3), 40, np.uint8)
    cv2.circle(img, (400, 200), 9, (255, 255, 255), -1)
    ok, buf = cv2.imencode(".png", img)
    assert ok
    r = httpx.post(installed.base_url + "/api/v1/vision/sun", timeout=60,
                   files={"file": ("f.png", buf.tobytes(), "image/png")},
                   data={"camera": "pinhole", "fov_deg": "67"})
    assert r.status_code == 200, r.text
    d = r.json()
    assert d["sun_found"] and 0.5 <= d["confidence"] <= 1.0
    assert d["centroid_px"] == pytest.approx([400, 200], abs=0.5)


def test_every_floor_is_the_major_minor_that_constraints_pins() -> None:
    """A floor in pyproject.toml is a version the test suite ran with (issue 21): the
    major.minor of the pin in constraints.txt, which must satisfy the whole range."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())
    pins: dict[str, Version] = {}
    for line in (ROOT / "constraints.txt").read_text().splitlines():
        if line and not line.startswith("#"):
            name, version = line.split("==")
            pins[name.lower().replace("_", "-")] = Version(version)
    requirements = [*project["build-system"]["requires"], *project["project"]["dependencies"],
                    *(r for extra in project["project"]["optional-dependencies"].values()
                      for r in extra)]
    for text in requirements:
        req = Requirement(text)
        pin = pins[req.name.lower().replace("_", "-")]
        assert pin in req.specifier, (text, str(pin))
        (floor,) = [Version(s.version) for s in req.specifier if s.operator == ">="]
        assert floor.release[:2] == pin.release[:2], (text, str(pin))

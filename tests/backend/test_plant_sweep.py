"""``heliotwin plant sweep`` on a Dask cluster this test starts by hand on 127.0.0.1 (a
scheduler and two single-threaded workers, as a user with a cluster would), and its
refusals. The rows' physics is checked in tests/sim/plant/test_plant_fields.py."""

from __future__ import annotations

import json
import re
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any, cast

import pytest
from live_service import run_in_own_thread

from backend.cli import main
from sim.plant.sweep import SweepCase, SweepSpec

BIN = Path(sys.executable).parent
SWEEP = ["plant", "sweep", "--collector-m", "12x5", "--lat", "38.299224", "--lon", "-5.303114",
         "--start", "2021-12-20", "--end", "2021-12-22", "--step-s", "1800", "--no-progress"]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _start_scheduler(folder: Path) -> tuple[subprocess.Popen[bytes], str]:
    """``dask scheduler`` on 127.0.0.1 at a port it takes itself (``--port 0``), and its
    address from its scheduler file, once it listens. A free port found here and handed to
    it raced the workers started beside it: a worker's HTTP server got the same port from
    the kernel first, the scheduler exited ("address in use"), and the client's handshake
    with that worker hung a CI run for good."""
    path = folder / "scheduler.json"
    proc = subprocess.Popen([str(BIN / "dask"), "scheduler", "--host", "127.0.0.1", "--port",
                             "0", "--scheduler-file", str(path), "--no-dashboard"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 60.0
    while True:
        try:
            return proc, str(json.loads(path.read_text())["address"])
        except (OSError, ValueError, KeyError):  # not written yet, or half written
            pass
        if proc.poll() is not None or time.monotonic() > deadline:
            proc.kill()
            raise RuntimeError(f"dask scheduler did not start (exit {proc.poll()})")
        time.sleep(0.05)


@pytest.fixture(scope="module")
def scheduler(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """``dask scheduler`` and two ``dask worker`` processes on 127.0.0.1; their address."""
    first, address = _start_scheduler(tmp_path_factory.mktemp("dask"))
    procs = [first]
    procs += [subprocess.Popen([str(BIN / "dask"), "worker", address, "--nthreads", "1",
                                "--no-nanny", "--host", "127.0.0.1", "--no-dashboard"],
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
              for _ in range(2)]
    try:
        from distributed import Client

        with Client(address, timeout="60s") as client:
            client.wait_for_workers(2, timeout=120)
        yield address
    finally:
        for p in procs:          # throw-away processes of this test: no graceful close
            p.kill()
        for p in procs:
            p.wait(20)


def test_sweep_runs_on_the_given_cluster(scheduler: str, capsys: pytest.CaptureFixture[str]
                                         ) -> None:
    """Six cases as tasks on the two workers: both run cases, each computes the sky of the
    range at most once (the reuse), and the rows carry the contract's columns."""
    t0 = time.perf_counter()
    code = main([*SWEEP, "--layouts", "square,hexagonal_e_w", "--gcr", "0.15:0.35:0.1",
                 "--scheduler", scheduler, "--json"])
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    assert out["engine"] == "dask" and out["scheduler"] == scheduler
    assert out["workers"] == 2 and out["cases"] == 6
    assert out["worker_processes"] == 2                       # both workers ran cases
    assert out["sky_computations"] <= 2                       # once per worker, not per case
    assert out["wall_s"] <= time.perf_counter() - t0
    rows = out["rows"]
    assert [(r["layout"], r["gcr"]) for r in rows] == [
        (lay, g) for lay in ("hexagonal_e_w", "square") for g in (0.15, 0.25, 0.35)]
    for r in rows:
        assert set(r) >= {"layout", "gcr", "strategy", "interior_beam_shaded_pct",
                          "field_beam_shaded_pct", "energy_kwh_per_collector",
                          "energy_mwh_per_ha", "land_m2_per_collector"}
        assert r["land_m2_per_collector"] == pytest.approx(60.0 / r["gcr"], rel=1e-6)
        assert r["energy_mwh_per_ha"] == pytest.approx(
            r["energy_kwh_per_collector"] / r["land_m2_per_collector"] * 10, rel=1e-3)
        # the interior collector's per hectare too (a large plant's: the dashboard's curves)
        assert r["interior_energy_mwh_per_ha"] == pytest.approx(
            r["interior_energy_kwh"] / r["land_m2_per_collector"] * 10, rel=1e-3)
    for lay in ("square", "hexagonal_e_w"):                  # denser: more shade, less each
        mine = [r for r in rows if r["layout"] == lay]
        assert [r["interior_beam_shaded_pct"] for r in mine] == sorted(
            r["interior_beam_shaded_pct"] for r in mine)
        assert [r["energy_kwh_per_collector"] for r in mine] == sorted(
            (r["energy_kwh_per_collector"] for r in mine), reverse=True)


def test_a_sweep_on_its_own_cluster_logs_nothing_below_warning() -> None:
    """The one-shot command's LocalCluster: distributed's import set its loggers back to
    INFO after the CLI quieted them (33 lines a run, its dashboard's address among them)."""
    p = subprocess.run([str(BIN / "heliotwin"), *SWEEP, "--gcr", "0.2,0.3", "--workers", "1",
                        "--json"], capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    assert json.loads(p.stdout)["cases"] == 2
    assert " INFO " not in p.stderr, p.stderr[:2000]


def test_one_case_runs_in_process_as_csv(capsys: pytest.CaptureFixture[str]) -> None:
    assert main([*SWEEP, "--gcr", "0.2", "--csv"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("layout,gcr,strategy,interior_beam_shaded_pct,")
    assert len(lines) == 2 and lines[1].startswith("square,0.2,sun,")


@pytest.mark.parametrize(("extra", "message"), [
    (["--gcr", "0.6"], "--gcr: square at GCR 0.6: gcr 0.6 outside (0, 0.3550]"),
    (["--gcr", "0.2,x"], "--gcr: expected numbers"),
    (["--gcr", "20,30"], "--gcr: every GCR must be in (0, 1), got [20.0, 30.0]: a fraction of "
     "the ground, 0.3 not 30 (%)"),
    # the request's bound; on the command line 99,999 m ran, its energy negative
    (["--gcr", "0.2", "--altitude-m", "99999"], "--altitude-m: must be in [-500, 9000] m, "
     "got 99999"),
    (["--gcr", "0.2", "--collector-m", "12000x5000"], "--collector-m: width 12000 m is more "
     "than 50 m, larger than any tracker's collector: give metres (not mm or cm)"),
    (["--gcr", "0.2", "--layouts", "triangle"], "--layouts: must be one or more of"),
    (["--gcr", "0.2", "--strategy", "moon"], "--strategy: must be one or more of"),
    (["--gcr", "0.2", "--field", "5"], "--field: expected ROWSxCOLUMNS like 5x5"),
    (["--gcr", "0.2", "--layouts", "custom"], "--layouts: layout custom needs --aspect-ratio, "
     "--offset and --rotation-deg"),
    (["--gcr", "0.2", "--layouts", "custom", "--offset", "0.1"], "--aspect-ratio: layout "
     "custom takes --aspect-ratio, --offset and --rotation-deg together"),
    (["--gcr", "0.2", "--rotation-deg", "30"], "--rotation-deg: --aspect-ratio, --offset and "
     "--rotation-deg apply only to layout custom, which --layouts (square) does not hold"),
    (["--gcr", "0.2", "--layouts", "custom", "--aspect-ratio", "1", "--offset", "0.7",
      "--rotation-deg", "0"], "--offset: custom at GCR 0.2: offset must be in [-0.5, 0.5)"),
    (["--gcr", "0.2", "--step-s", "1"], "--step-s: 1 cases"),
    # a range of 200,001 GCRs: refused before any list or Dask task is made
    (["--gcr", "0.1:0.3:0.000001"], "--gcr: range '0.1:0.3:0.000001' holds 200,001 values, "
     "more than 40"),
    (["--gcr", "0.1:0.3:1e-15"], "more than 40"),
    (["--gcr", ",".join(["0.2"] * 41)], "--gcr: 41 values, more than 40"),
    # a name listed twice ran its cases twice; 10,000 times was "too many cases" on --gcr
    (["--gcr", "0.1:0.3:0.01", "--layouts", "square,diagonal,hexagonal_n_s,hexagonal_e_w,"
      "square", "--strategy", "sun,backtrack,sky_scan"],
     "--layouts: square is listed twice: list each once"),
    (["--gcr", "0.2", "--layouts", ",".join(["square"] * 10_000)],
     "--layouts: square is listed twice"),
    (["--gcr", "0.2", "--strategy", "sun,backtrack,sun"], "--strategy: sun is listed twice"),
    (["--gcr", "0.2,0.3,0.20"], "--gcr: 0.2 is listed twice"),
    # a thousand worker processes on two cores hung; -1 hung; 0 was the default
    (["--gcr", "0.2,0.3", "--workers", "1000"], "--workers: 1000 is not in [1, "),
    (["--gcr", "0.2,0.3", "--workers", "0"], "--workers: 0 is not in [1, "),
    (["--gcr", "0.2", "--timezone", "Europe/Penarroya"], "--timezone: 'Europe/Penarroya' is "
     "not an IANA time zone"),
    # distributed's own ValueError came out as a traceback
    (["--gcr", "0.2,0.3", "--scheduler", "http://127.0.0.1:8786"],
     "--scheduler: 'http://127.0.0.1:8786' is no Dask scheduler address (tcp://HOST:PORT)"),
])
def test_bad_input_names_the_flag(extra: list[str], message: str,
                                  capsys: pytest.CaptureFixture[str]) -> None:
    args = [*SWEEP, *extra]
    if extra == ["--gcr", "0.2", "--step-s", "1"]:
        args = [a if a != "2021-12-22" else "2023-12-22" for a in args]
    with pytest.raises(SystemExit) as exc:
        raise SystemExit(main(args))
    assert exc.value.code == 2
    assert message in capsys.readouterr().err


def test_a_plant_too_small_to_scale_names_the_plant(tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """A one-tracker plant has no ground area to scale to a GCR: the refusal names --plant
    (it named --layouts, which a plant's sweep ignores)."""
    from sim.plant import default_plants_dir

    d = json.loads((default_plants_dir() / "penarroya.json").read_text())
    d.update(plant_id="solo", frame="enu", trackers=[{"tracker_id": 1, "east_m": 0,
                                                      "north_m": 0}])
    (tmp_path / "solo.json").write_text(json.dumps(d))
    with pytest.raises(SystemExit) as exc:
        raise SystemExit(main(["plant", "sweep", "--plant", "solo", "--plants-dir",
                               str(tmp_path), "--gcr", "0.2", "--start", "2024-06-21",
                               "--end", "2024-06-22"]))
    assert exc.value.code == 2
    assert ("--plant: plant solo at GCR 0.2: a plant needs at least 3 trackers"
            in capsys.readouterr().err)


L_TEXT = "-6,-2.5;6,-2.5;6,0;0,0;0,2.5;-6,2.5"
POLY_SWEEP = [a for a in SWEEP if a not in ("--collector-m", "12x5")]



def test_the_documented_polygon_examples_survive_a_shell(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """The L of docs/plants.md and of ``plant sweep --help`` is quoted: typed into a shell,
    it stays one argument (unquoted, ``;`` ended the command at the first vertex)."""
    import re
    import shlex

    docs = (Path(__file__).resolve().parents[2] / "docs" / "plants.md").read_text()
    (line,) = [x for x in docs.splitlines() if "plant sweep" in x and "collector-polygon=" in x]
    monkeypatch.setenv("COLUMNS", "1000")  # the help unwrapped
    with pytest.raises(SystemExit):
        main(["plant", "sweep", "--help"])
    (example,) = re.findall(r"'--collector-polygon=[^']*'", capsys.readouterr().out)
    for text in (line, example):
        words = shlex.split(text, comments=True)
        (arg,) = [w for w in words if w.startswith("--collector-polygon")]
        assert arg == f"--collector-polygon={L_TEXT}", text


def test_a_polygon_collector_from_text_or_file(tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    """``--collector-polygon`` as text and as a JSON file give the same row: the L's land
    per collector is its 45 m² over the GCR."""
    # a first vertex with a minus reads as a flag to argparse: the = form
    assert main([*POLY_SWEEP, f"--collector-polygon={L_TEXT}", "--gcr", "0.2", "--json"]) == 0
    (row,) = json.loads(capsys.readouterr().out)["rows"]
    assert row["land_m2_per_collector"] == pytest.approx(225.0)
    assert row["interior_beam_shaded_pct"] > 0
    path = tmp_path / "l.json"
    path.write_text(json.dumps([[float(x) for x in p.split(",")] for p in L_TEXT.split(";")]))
    assert main([*POLY_SWEEP, "--collector-polygon", str(path), "--gcr", "0.2", "--json"]) == 0
    (again,) = json.loads(capsys.readouterr().out)["rows"]
    assert again == row


@pytest.mark.parametrize(("extra", "message"), [
    (["--collector-polygon", "0,0;2,2;2,0;0,1"], "--collector-polygon: collector outline: "
     "the polygon crosses itself"),
    (["--collector-polygon", "0,0;2"], "--collector-polygon: expected vertices u,v"),
    ([f"--collector-polygon={L_TEXT}", "--strategy", "sun,backtrack"],
     "--strategy: a polygon collector takes strategy sun only"),
    ([f"--collector-polygon={L_TEXT}", "--collector-m", "12x5"], "--collector-m: give the "
     "collector size, e.g. 12x5, or its polygon"),
    # its steps weigh 100× in the bound of a token's sweep as in an anonymous one (the CLI
    # took 1,051,200 polygon steps, worth 105 million of the rectangle's, against 50 million)
    ([f"--collector-polygon={L_TEXT}", "--end", "2023-12-20", "--step-s", "60"],
     "--step-s: 1 cases × 1051200 steps (a polygon collector's steps count 100×) is more "
     "than 50,000,000: use a larger --step-s, a shorter range or fewer cases"),
])
def test_bad_polygon_names_the_flag(extra: list[str], message: str,
                                    capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        raise SystemExit(main([*POLY_SWEEP, "--gcr", "0.2", *extra]))
    assert exc.value.code == 2
    assert message in capsys.readouterr().err


def test_unreachable_scheduler_is_an_error(monkeypatch: pytest.MonkeyPatch,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    """Nothing listens at the address: one error line, exit 2 (distributed retries a
    refused connection until the connect timeout: 1 s here, not the 5 s it costs a user)."""
    from backend.plants import sweep as sweep_mod

    monkeypatch.setattr(sweep_mod, "CONNECT_TIMEOUT", "1s")
    port = _free_port()
    with pytest.raises(SystemExit) as exc:
        raise SystemExit(main([*SWEEP, "--gcr", "0.2,0.3", "--scheduler",
                               f"tcp://127.0.0.1:{port}"]))
    assert exc.value.code == 2
    assert "--scheduler: cannot reach" in capsys.readouterr().err


@pytest.fixture
def silent_port() -> Iterator[int]:
    """A port that accepts connections (the kernel's backlog) and never answers, as the
    Dask dashboard's or ``python -m http.server`` to Dask's binary handshake."""
    with socket.socket() as srv:
        srv.bind(("127.0.0.1", 0))
        srv.listen(16)
        yield int(srv.getsockname()[1])


@pytest.fixture
def http_port() -> Iterator[int]:
    """A port that answers any bytes with an HTTP 400, as uvicorn (heliotwin's own port)."""
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(16)
    srv.settimeout(0.2)
    stop = threading.Event()

    def serve() -> None:
        while not stop.is_set():
            try:
                conn, _ = srv.accept()
            except OSError:
                continue
            with conn:
                conn.settimeout(2)
                try:
                    conn.recv(4096)
                    conn.sendall(b"HTTP/1.1 400 Bad Request\r\ncontent-type: text/plain\r\n"
                                 b"content-length: 11\r\n\r\nBad Request")
                except OSError:
                    pass

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    try:
        yield int(srv.getsockname()[1])
    finally:
        stop.set()
        thread.join(5)
        srv.close()


@pytest.mark.timeout(60)
def test_a_port_that_never_answers_is_no_scheduler(silent_port: int,
                                                   monkeypatch: pytest.MonkeyPatch,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """The Dask dashboard's port accepts the connection and never answers Dask's handshake,
    which distributed's connect timeout does not bound: the sweep waited for ever (a
    tester's finding). It fails within the connect timeout, as an address where nothing
    listens, suggesting the scheduler's port."""
    from backend.plants import sweep as sweep_mod

    monkeypatch.setattr(sweep_mod, "CONNECT_TIMEOUT", "1s")
    started = time.monotonic()
    with pytest.raises(SystemExit) as exc:
        raise SystemExit(main([*SWEEP, "--gcr", "0.2,0.3", "--scheduler",
                               f"tcp://127.0.0.1:{silent_port}"]))
    assert time.monotonic() - started < 15
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert f"--scheduler: cannot reach 'tcp://127.0.0.1:{silent_port}'" in err
    assert "not a Dask scheduler" in err and "8786" in err and len(err.splitlines()) == 1


@pytest.mark.timeout(60)
def test_an_http_port_is_no_scheduler(http_port: int, capsys: pytest.CaptureFixture[str]
                                      ) -> None:
    """An HTTP answer was read as a Dask frame's length (numpy's "Unable to allocate 3.07
    EiB" as a traceback): one error line instead."""
    with pytest.raises(SystemExit) as exc:
        raise SystemExit(main([*SWEEP, "--gcr", "0.2,0.3", "--scheduler",
                               f"tcp://127.0.0.1:{http_port}"]))
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert f"--scheduler: cannot reach 'tcp://127.0.0.1:{http_port}': it answered, but not " \
           "as a Dask scheduler" in err and len(err.splitlines()) == 1


def test_a_port_out_of_range_is_said(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        raise SystemExit(main([*SWEEP, "--gcr", "0.2,0.3", "--scheduler",
                               "tcp://127.0.0.1:99999"]))
    assert exc.value.code == 2
    assert "--scheduler: 'tcp://127.0.0.1:99999': port 99999 is out of range (1 to 65535)" \
        in capsys.readouterr().err


@pytest.mark.timeout(60)
def test_the_service_cancels_a_sweep_still_connecting_and_names_its_setting(
        silent_port: int, http_port: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """The service's sweep on a port that never answers: DELETE ends it while it connects
    (it stayed "running" and the queue filled behind it), and one on a port that is no
    scheduler fails naming HELIOTWIN_PLANTS_DASK_SCHEDULER."""
    import asyncio

    import pandas as pd

    from backend.plants import sweep as sweep_mod
    from backend.plants import sweep_runner

    monkeypatch.setattr(sweep_mod, "CONNECT_TIMEOUT", "30s")
    spec, cases = sweep_mod.prepare_sweep(
        layouts=["square"], gcr=[0.2, 0.3], strategies=["sun"],
        start=pd.Timestamp("2021-12-20", tz="UTC"), end=pd.Timestamp("2021-12-21", tz="UTC"),
        step_s=3600.0, latitude_deg=38.3, longitude_deg=-5.3, collector_m=(12.0, 5.0))

    async def run(port: int, cancel: bool) -> tuple[str, str | None, float]:
        runner = sweep_runner.SweepRunner(f"tcp://127.0.0.1:{port}", 2)
        state = runner.submit(spec, cases, {})
        while state.status == "queued":
            await asyncio.sleep(0.05)
        started = time.monotonic()
        if cancel:
            await asyncio.sleep(0.5)
            runner.cancel(state.sweep_id)
        while state.status == "running":
            await asyncio.sleep(0.05)
        return state.status, state.error, time.monotonic() - started

    status, error, took = run_in_own_thread(run(silent_port, True))
    assert (status, error) == ("failed", "cancelled") and took < 5
    status, error, _ = run_in_own_thread(run(http_port, False))
    assert status == "failed" and error is not None
    assert error.startswith(f"HELIOTWIN_PLANTS_DASK_SCHEDULER: cannot reach "
                            f"'tcp://127.0.0.1:{http_port}': it answered, but not as a Dask")


@pytest.mark.timeout(180)
def test_a_worker_without_heliotwin_is_named(tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    """A worker whose environment lacks heliotwin failed the whole sweep with a bare
    ``ModuleNotFoundError`` and no worker named (a tester's finding): it is refused at
    connection, by its address, saying to install heliotwin on the workers."""
    first, address = _start_scheduler(tmp_path)
    common = ["--nthreads", "1", "--no-nanny", "--host", "127.0.0.1", "--no-dashboard"]
    procs = [first]
    bad = tmp_path / "bad.log"
    blocked = ("import sys; sys.modules['backend'] = sys.modules['sim'] = None; "
               "from distributed.cli.dask_worker import main; main()")
    procs += [subprocess.Popen([str(BIN / "dask"), "worker", address, *common],
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL),
              subprocess.Popen([sys.executable, "-c", blocked, address, *common],
                               cwd=tmp_path, stdout=subprocess.DEVNULL,
                               stderr=bad.open("w"))]
    try:
        from distributed import Client

        with Client(address, timeout="60s") as client:
            client.wait_for_workers(2, timeout=120)
            workers = client.scheduler_info(n_workers=-1)["workers"]
            bad_worker = next(w for w in workers if w in bad.read_text())  # its log says
        with pytest.raises(SystemExit) as exc:
            raise SystemExit(main([*SWEEP, "--gcr", "0.2,0.3", "--scheduler", address]))
        assert exc.value.code == 2
        err = capsys.readouterr().err
        assert len(err.splitlines()) == 1, err
        assert f"1 of 2 workers of {address} cannot import heliotwin's code ({bad_worker}: " \
               "ModuleNotFoundError" in err
        assert "install heliotwin in the workers' environment" in err
    finally:
        for p in procs:
            p.kill()
        for p in procs:
            p.wait(20)


def test_a_cancelled_sweep_keeps_the_cases_it_finished(scheduler: str) -> None:
    """Cancelled after its first result: the cases done come with the cancellation (they
    were thrown away: a tester's finding), the rest are not run."""
    import pandas as pd

    from backend.plants import sweep as sweep_mod

    spec, cases = sweep_mod.prepare_sweep(
        layouts=["square", "diagonal"], gcr=[0.2, 0.25, 0.3], strategies=["sun"],
        start=pd.Timestamp("2021-12-20", tz="UTC"), end=pd.Timestamp("2021-12-21", tz="UTC"),
        step_s=1800.0, latitude_deg=38.3, longitude_deg=-5.3, collector_m=(12.0, 5.0))
    done = [0]

    def progress(n: int, total: int) -> None:
        done[0] = n

    with pytest.raises(sweep_mod.SweepCancelled) as stopped:
        sweep_mod.run_sweep(spec, cases, scheduler=scheduler, progress=progress,
                            cancelled=lambda: done[0] >= 1)
    result = stopped.value.result
    assert result is not None and 1 <= result["cases"] < len(cases)
    assert len(result["rows"]) == result["cases"] and result["rows"][0]["energy_kwh_per_collector"]


def test_a_scheduler_without_workers_fails_the_sweep(monkeypatch: pytest.MonkeyPatch,
                                                     capsys: pytest.CaptureFixture[str],
                                                     tmp_path: Path) -> None:
    """Every worker gone (killed, or never started): the tasks would wait for one for ever
    and the service showed the sweep "running"; after NO_WORKERS_S it fails, saying so."""
    import pandas as pd

    from backend.plants import sweep as sweep_mod

    proc, address = _start_scheduler(tmp_path)
    try:
        monkeypatch.setattr(sweep_mod, "NO_WORKERS_S", 1.0)
        monkeypatch.setattr(sweep_mod, "WORKERS_LOOK_S", 0.5)
        monkeypatch.setattr(sweep_mod, "CONNECT_TIMEOUT", "30s")
        spec, cases = sweep_mod.prepare_sweep(
            layouts=["square"], gcr=[0.2, 0.3], strategies=["sun"],
            start=pd.Timestamp("2021-12-20", tz="UTC"), end=pd.Timestamp("2021-12-21", tz="UTC"),
            step_s=3600.0, latitude_deg=38.3, longitude_deg=-5.3, collector_m=(12.0, 5.0))
        with pytest.raises(RuntimeError, match="has had no worker for 1 s"):
            sweep_mod.run_sweep(spec, cases, scheduler=address)
        # the CLI says it in its one error line (it printed an 18-line traceback), exit 1
        with pytest.raises(SystemExit) as exc:
            raise SystemExit(main([*SWEEP, "--gcr", "0.2,0.3", "--scheduler", address]))
        assert exc.value.code == 1
        err = capsys.readouterr().err.strip()
        assert err.startswith("heliotwin plant sweep: error: the Dask scheduler at ") and \
            "has had no worker for 1 s" in err and len(err.splitlines()) == 1, err
    finally:
        proc.kill()
        proc.wait(20)


@pytest.mark.timeout(180)
def test_a_lost_scheduler_keeps_the_cases_it_finished(capsys: pytest.CaptureFixture[str],
                                                      tmp_path: Path) -> None:
    """The scheduler killed after the first result: Dask cancels every future
    ("scheduler-connection-lost") and the finished cases were thrown away with a raw
    FuturesCancelledError (a tester's finding). They are kept, as a cancelled sweep's, and
    the message says what happened; the CLI prints them and the error line, exit 1."""
    first, address = _start_scheduler(tmp_path)
    procs = [first,
             subprocess.Popen([str(BIN / "dask"), "worker", address, "--nthreads", "1",
                               "--no-nanny", "--host", "127.0.0.1", "--no-dashboard"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        from distributed import Client

        from backend.plants import sweep as sweep_mod

        with Client(address, timeout="60s") as client:
            client.wait_for_workers(1, timeout=120)
        real_run = sweep_mod.run_sweep

        def run_and_lose(*args: Any, **kwargs: Any) -> dict[str, Any]:
            def progress(done: int, total: int) -> None:
                if procs[0].poll() is None:
                    procs[0].kill()
            return real_run(*args, **{**kwargs, "progress": progress})

        sweep_mod.run_sweep = run_and_lose   # the CLI imports it at its call
        try:
            with pytest.raises(SystemExit) as exc:
                raise SystemExit(main(["plant", "sweep", "--collector-m", "12x5", "--lat", "38.3",
                                       "--lon", "-5.3", "--start", "2021-01-01", "--end",
                                       "2021-07-01", "--step-s", "600", "--no-progress",
                                       "--gcr", "0.2,0.25,0.3,0.35", "--json",
                                       "--scheduler", address]))
        finally:
            sweep_mod.run_sweep = real_run
        assert exc.value.code == 1
        captured = capsys.readouterr()
        out = json.loads(captured.out)
        assert 1 <= out["cases"] < 4 and len(out["rows"]) == out["cases"]
        assert out["rows"][0]["energy_kwh_per_collector"] > 0
        err = captured.err.strip()
        assert len(err.splitlines()) == 1, err
        assert err.endswith(f"error: the scheduler at {address} was lost after "
                            f"{out['cases']} of 4 cases")
    finally:
        for p in procs:
            p.kill()
        for p in procs:
            p.wait(20)


def test_runner_close_cancels_a_running_sweep(monkeypatch: pytest.MonkeyPatch) -> None:
    """The service's shutdown (``SweepRunner.close``, from the app's lifespan) stops a
    running sweep through its ``cancelled`` callback (where run_sweep closes the cluster it
    made) and fails the queued one, instead of leaving them to outlive the service."""
    import asyncio
    import threading

    from backend.plants import sweep_runner
    from backend.plants.sweep import SweepCancelled

    polled = threading.Event()

    def fake_run_sweep(spec: Any, cases: Any, scheduler: Any = None, progress: Any = None,
                       cancelled: Any = None) -> dict[str, Any]:
        while not cancelled():           # a case that would take minutes
            polled.set()
            time.sleep(0.01)
        raise SweepCancelled("cancelled after 0 of 1 cases")

    monkeypatch.setattr(sweep_runner, "run_sweep", fake_run_sweep)

    async def main() -> tuple[str, str | None, str, str | None]:
        runner = sweep_runner.SweepRunner(None, 2)
        spec, case = cast(SweepSpec, None), cast(SweepCase, None)   # the fake never reads them
        running = runner.submit(spec, [case], {})
        queued = runner.submit(spec, [case], {})
        while not polled.is_set():
            await asyncio.sleep(0.01)
        await runner.close(timeout_s=20)
        return running.status, running.error, queued.status, queued.error

    assert run_in_own_thread(main()) == ("failed", "cancelled", "failed", "cancelled")


def test_the_local_clusters_workers_keep_glibc_malloc_and_slow_dask_monitors() -> None:
    """The sweep's own LocalCluster starts its workers without Dask's
    MALLOC_TRIM_THRESHOLD_ (set, it also fixes glibc's mmap threshold, and the bench's cases
    ran 1.5x slower); Dask's other worker settings (one BLAS thread) stay. Nor do they run
    the dashboard's monitors at their rates (the profiler, the 20 ms tick; the memory check
    every second)."""
    import os

    import dask
    from distributed import Client

    from backend.plants.sweep import local_cluster

    with local_cluster(1) as cluster, Client(cluster) as client:
        env = client.run(lambda: {k: os.environ.get(k) for k in
                                  ("MALLOC_TRIM_THRESHOLD_", "OMP_NUM_THREADS")})
        monitors = client.run(lambda: [dask.config.get(f"distributed.{k}") for k in (
            "worker.profile.enabled", "admin.tick.interval", "admin.system-monitor.interval",
            "worker.memory.monitor-interval")])
    assert list(env.values()) == [{"MALLOC_TRIM_THRESHOLD_": None, "OMP_NUM_THREADS": "1"}]
    assert list(monitors.values()) == [[False, "1s", "5s", "1s"]]


def test_the_text_table_says_n_a_for_an_undefined_fraction() -> None:
    """A fraction without a denominator (no daylight, no beam) is None in the rows; the
    text output printed ``None`` where docs/plants.md says ``n/a``."""
    from backend.cli.plant import sweep_cell

    assert [sweep_cell(v) for v in (None, 0.0, 4.94, "square")] == ["n/a", "0.0", "4.94",
                                                                     "square"]


def test_a_scheduler_given_as_host_and_port_is_tcp(scheduler: str,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """``--scheduler 127.0.0.1:PORT``, the form Dask's own ``Client`` takes, runs on that
    cluster (it was refused as 'no Dask scheduler address', a tester's finding)."""
    bare = scheduler.removeprefix("tcp://")
    code = main([*SWEEP, "--layouts", "square", "--gcr", "0.25", "--scheduler", bare, "--json"])
    assert code == 0, capsys.readouterr().err
    out = json.loads(capsys.readouterr().out)
    assert out["engine"] == "dask" and out["scheduler"] == scheduler and out["cases"] == 1


@pytest.mark.parametrize(("field", "text", "parsed"), [
    ("collector_m", "12x5", (12.0, 5.0)),
    ("collector_m", "8 x 4", (8.0, 4.0)),      # the HTTP body refused it, the CLI ran it
    ("collector_m", "8X4.5", (8.0, 4.5)),
    ("collector_m", "8*4", None),
    ("collector_m", "1e1x5", None),           # float() read these on the CLI alone
    ("collector_m", "8_0x4", None),
    ("collector_m", "infx5", None),
    ("collector_m", "12x", None),
    ("field_size", "5 x 5", (5.0, 5.0)),
    ("field_size", "5.5x5", None),            # the CLI ran a 5 x 5 field (int(5.5))
    ("field_size", "100x5", None),
])
def test_a_size_is_read_by_one_rule_on_the_cli_and_over_http(
        field: str, text: str, parsed: tuple[float, float] | None) -> None:
    """``collector_m``/``field_size``: the HTTP body's pattern and the CLI's ``parse_size``
    accept and refuse the same texts."""
    from pydantic import ValidationError

    from backend.api.schemas.plants import SweepCreate
    from backend.plants.sweep import SweepInputError, parse_size

    body = {"gcr": [0.2], "start": "2021-06-01", "end": "2021-06-02", field: text}
    if parsed is None:
        with pytest.raises(SweepInputError, match=f"expected .*, got {re.escape(repr(text))}"):
            parse_size(text, field)
        with pytest.raises(ValidationError, match=field):
            SweepCreate(**body)
    else:
        assert parse_size(text, field) == parsed
        assert getattr(SweepCreate(**body), field) == text


@pytest.mark.parametrize("fmt", ["--json", "--csv"])
def test_ctrl_c_prints_the_cases_finished_and_exits_130(fmt: str) -> None:
    """Ctrl-C at the terminal (SIGINT to the whole process group, the LocalCluster's workers
    too) exited 130 with nothing printed: the cases finished are printed in the format
    asked, stderr says after how many of how many it stopped, and no worker's traceback."""
    import os
    import signal

    cmd = [str(BIN / "heliotwin"), "--verbose", "plant", "sweep", "--collector-m", "12x5",
           "--lat", "38.3", "--lon", "-5.3", "--gcr", "0.05:0.35:0.05", "--start",
           "2021-01-01", "--end", "2022-01-01", "--step-s", "60", "--workers", "1", fmt]
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         start_new_session=True)
    try:
        assert p.stderr is not None
        lines = []
        for line in p.stderr:      # its cluster up, the cases submitted (a year each at 1 min)
            lines.append(line)
            if "plant sweep: 7 cases on" in line:
                break
        os.killpg(p.pid, signal.SIGINT)
        out, err = p.communicate(timeout=120)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
    err = "".join(lines) + err
    assert p.returncode == 130, err[-2000:]
    said = re.search(r"heliotwin plant sweep: interrupted after (\d) of 7 cases", err)
    assert said, err[-2000:]
    assert "Traceback" not in err, err[-3000:]
    done = int(said.group(1))
    if fmt == "--json":
        result = json.loads(out)
        assert result["cases"] == len(result["rows"]) == done
    else:
        lines = out.splitlines()
        assert lines[0].startswith("layout,gcr,strategy,") and len(lines) == 1 + done

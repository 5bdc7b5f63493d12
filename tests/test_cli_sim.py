"""``heliotwin sun`` and ``heliotwin simulate`` as a user runs them (subprocess)."""

import csv
import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def heliotwin(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "backend", *args],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=60,
    )


def test_sun_reproduces_nrel_spa_reference() -> None:
    # Reda & Andreas (2004), Appendix A.5 (../shared/reference/spa_reference.json)
    p = heliotwin(
        "sun",
        "--lat",
        "39.742476",
        "--lon",
        "-105.1786",
        "--time",
        "2003-10-17T12:30:30-07:00",
        "--elevation-m",
        "1830.14",
        "--pressure-hpa",
        "820",
        "--temperature-c",
        "11",
        "--delta-t-s",
        "67",
        "--json",
    )
    assert p.returncode == 0, p.stderr
    d = json.loads(p.stdout)
    assert abs(d["apparent_zenith_deg"] - 50.11162) <= 1e-4
    assert abs(d["azimuth_deg"] - 194.34024) <= 1e-4
    assert d["elevation_deg"] == pytest.approx(90 - d["zenith_deg"])
    assert d["apparent_elevation_deg"] == pytest.approx(90 - d["apparent_zenith_deg"])


def test_sun_duffie_beckman_and_naive_time() -> None:
    p = heliotwin(
        "sun",
        "--lat",
        "16.28875",
        "--lon",
        "-95.240871",
        "--time",
        "2024-03-15T12:00:00-06:00",
        "--method",
        "duffie-beckman",
        "--json",
    )
    assert p.returncode == 0, p.stderr
    assert json.loads(p.stdout)["method"] == "duffie-beckman"
    p = heliotwin("sun", "--lat", "16", "--lon", "-95", "--time", "2024-03-15T12:00:00", "--json")
    assert p.returncode == 2 and "offset" in p.stderr


def test_simulate_one_day_json_and_csv(tmp_path) -> None:
    out = tmp_path / "day.csv"
    p = heliotwin(
        "simulate",
        "--site",
        "tehuantepec",
        "--start",
        "2024-03-15",
        "--end",
        "2024-03-16",
        "--json",
        "--csv",
        str(out),
    )
    assert p.returncode == 0, p.stderr
    d = json.loads(p.stdout)
    for key in (
        "site_id",
        "start",
        "end",
        "step_s",
        "tracker_energy_wh",
        "fixed_energy_wh",
        "gain_pct",
        "tracker_peak_w",
        "fixed_peak_w",
    ):
        assert key in d
    assert d["start"] == "2024-03-15T00:00:00-06:00"  # bare date = local midnight
    assert d["tracker_energy_wh"] > d["fixed_energy_wh"] > 0
    rows = list(csv.DictReader(out.open()))
    assert len(rows) == 1440
    assert rows[0]["ts"] == "2024-03-15T06:00:00+00:00"
    assert sum(float(r["tracker_power_w"]) for r in rows) / 60 == pytest.approx(
        d["tracker_energy_wh"], rel=1e-4
    )
    assert "\r" not in p.stderr  # no progress bar when stderr is not a terminal


@pytest.mark.parametrize(
    "args, message",
    [
        (["--site", "atlantis", "--start", "2024-03-15", "--end", "2024-03-16"], "unknown site"),
        (["--start", "2024-03-16", "--end", "2024-03-15"], "must be after"),
        (["--start", "2024-02-30", "--end", "2024-03-15"], "--start"),
        (["--start", "2024-03-15T00:00", "--end", "2024-03-16"], "offset"),
        (["--start", "2024-03-15", "--end", "2024-03-16", "--controller", "pid"], "ideal"),
    ],
)
def test_simulate_errors_exit_2(args, message) -> None:
    p = heliotwin("simulate", *args, "--json")
    assert p.returncode == 2
    assert message in p.stderr and p.stdout == ""


def test_progress_bar_only_on_a_terminal() -> None:
    import fcntl
    import os
    import pty
    import struct
    import termios

    master, slave = pty.openpty()
    # a terminal 24 rows x 80 columns (a fresh pty has width 0, where tqdm draws nothing)
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 80, 0, 0))
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "backend",
            "simulate",
            "--start",
            "2024-01-01",
            "--end",
            "2024-03-01",
        ],
        stdout=subprocess.PIPE,
        stderr=slave,
        cwd=ROOT,
    )
    os.close(slave)
    seen = b""
    while True:
        try:
            chunk = os.read(master, 4096)
        except OSError:  # EIO: the child closed the terminal
            break
        if not chunk:
            break
        seen += chunk
    out, _ = proc.communicate(timeout=60)
    os.close(master)
    assert proc.returncode == 0
    assert b"simulating" in seen and b"%" in seen
    assert b"gain" in out

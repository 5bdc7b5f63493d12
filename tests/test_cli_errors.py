"""The CLI's one error path: a subcommand calls ``backend.cli.fail``; ``main`` alone prints
``heliotwin <command>: error: <message>`` to stderr (nothing on stdout) and returns the code.

In process (``main(argv)``): the error path is the dispatcher's, not a process's.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import pytest

from backend import cli


@pytest.mark.parametrize("argv,line", [
    (["sun", "--lat", "100", "--lon", "0", "--time", "2025-01-01T12:00:00+00:00"],
     "heliotwin sun: error: --lat 100.0: latitude must be within [-90, 90] deg"),
    (["dynamics", "check", "--dt-s", "0"],
     "heliotwin dynamics check: error: --dt-s 0.0: must be in (0, 0.05] s"),
    (["plant", "simulate", "--plant", "penarroya", "--start", "2025-01-02", "--end",
      "2025-01-01"], "heliotwin plant simulate: error: --end (2025-01-01) must be after"),
    (["plant", "list", "--plants-dir", "/no/such/folder"],  # listed nothing, exit 0
     "heliotwin plant list: error: --plants-dir: plants folder '/no/such/folder' does not "
     "exist"),
    (["demo-logger", "--site", "no-such-site", "--token", "t"],
     "heliotwin demo-logger: error: "),
    # a tester's findings: each named something else than the flag and its problem
    (["simulate", "--start", "2024-03-15", "--end", "2024-03-16", "--controller",
      "open_loop_spa", "--pedestal-yaw-deg", "nan"],
     "heliotwin simulate: error: --pedestal-yaw-deg: nan is not a finite number"),
    (["simulate", "--start", "2024-03-15", "--end", "2024-03-16", "--controller",
      "open_loop_model", "--pointing-model-terms", "[]"],
     "heliotwin simulate: error: --pointing-model-terms: '[]' is not a JSON object"),
    # a user's `curl …/pointing-model > model.json` of a range without offsets: it read
    # "detail: not a pointing-model term"
    (["simulate", "--start", "2024-03-15", "--end", "2024-03-16", "--controller",
      "open_loop_model", "--pointing-model-terms", '{"detail": "0 observations with sun '
      'offsets in the range; the fit needs at least 10"}'],
     "heliotwin simulate: error: --pointing-model-terms: the service's refusal, not a "
     "pointing model: 0 observations with sun offsets in the range"),
    # a tester's finding: the ideal controller ignored them while the summary echoed them
    (["simulate", "--start", "2024-03-15", "--end", "2024-03-16", "--backlash-deg", "1"],
     "heliotwin simulate: error: --backlash-deg: the ideal controller feels no disturbance"),
    (["plant", "sweep", "--collector-m", "12x5", "--lat", "38.3", "--lon", "-5.3", "--gcr",
      "0.2", "--start", "2021-06-01", "--end", "2021-06-02", "--field", "5"],
     "heliotwin plant sweep: error: --field: expected ROWSxCOLUMNS like 5x5, got '5'"),
    (["plant", "sweep", "--collector-polygon", "0,0;1,nan;1,1", "--lat", "38.3", "--lon",
      "-5.3", "--gcr", "0.2", "--start", "2021-06-01", "--end", "2021-06-02"],
     "heliotwin plant sweep: error: --collector-polygon: "),
    # a tester's finding: a 12-hour step read a month +58 %, a day's 0 Wh (the twin's bound)
    (["plant", "sweep", "--collector-m", "12x5", "--lat", "-33.9", "--lon", "18.4", "--gcr",
      "0.2", "--start", "2021-06-01", "--end", "2021-07-01", "--step-s", "43200"],
     "heliotwin plant sweep: error: --step-s: 43200 s is longer than an hour (3600 s)"),
    # a plant's sweep takes the plant's ground, field, layout and altitude: the flags were
    # accepted and ignored (rows byte for byte the same; a tester's finding)
    *[(["plant", "sweep", "--plant", "penarroya", "--gcr", "0.1", "--start", "2021-12-21",
        "--end", "2021-12-22", *flag], f"heliotwin plant sweep: error: {flag[0]}: the plant "
       f"(--plant) sets the place, the collector, the layout, the field and its ground: give "
       f"--plant or {flag[0]}, not both")
      for flag in (["--slope-tilt-deg", "10"], ["--slope-azimuth-deg", "180"],
                   ["--layouts", "hexagonal_e_w"], ["--field", "3x3"], ["--altitude-m", "0"],
                   ["--rotation-deg", "30"], ["--lat", "38"])],
    (["plant", "simulate", "--plant", "penarroya", "--start", "2021-06-01", "--end",
      "2021-06-03", "--step-s", "86400"],
     "heliotwin plant simulate: error: --step-s: 86400 s is longer than an hour (3600 s)"),
])
def test_a_refusal_is_one_error_line_on_stderr_and_exit_2(
        argv: list[str], line: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(argv) == 2
    out, err = capsys.readouterr()
    assert out == ""
    assert err.startswith(line) and err.count("\n") == 1, err


@pytest.mark.parametrize("name,value,line", [
    ("HELIOTWIN_ENERGY_MAX_GAP_S", "3601",
     "HELIOTWIN_ENERGY_MAX_GAP_S=3601: Input should be less than or equal to 3600"),
    # a group's own prefix is the variable's (it said HELIOTWIN_HISTORY_DAYS)
    ("HELIOTWIN_TWIN_HISTORY_DAYS", "-5",
     "HELIOTWIN_TWIN_HISTORY_DAYS=-5: Input should be greater than or equal to 0"),
    # a URL may hold a password: not printed
    ("HELIOTWIN_DATABASE_URL", "postgresql+psycopg://u:s3cret@h:notaport/db",
     "HELIOTWIN_DATABASE_URL (value not shown): "),
])
def test_serve_names_a_bad_setting_in_one_line(name: str, value: str, line: str,
                                               monkeypatch: pytest.MonkeyPatch,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    """A bad environment value stops ``serve`` with the variable, its value and the
    problem (it printed pydantic's traceback)."""
    monkeypatch.setenv(name, value)
    assert cli.main(["serve", "--no-demo"]) == 2
    out, err = capsys.readouterr()
    assert err.startswith(f"heliotwin serve: error: {line}") and err.count("\n") == 1, err
    assert "s3cret" not in err


def test_serve_names_a_malformed_site_file_in_one_line(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """docs/sites.md's malformed ``my-roof.json`` in the sites folder stopped ``serve``'s
    start-up with a 40-frame traceback (exit 3); now one line naming its fields, exit 2."""
    (tmp_path / "my-roof.json").write_text(
        '{"site_id": "my-roof", "latitude_deg": 91, "longitude_deg": -79.95, '
        '"timezone": "America/New_York", "arrays": {"tracker": {"mount": "tracker"}, '
        '"fixed": {"mount": "fixed", "tilt": 36}}}')
    for name, value in {"HELIOTWIN_SITES_DIR": str(tmp_path), "HELIOTWIN_PORT": "0",
                        "HELIOTWIN_VISER": "false",
                        "HELIOTWIN_DATABASE_URL": f"sqlite:///{tmp_path / 's.sqlite'}"}.items():
        monkeypatch.setenv(name, value)
    monkeypatch.delenv("HELIOTWIN_MQTT_URL", raising=False)
    assert cli.main(["serve", "--no-demo"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("heliotwin serve: error: HELIOTWIN_SITES_DIR: ") and \
        err.count("\n") == 1, err
    assert "latitude_deg: Input should be less than or equal to 90" in err
    assert "arrays.fixed.tilt: unknown key" in err


def test_fail_carries_its_exit_code(monkeypatch: pytest.MonkeyPatch,
                                    capsys: pytest.CaptureFixture[str]) -> None:
    import backend.cli.sun

    def refuse(args: argparse.Namespace) -> int:
        cli.fail("--url: the service does not answer", code=1)

    monkeypatch.setattr(backend.cli.sun, "run", refuse)  # registered by the next main()
    assert cli.main(["sun", "--lat", "0", "--lon", "0", "--time",
                     "2025-01-01T12:00:00+00:00"]) == 1
    assert capsys.readouterr() == ("", "heliotwin sun: error: --url: the service does not "
                                       "answer\n")

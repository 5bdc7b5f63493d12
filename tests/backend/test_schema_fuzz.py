"""Schema fuzzing: schemathesis against the service's own OpenAPI, over real HTTP.

Every operation of ``/openapi.json`` gets its documented examples and
``HELIOTWIN_FUZZ_EXAMPLES`` generated requests (default 5 here in ``make test``;
``make fuzz`` runs 300 and schemathesis' coverage phase, ``HELIOTWIN_FUZZ_COVERAGE=1``),
once without a token and (the operations that write) once with the site's write
token. Checked on each answer: no 5xx, the status code is documented, the content
type and the body match the documented response schema, and a request the schema
forbids is not accepted (2xx).

The service runs as ``heliotwin serve`` on a throw-away SQLite file; bodies the
fuzzer sends are real requests (a generated simulation really runs, within the
service's own limits).
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
import schemathesis
from hypothesis import HealthCheck, Phase, settings
from live_service import ServerProcess
from schemathesis.checks import not_a_server_error
from schemathesis.config import SchemathesisConfig
from schemathesis.specs.openapi.checks import (
    content_type_conformance,
    negative_data_rejection,
    response_schema_conformance,
    status_code_conformance,
)

#: schemathesis' cases of one operation share a node id: xdist would run one of them
pytestmark = pytest.mark.one_process

EXAMPLES = int(os.environ.get("HELIOTWIN_FUZZ_EXAMPLES", "5"))
#: schemathesis' coverage phase (boundary values of every field: hundreds of requests per
#: operation, each valid simulation a real run) only in the long run, ``make fuzz``
COVERAGE = os.environ.get("HELIOTWIN_FUZZ_COVERAGE") == "1"
CHECKS = [not_a_server_error, status_code_conformance, content_type_conformance,
          response_schema_conformance, negative_data_rejection]


@pytest.fixture(scope="module")
def fuzz_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[ServerProcess]:
    tmp: Path = tmp_path_factory.mktemp("fuzz")
    server = ServerProcess(f"sqlite:///{tmp / 'fuzz.sqlite'}", tmp / "server.log",
                           extra_env={"HELIOTWIN_VISER": "true"}).start()
    try:
        yield server
    finally:
        server.stop()


@pytest.fixture(scope="module")
def fuzz_token(fuzz_server: ServerProcess) -> str:
    return fuzz_server.token()


def _openapi() -> dict:
    """The OpenAPI document the service serves, built in-process at collection time
    (schemathesis' lazy fixture loader does not run under pytest 9);
    :func:`test_the_fuzzed_schema_is_the_servers` checks it is the live one."""
    from backend.app import create_app
    from backend.settings import Settings

    return create_app(Settings(database_url="sqlite://", viser=False, live_twin=False,
                               demo_logger=False)).openapi()


OPENAPI = _openapi()
schema = schemathesis.openapi.from_dict(OPENAPI, config=SchemathesisConfig.from_dict(
    {"phases": {"coverage": {"enabled": COVERAGE}}}))
# no shrinking: a failure is reported with the request that found it (curl), at once
FUZZ = settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=list(HealthCheck),
                phases=[Phase.explicit, Phase.reuse, Phase.generate])


@pytest.mark.slow
@schema.parametrize()
@FUZZ
def test_no_token(case: schemathesis.Case, fuzz_server: ServerProcess) -> None:
    case.call_and_validate(base_url=fuzz_server.base_url, checks=CHECKS, timeout=120)


@pytest.mark.slow
@schema.include(method=["POST", "PUT", "DELETE"]).parametrize()
@FUZZ
def test_with_token(case: schemathesis.Case, fuzz_server: ServerProcess,
                    fuzz_token: str) -> None:
    case.call_and_validate(base_url=fuzz_server.base_url, checks=CHECKS, timeout=120,
                           headers={"Authorization": f"Bearer {fuzz_token}"})


def test_the_fuzzed_schema_is_the_servers(fuzz_server: ServerProcess) -> None:
    assert httpx.get(f"{fuzz_server.base_url}/openapi.json").json() == OPENAPI

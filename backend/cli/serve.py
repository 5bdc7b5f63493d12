"""``heliotwin serve``: the API and dashboard, the 3D twin, the live twin loop, the demo logger."""

from __future__ import annotations

import argparse
import gc
import logging
from typing import Any

from backend.cli import fail

logger = logging.getLogger(__name__)


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add the ``serve`` subcommand."""
    p = subparsers.add_parser(
        "serve", help="run the service (API + dashboard, 3D twin, live twin, demo logger)",
        description="Run the service. Settings come from HELIOTWIN_* environment variables "
                    "(see the README); the flags below override them.",
    )
    p.add_argument("--host", default=None, help="interface (default 127.0.0.1)")
    p.add_argument("--port", type=int, default=None, help="API/dashboard port (default 8000)")
    p.add_argument("--viser-port", type=int, default=None, help="3D twin port (default 8080)")
    p.add_argument("--no-demo", action="store_true", help="do not run the demo field logger")
    p.add_argument("--forwarded-allow-ips", default=None, metavar="IPS",
                   help="addresses of the reverse proxies whose X-Forwarded-For/-Proto are "
                        "trusted, comma-separated, or '*' (default: $FORWARDED_ALLOW_IPS, else "
                        "127.0.0.1,::1, uvicorn's); the client address the anonymous "
                        "allowances are counted by is then the one the proxy forwards")
    p.set_defaults(func=run)


def _check_database(settings: Any) -> None:
    """Refuse a database a newer heliotwin migrated before uvicorn starts
    (``SchemaTooNewError``, one line by :func:`backend.cli.main`): the app's lifespan would
    refuse it too, but uvicorn prints that under a 90-line traceback and exits 3."""
    from backend.storage.engine import check_schema, make_engine

    engine = make_engine(settings)
    try:
        check_schema(engine)
    finally:
        engine.dispose()


def run(args: argparse.Namespace) -> int:
    """Start uvicorn with :func:`backend.app.create_app` until interrupted."""
    import uvicorn
    from pydantic import ValidationError

    from backend.api.security import viser_listen_port, viser_public_port
    from backend.app import create_app
    from backend.limits import tune_malloc
    from backend.settings import get_settings, settings_error_text
    from sim.sites import list_sites

    # before any thread starts: two glibc heaps and large arrays unmapped when freed, so
    # an idle server gives back what its big requests used (backend/limits.py)
    tune_malloc()

    overrides: dict[str, object] = {}
    if args.host is not None:
        overrides["host"] = args.host
    if args.port is not None:
        overrides["port"] = args.port
    if args.viser_port is not None:
        overrides["viser_port"] = args.viser_port
    if args.no_demo:
        overrides["demo_logger"] = False
    try:
        settings = get_settings(**overrides)
    except ValidationError as exc:
        fail(settings_error_text(exc))
    try:  # a malformed site file stopped the start-up with a 40-frame traceback
        list_sites(settings.sites.user_dir)
    except ValueError as exc:
        fail(f"HELIOTWIN_SITES_DIR: {exc}")
    server = settings.server
    _check_database(settings)

    def banner(app: Any) -> None:
        """Said once the 3D scene started: the port it took (the next free one when the
        configured one was busy), not the one asked for."""
        if not server.viser:
            twin3d = "no 3D twin (HELIOTWIN_VISER=false)"
        elif getattr(app.state, "scene", None) is None:
            twin3d = "no 3D twin (it did not start: see the log)"
        else:
            port, public = viser_listen_port(app), viser_public_port(app)
            twin3d = f"3D twin on :{port}"
            if port != server.viser_port:
                twin3d += f" (:{server.viser_port} was busy)"
            if public != port:
                twin3d += f", framed by the dashboard at :{public}"
        print(f"heliotwin: dashboard and API on http://{server.host}:{server.port}/ "
              f"(OpenAPI at /docs), {twin3d}", flush=True)

    app = create_app(settings, on_started=banner)
    # The ~200,000 objects of the libraries loaded by now live as long as the process:
    # moved out of the collector's reach, a full collection (~80-140 ms with the event
    # loop stopped) no longer walks them. 200 loggers at a reading a second each: p99 385
    # ms against a p50 of 2.6 ms without this, 10.7 ms with it (benchmarks/RESULTS.md,
    # "service"). Only here, in the served process: the tests' in-process apps come and go.
    gc.collect()
    gc.freeze()
    uvicorn.run(
        app, host=server.host, port=server.port, loop="uvloop", http="httptools",
        access_log=server.access_log, log_level="info", timeout_graceful_shutdown=10,
        # None: uvicorn reads FORWARDED_ALLOW_IPS, else trusts 127.0.0.1 and ::1
        forwarded_allow_ips=args.forwarded_allow_ips,
    )
    return 0

"""The FastAPI application: routers and the lifespan that owns every background part.

``create_app(settings)`` includes the API routers (health/meta, sites,
measurements, energy, simulations, vision) and, last, the dashboard (its ``/``
must never shadow the API), and the middlewares: gzip for answers of 2 KiB or
more and, ahead of it, ``backend.api.strict.StrictBodies`` (request encodings and
repeated JSON keys; logger ingest reads its own body after checking its token).
The lifespan:

1. runs the migrations, loads the built-in sites, starts the writer
   (:func:`backend.context.open_context`);
2. starts the 3D scene (``backend.twin.scene.TwinScene``) when enabled;
3. starts the live twin loop (an asyncio task, every minute);
4. starts the demo logger thread when enabled (making its own token if none is
   configured);
5. gives freed heap memory back to the system every ``TRIM_INTERVAL_S``
   (:func:`backend.limits.release_memory`: after big requests glibc keeps the pages);
6. owns the plant sweeps' runner (``app.state.sweeps``, made on first use): on
   shutdown its sweeps are cancelled and its Dask cluster closed;

Outermost of all, ``backend.api.security.SecurityHeaders`` adds the CSP and
the other security headers to every response; ``/docs`` is served from local
assets (``security.add_docs``) and the OpenAPI document declares the Bearer
scheme (``security.declare_bearer``).

On shutdown the lifespan stops them in reverse order, the writer last, so everything
acknowledged is committed before the process exits.
"""

from __future__ import annotations

import asyncio
import logging
import threading
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from typing import Any

import anyio
import orjson
from fastapi import Depends, FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import Response
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.middleware.gzip import GZipMiddleware

from backend.api import security, strict
from backend.api.deps import read_token
from backend.api.routes import (
    alerts,
    dashboard,
    diagnosis,
    energy,
    health,
    measurements,
    plants,
    pointing_model,
    simulations,
    sites,
    tokens,
    twin3d,
    vision,
    weather,
)
from backend.context import ServiceContext, open_context
from backend.errors import InputError, bounded_detail, bounded_errors
from backend.limits import TRIM_INTERVAL_S, release_memory
from backend.settings import Settings, get_settings
from backend.twin import viser_http
from backend.twin.scene import TwinScene
from sim.plant import load_plant

logger = logging.getLogger(__name__)


def _start_scene(ctx: ServiceContext) -> TwinScene | None:
    s = ctx.settings
    info = ctx.registry.get(s.sites.default_site)
    if not s.server.viser or info is None:
        return None
    try:
        def site_of(site_id: str) -> Any:  # each viewer shows the site the dashboard selects
            found = ctx.registry.get(site_id)
            return None if found is None else found.site

        viser_http.install()  # same-origin WebSockets, security headers on the page
        scene = TwinScene(info.site, s.server.host, s.server.viser_port, sites=site_of,
                          plants=lambda plant_id: load_plant(plant_id, s.sites.plants_dir))
        scene.start()
    except OSError as exc:  # a port taken, a host not of this machine: said in one line
        logger.error("3D scene did not start on %s:%s: %s", s.server.host, s.server.viser_port,
                     exc)
        return None
    except Exception:  # the service runs without its 3D view rather than not at all
        logger.exception("3D scene did not start")
        return None
    return scene


def _demo_base_url(settings: Settings) -> str:
    host = "127.0.0.1" if settings.server.host in ("0.0.0.0", "::", "") else settings.server.host
    return f"http://{host}:{settings.server.port}"


def _start_demo(ctx: ServiceContext, stop: threading.Event) -> threading.Thread | None:
    s = ctx.settings
    info = ctx.registry.get(s.sites.default_site)
    if not s.demo.enabled or info is None:
        return None
    from backend.twin.demo_logger import DemoLogger, demo_token

    token = s.demo.token.get_secret_value() if s.demo.token else ctx.writer.call(
        lambda conn: demo_token(conn, s.sites.default_site)).result()
    demo = DemoLogger(info.site, _demo_base_url(s), token)

    def run() -> None:
        try:
            demo.run(stop, backfill_days=s.demo.backfill_days)
        except Exception:
            logger.exception("demo logger stopped")
        finally:
            demo.close()

    thread = threading.Thread(target=run, name="heliotwin-demo-logger", daemon=True)
    thread.start()
    return thread


async def _trim_memory(stop: asyncio.Event) -> None:
    """Every ``TRIM_INTERVAL_S`` until ``stop``: :func:`release_memory` on a worker thread
    (it takes ≈ 4 ms; the heap is locked meanwhile, the event loop is not)."""
    while not stop.is_set():
        try:
            await asyncio.wait_for(stop.wait(), TRIM_INTERVAL_S)
        except TimeoutError:
            await anyio.to_thread.run_sync(release_memory)


async def validation_error(request: Request, exc: RequestValidationError) -> Response:
    """FastAPI's 422 body, bounded and JSON-safe (:func:`backend.errors.bounded_errors`):
    no input (NaN, an integer beyond 64 bits, a megabyte string) makes it fail or grow."""
    body = orjson.dumps({"detail": bounded_errors(exc.errors())})
    return Response(body, status_code=422, media_type="application/json")


async def input_error(request: Request, exc: InputError) -> Response:
    """A service function's :class:`backend.errors.InputError` → its 4xx with ``detail``."""
    body = orjson.dumps({"detail": bounded_detail(exc.detail)})
    return Response(body, status_code=exc.status_code, media_type="application/json")


def create_app(settings: Settings | None = None,
               on_started: Callable[[FastAPI], None] | None = None) -> FastAPI:
    """Build the application (nothing starts until the lifespan runs); ``on_started(app)``
    runs once its start-up is done (the 3D scene on the port it really took:
    ``heliotwin serve`` prints its banner then)."""
    settings = settings or get_settings()

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        ctx = await anyio.to_thread.run_sync(open_context, settings)
        app.state.ctx = ctx
        scene = await anyio.to_thread.run_sync(_start_scene, ctx)
        ctx.twin.scene = scene
        app.state.scene = scene
        stop_live = asyncio.Event()
        live_task = None
        if settings.twin.live:
            live_task = asyncio.create_task(
                ctx.twin.run_live(stop_live, settings.twin.live_interval_s), name="live-twin")
        stop_demo = threading.Event()
        demo_thread = _start_demo(ctx, stop_demo)
        trim_task = asyncio.create_task(_trim_memory(stop_live), name="trim-memory")
        if on_started is not None:
            on_started(app)
        try:
            yield
        finally:
            stop_demo.set()
            stop_live.set()
            await trim_task
            sweeps = getattr(app.state, "sweeps", None)
            if sweeps is not None:
                await sweeps.close()
            if live_task is not None:
                await live_task
            if demo_thread is not None:
                await anyio.to_thread.run_sync(demo_thread.join, 10.0)
            if scene is not None:
                await anyio.to_thread.run_sync(scene.stop)
            await anyio.to_thread.run_sync(ctx.close)
            logger.info("service stopped")

    app = FastAPI(
        title="heliotwin",
        summary="Digital twin and field dashboard for dual-axis solar trackers",
        version=health.service_version(),
        lifespan=lifespan,
        docs_url=None,  # served from local assets by security.add_docs
        redoc_url=None,
        # HELIOTWIN_READ_REQUIRE_TOKEN: the one check of who may read (deps.read_token)
        dependencies=[Depends(read_token)],
    )
    app.state.settings = settings
    app.add_exception_handler(RequestValidationError, validation_error)  # type: ignore[arg-type]
    app.add_exception_handler(InputError, input_error)  # type: ignore[arg-type]
    app.add_exception_handler(StarletteHTTPException, strict.http_error)  # type: ignore[arg-type]
    # the last middleware added runs first; gzip leaves responses that already carry a
    # Content-Encoding (the dashboard's Plotly) alone.
    # Level 5: a year downsampled to 2,000 points (480 kB of JSON) packs to 106 kB in
    # 9 ms; level 9 (Starlette's default) saves 6 kB more for 25 ms.
    app.add_middleware(GZipMiddleware, minimum_size=2048, compresslevel=5)
    # first of all: Content-Encoding, repeated keys (ingest checks its token, then its body)
    app.add_middleware(strict.StrictBodies, own_body=measurements.INGEST_PATH)
    # HEAD routed as GET (FastAPI's routes take only the methods they declare)
    app.add_middleware(strict.HeadAsGet)
    # outermost: CSP, X-Frame-Options, nosniff, Referrer-Policy on every response
    app.add_middleware(security.SecurityHeaders, viser_port=settings.server.viser_port)
    security.add_docs(app, settings.server.viser_public_port or settings.server.viser_port)
    # ingest first: a request is matched against the routers in this order, and logger
    # ingest is the busiest request of the service (one match instead of ~12)
    for module in (measurements, health, sites, energy, diagnosis, alerts, simulations, weather,
                   twin3d, plants, vision, tokens, dashboard, pointing_model):
        app.include_router(module.router)
    generate_openapi = app.openapi

    def openapi() -> dict[str, Any]:
        if app.openapi_schema is None:
            app.openapi_schema = security.declare_bearer(strict.document_errors(
                generate_openapi()))
        return app.openapi_schema

    app.openapi = openapi  # type: ignore[method-assign]
    return app

"""``heliotwin demo-logger``: a field logger that posts realistic minute readings over HTTP."""

from __future__ import annotations

import argparse
import signal
import threading

from backend.cli import TOKEN_ENV, add_token_argument, fail, site_or_fail


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add the ``demo-logger`` subcommand."""
    p = subparsers.add_parser(
        "demo-logger", help="post realistic minute readings to a running service",
        description="Act as a field logger: the twin's expectation plus clouds, noise and "
                    "dropouts, posted every minute (and optionally back-filled).",
    )
    p.add_argument("--site", default="tehuantepec", help="site id (default tehuantepec)")
    p.add_argument("--url", default="http://127.0.0.1:8000", help="service base URL")
    add_token_argument(p, "required")
    p.add_argument("--backfill-days", type=float, default=0.0,
                   help="post the last N days first (default 0)")
    p.add_argument("--once", action="store_true", help="back-fill and exit")
    p.add_argument("--seed", type=int, default=0, help="seed of clouds and noise")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run until interrupted (or, with ``--once``, until the back-fill is posted)."""
    from backend.settings import get_settings
    from backend.twin.demo_logger import DemoLogger, TokenRefused
    from sim.twin import has_twin_arrays

    if not args.token:
        fail(f"--token: the site's write token is required (or set {TOKEN_ENV})")
    site = site_or_fail(args.site, get_settings().sites.user_dir)
    if not has_twin_arrays({name: a.mount for name, a in site.arrays.items()}):
        # the demo logger posts what the twin makes (a tester's string-level site crashed
        # with a traceback and exit 0)
        fail(f"--site: {site.site_id!r} has arrays {', '.join(site.arrays)}; the demo logger "
             "posts the twin's readings and needs arrays 'tracker' and 'fixed' (mounts "
             "tracker and fixed)")
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    demo = DemoLogger(site, args.url, args.token, seed=args.seed)
    try:
        if args.once:
            if not demo.wait_until_up(stop):
                fail(f"{args.url} does not answer /healthz", code=1)
            try:
                accepted, duplicates = demo.backfill(args.backfill_days)
            except TokenRefused as exc:
                fail(f"--token: the service refuses it ({exc})", code=1)
            print(f"posted: {accepted} accepted, {duplicates} duplicates")
            return 0
        ran = demo.run(stop, backfill_days=args.backfill_days)
    except KeyboardInterrupt:
        stop.set()
        ran = True
    finally:
        demo.close()
    print(f"demo logger stopped; {demo.posted} readings accepted")
    if not ran:  # the reason is logged above (no service at --url, or --token refused)
        fail(f"could not post to {args.url}: see the line above", code=1)
    return 0

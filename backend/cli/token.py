"""``heliotwin token create --site ID``: a new write token for a site's field loggers.

The token is printed once, alone on the last line; only its SHA-256 is stored.
"""

from __future__ import annotations

import argparse
import sys


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add the ``token`` subcommand."""
    p = subparsers.add_parser("token", help="manage write tokens of field loggers")
    sub = p.add_subparsers(dest="token_command", metavar="ACTION", required=True)
    c = sub.add_parser("create", help="make a new write token for a site (printed once)")
    c.add_argument("--site", required=True, help="site id, e.g. tehuantepec")
    c.add_argument("--label", default="", help="a note to recognise the token by")
    c.set_defaults(func=create)


def create(args: argparse.Namespace) -> int:
    """Migrate if needed, load the built-in sites, store and print a new token."""
    from backend.auth import UnknownSite, create_token
    from backend.settings import get_settings
    from backend.sites import Registry, sync_sites
    from backend.storage.engine import make_engine, run_migrations

    settings = get_settings()
    engine = make_engine(settings)
    try:
        run_migrations(engine)
        registry = Registry.load_files(settings.sites_dir)
        with engine.begin() as conn:
            sync_sites(conn, [info.site for info in registry.sites.values()])
            token = create_token(conn, args.site, args.label)
    except UnknownSite as exc:
        print(f"heliotwin token: {exc}", file=sys.stderr)
        return 2
    finally:
        engine.dispose()
    print(f"write token for site {args.site} (shown once; send it as "
          "'Authorization: Bearer <token>'):")
    print(token)
    return 0

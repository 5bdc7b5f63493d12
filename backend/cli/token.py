"""``heliotwin token create|list|revoke``: the write tokens of a site's field loggers.

- ``create --site ID [--scope ingest|site] [--label TEXT] [--expires-in-days N |
  --expires ISO]`` prints the new token once, alone on the last line; only its SHA-256
  is stored. ``ingest`` (default): a field device, writes readings only; ``site``: also
  edits the site, its calibrations and the shared 3D replay, and acknowledges its alerts
  (``backend/auth.py``).
- ``list [--site ID] [--json]`` shows every token's id, site, scope, prefix, label,
  times and status (``active``, ``expired``, ``revoked``) — never the token.
- ``revoke TOKEN_OR_ID`` revokes by the id ``list`` shows or by the token itself; a
  running service refuses it within ``HELIOTWIN_TOKEN_CACHE_TTL_S`` (≤ 1 s).

Each command is one ``BEGIN IMMEDIATE`` transaction on SQLite, retried while the
database stays locked (:func:`backend.cli.db.with_db`), so it works while loggers write.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import sys

from backend.cli import fail
from backend.cli.db import with_db


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add the ``token`` subcommand."""
    p = subparsers.add_parser("token", help="manage write tokens of field loggers")
    sub = p.add_subparsers(dest="token_command", metavar="ACTION", required=True)
    c = sub.add_parser("create", help="make a new write token for a site (printed once)")
    c.add_argument("--site", required=True, help="site id, e.g. tehuantepec")
    c.add_argument("--label", default="", help="a note to recognise the token by")
    c.add_argument("--scope", default="ingest", metavar="ingest|site",
                   help="ingest: a field device, writes readings only (default); site: "
                        "also edits the site, its calibrations and the shared 3D replay, "
                        "and acknowledges its alerts")
    exp = c.add_mutually_exclusive_group()
    exp.add_argument("--expires-in-days", type=float, metavar="DAYS",
                     help="refused after this many days (default: never expires)")
    exp.add_argument("--expires", metavar="ISO",
                     help="refused from this instant (ISO 8601 with offset)")
    c.set_defaults(func=create)
    ls = sub.add_parser("list", help="show the tokens (ids, sites, status; never the tokens)")
    ls.add_argument("--site", help="only this site's tokens")
    ls.add_argument("--json", action="store_true", help="print JSON")
    ls.set_defaults(func=list_)
    r = sub.add_parser("revoke", help="revoke a token (by the id `list` shows, or the token)")
    r.add_argument("token_or_id", metavar="TOKEN_OR_ID")
    r.set_defaults(func=revoke)


def _expiry(args: argparse.Namespace) -> dt.datetime | None:
    from backend.timestamps import parse_instant

    if args.expires_in_days is not None:
        if not 0 < args.expires_in_days <= 36_600:
            raise ValueError(f"--expires-in-days: {args.expires_in_days} is not in (0, 36600]")
        return dt.datetime.now(dt.UTC) + dt.timedelta(days=args.expires_in_days)
    if args.expires is not None:
        t = parse_instant(args.expires, "--expires")
        if t <= dt.datetime.now(dt.UTC):
            raise ValueError(f"--expires: {args.expires} is in the past")
        return t
    return None


def create(args: argparse.Namespace) -> int:
    """Store and print a new token."""
    from backend.auth import UnknownSite, check_scope, create_token

    try:
        check_scope(args.scope)
        expires = _expiry(args)
        token = with_db(lambda conn: create_token(conn, args.site, args.label, expires,
                                                   args.scope), args.site)
    except UnknownSite as exc:
        fail(f"--site: {exc}")
    except ValueError as exc:
        fail(str(exc))
    until = "" if expires is None else f", valid until {expires.isoformat()}"
    # the sentence on stderr, the token alone on stdout: TOKEN=$(heliotwin token create …)
    print(f"{args.scope} token for site {args.site} (shown once{until}; send it as "
          "'Authorization: Bearer <token>'):", file=sys.stderr)
    print(token)
    return 0


def list_(args: argparse.Namespace) -> int:
    """Print the stored tokens, as a table or JSON."""
    from backend.auth import UnknownSite, list_tokens

    try:
        rows = [t.to_dict() for t in with_db(lambda conn: list_tokens(conn, args.site),
                                             args.site, configured=False)]
    except UnknownSite as exc:
        fail(f"--site: {exc}")
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    cols = ("id", "site_id", "scope", "token_prefix", "status", "created_at", "expires_at",
            "label")
    table = [[str(r[c] if r[c] is not None else "-") for c in cols] for r in rows]
    widths = [max([len(c), *(len(row[i]) for row in table)]) for i, c in enumerate(cols)]
    for row in [list(cols), *table]:
        print("  ".join(v.ljust(w) for v, w in zip(row, widths, strict=True)).rstrip())
    return 0


def revoke(args: argparse.Namespace) -> int:
    """Revoke one token; exit 2 when none matches."""
    from backend.auth import UnknownToken, revoke_token

    try:
        info, _ = with_db(lambda conn: revoke_token(conn, args.token_or_id))
    except UnknownToken as exc:
        fail(str(exc))
    assert info.revoked_at is not None
    print(f"revoked token {info.id} ({info.token_prefix}…, site {info.site_id}) at "
          f"{info.revoked_at.isoformat()}")
    return 0

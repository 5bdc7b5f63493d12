"""The ``heliotwin`` command line: one dispatcher, one module per subcommand.

Each subcommand module in this package defines ``register(subparsers)``, which
adds its parser and sets ``func`` (called with the parsed ``argparse.Namespace``
and returning an exit code). Output to stdout is the CLI's job; everything else
logs.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys

# Subcommand modules, in the order `heliotwin --help` lists them.
SUBCOMMAND_MODULES = (
    "backend.cli.sun",
    "backend.cli.simulate",
    "backend.cli.serve",
    "backend.cli.token",
    "backend.cli.demo_logger",
    "backend.cli.vision",
    "backend.cli.dynamics",
    "backend.cli.plant",
)


def build_parser() -> argparse.ArgumentParser:
    """Build the top-level parser with every subcommand that is installed."""
    parser = argparse.ArgumentParser(
        prog="heliotwin",
        description="Digital twin and field dashboard for dual-axis solar trackers.",
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="log at DEBUG level")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in SUBCOMMAND_MODULES:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name == name:  # subcommand not written yet / not shipped
                continue
            raise
        module.register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``heliotwin`` console script."""
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
        stream=sys.stderr,
    )
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())

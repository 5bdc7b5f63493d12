"""The ``heliotwin`` command line: one dispatcher, one module per subcommand.

Each subcommand module in this package defines ``register(subparsers)``, which
adds its parser and sets ``func`` (called with the parsed ``argparse.Namespace``
and returning an exit code). Output to stdout is the CLI's job; everything else
logs, to stderr: at INFO for the long-running commands (:data:`SERVICE_COMMANDS`,
whose log is their output), at WARNING for the one-shot ones (``token create``
prints its token and nothing about migrations), at DEBUG with ``-v``.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
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
    "backend.cli.site",
)

#: Commands that run until stopped and report what they do by logging at INFO.
SERVICE_COMMANDS = frozenset({"serve", "demo-logger"})


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
    quiet = logging.INFO if args.command in SERVICE_COMMANDS else logging.WARNING
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else quiet,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
        stream=sys.stderr,
    )
    try:
        code = int(args.func(args) or 0)
        sys.stdout.flush()  # a closed pipe shows here, not at interpreter exit
        return code
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:
        return _stdout_closed()


def _stdout_closed() -> int:
    """The reader of stdout went away (``heliotwin simulate … | head``): no traceback; stdout
    goes to /dev/null so the interpreter's final flush is quiet; 141 = 128 + SIGPIPE, as a
    command killed by the signal."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
    os.close(devnull)
    return 141


if __name__ == "__main__":
    sys.exit(main())

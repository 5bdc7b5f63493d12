"""The ``heliotwin`` command line: one dispatcher, one module per subcommand.

Each subcommand module in this package defines ``register(subparsers)``, which
adds its parser and sets ``func`` (called with the parsed ``argparse.Namespace``
and returning an exit code). Output to stdout is the CLI's job; everything else
logs, to stderr: at INFO for the long-running commands (:data:`SERVICE_COMMANDS`,
whose log is their output), at WARNING for the one-shot ones (``token create``
prints its token and nothing about migrations), at DEBUG with ``-v``.

A subcommand that refuses (bad input, nothing to act on) calls :func:`fail` (or
raises :class:`CliError`) from anywhere below its ``func``; :func:`main` alone prints
``heliotwin <command>: error: <message>`` to stderr — argparse's own form — and
exits with the error's code (2 by default, as argparse's usage errors). A
:class:`backend.errors.SetupError` (a database a newer heliotwin migrated) is printed the
same way, exit 1: its message says what to do, a traceback only hid it.
"""

from __future__ import annotations

import argparse
import gc
import importlib
import logging
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING, NoReturn

if TYPE_CHECKING:
    from sim.sites import Site

from backend.errors import SetupError

# Subcommand modules, in the order `heliotwin --help` lists them.
SUBCOMMAND_MODULES = (
    "backend.cli.sun",
    "backend.cli.simulate",
    "backend.cli.serve",
    "backend.cli.token",
    "backend.cli.demo_logger",
    "backend.cli.readings",
    "backend.cli.vision",
    "backend.cli.dynamics",
    "backend.cli.plant",
    "backend.cli.site",
)

#: Commands that run until stopped and report what they do by logging at INFO.
SERVICE_COMMANDS = frozenset({"serve", "demo-logger"})


class CliError(Exception):
    """A subcommand's refusal: ``message`` for stderr, ``code`` the exit status (2: bad input)."""

    def __init__(self, message: str, code: int = 2) -> None:
        super().__init__(message)
        self.code = code


#: The environment variable a command posting to the service takes its write token from
#: when ``--token`` is not given: a token on the command line is visible to every user of
#: the machine in ``ps`` and stays in the shell's history.
TOKEN_ENV = "HELIOTWIN_TOKEN"


def add_token_argument(parser: argparse.ArgumentParser, needed: str) -> None:
    """``--token``, by default :data:`TOKEN_ENV`'s value; ``needed`` says when it must be
    there (the command checks, so ``--help`` and a dry run need none)."""
    parser.add_argument("--token", default=os.environ.get(TOKEN_ENV) or None,
                        help=f"the site's write token, {needed}; default ${TOKEN_ENV} "
                             "(which keeps it out of ps and the shell's history)")


def fail(message: str, code: int = 2) -> NoReturn:
    """Stop the subcommand: :func:`main` prints ``message`` as its error and exits ``code``."""
    raise CliError(message, code)


def site_or_fail(site_id: str, sites_dir: str | Path | None, flag: str = "--site") -> Site:
    """The site a command names, else its refusal ``FLAG: why``: an unknown id, or a file
    that does not validate (every bad field named, as ``site validate`` says it)."""
    from sim.sites import load_site

    try:
        return load_site(site_id, sites_dir)
    except ValueError as exc:  # UnknownSiteError, or the file's problems
        fail(f"{flag}: {exc}")


def _tag_commands(parser: argparse.ArgumentParser) -> None:
    """Set ``cli_prog`` (e.g. ``heliotwin plant simulate``) on every subcommand's parser, for
    :func:`main`'s error line; a nested subcommand's default overrides its parent's."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                sub.set_defaults(cli_prog=sub.prog)
                _tag_commands(sub)


class _OneLineParser(argparse.ArgumentParser):
    """argparse's parser whose usage errors are one line, as the subcommands' own errors
    (:func:`fail`): a bad ``--time`` printed the whole usage block first (a tester's
    finding); ``--help`` still shows it."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (--help for usage)\n")


def build_parser() -> argparse.ArgumentParser:
    """Build the top-level parser with every subcommand that is installed (their parsers
    are of the top-level parser's class)."""
    parser = _OneLineParser(
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
    _tag_commands(parser)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``heliotwin`` console script.

    Without ``argv`` it runs this process's own command (the console script, ``python -m
    backend``) and freezes the objects alive when it returns (``gc.freeze``): the
    interpreter's exit then does not walk the objects of numpy, pandas, scipy and pvlib for
    cycles, 0.2–0.3 s of CPU measured (they are still freed by reference counting). Tests
    pass ``argv``: their collector keeps collecting.
    """
    try:
        return _run(argv)
    finally:
        if argv is None:
            gc.freeze()


def _run(argv: list[str] | None) -> int:
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
    except CliError as exc:
        print(f"{getattr(args, 'cli_prog', parser.prog)}: error: {exc}", file=sys.stderr)
        return exc.code
    except SetupError as exc:
        print(f"{getattr(args, 'cli_prog', parser.prog)}: error: {exc}", file=sys.stderr)
        return 1
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

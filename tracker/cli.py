"""``tracker`` command line: one module per command, each with ``register(subparsers)``.

``main(argv) -> int`` never raises for expected failures: it prints one line on
stderr and returns the contract's exit code (2 bad input, 1 anything else).
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys
from typing import NoReturn

from tracker import __version__
from tracker.errors import TrackerError

# Modules that add a command; each defines register(subparsers).
COMMAND_MODULES = (
    "tracker.cli_run",
    "tracker.cli_synth",
    "tracker.cli_evaluate",
    "tracker.recording.cli",
    "plc.cli",
    "tracker.calibrate.cli",
)


class _Parser(argparse.ArgumentParser):
    """Usage errors are one line (contract: exit 2 with a one-line reason), with where to look."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="tracker", description="Poses of parts on a conveyor belt from one fixed camera."
    )
    parser.add_argument("--version", action="version", version=f"belt-tracker {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="log debug details")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    return parser


def setup_logging(verbose: bool) -> None:
    logging.basicConfig(
        level=logging.DEBUG if verbose else logging.INFO,
        format="tracker: %(message)s",
        stream=sys.stderr,
        force=True,
    )
    # pymodbus logs every retry itself; the PLC writer logs state changes once instead.
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse: --help (0) or a usage error (2)
        return int(exc.code or 0)
    setup_logging(args.verbose)
    if args.command is None:
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except TrackerError as exc:
        print(f"tracker: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print("tracker: interrupted", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())

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

# Every command: the module that adds it (``register(subparsers)``) and its line in
# ``tracker --help``. Only the module of the command given is imported: the others pull in
# OpenCV, numpy, pymodbus or protobuf, which ``tracker --help`` and ``tracker plc map`` do
# not need (tests/test_startup.py checks both the import graph and that these lines match
# what each module registers).
COMMANDS: dict[str, tuple[str, str]] = {
    "run": ("tracker.cli_run", "track parts (no arguments: the bundled demo)"),
    "synth": ("tracker.cli_synth", "render a synthetic scene (frames, calibration, ground truth)"),
    "evaluate": ("tracker.cli_evaluate", "compare a pose stream with ground truth (from tracker synth)"),
    "replay": ("tracker.recording.cli", "re-run the pipeline on a recording (--check: compare with the live poses)"),
    "plc-sim": ("plc.cli", "stand-in PLC: a Modbus TCP server holding the register map"),
    "plc": ("plc.cli", "PLC helpers (plc map: the register map)"),
    "calibrate": ("tracker.calibrate.cli", "camera intrinsics and the belt pose from chessboard views"),
}
ALL = "*"


class _Parser(argparse.ArgumentParser):
    """Usage errors are one line (contract: exit 2 with a one-line reason), with where to look."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


def command_in(argv: list[str]) -> str | None:
    """The command named in ``argv`` (the first word that is not an option), if any."""
    for word in argv:
        if not word.startswith("-"):
            return word if word in COMMANDS else None
    return None


def build_parser(command: str | None = ALL) -> argparse.ArgumentParser:
    """The parser with every command listed; ``command`` (ALL: every one) gets its real sub-parser,
    the others a stand-in that only shows their line in ``tracker --help``."""
    parser = _Parser(
        prog="tracker", description="Poses of parts on a conveyor belt from one fixed camera."
    )
    parser.add_argument("--version", action="version", version=f"belt-tracker {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="log debug details")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    wanted = COMMANDS[command][0] if command in COMMANDS else None
    for name, (module, help_text) in COMMANDS.items():
        if name in sub.choices:
            continue  # added by an earlier command's module
        if command == ALL or module == wanted:
            importlib.import_module(module).register(sub)
        else:
            sub.add_parser(name, help=help_text, add_help=False)
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
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(command_in(argv))
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

"""Start-up: ``tracker --help`` and ``tracker plc map`` import only what they use (the import graph, not the
time, is asserted; bench/bench.py measures the time)."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

from tracker.cli import ALL, COMMANDS, build_parser, main

ROOT = Path(__file__).resolve().parent.parent
HEAVY = ("cv2", "numpy", "scipy", "filterpy", "pymodbus", "mcap", "google.protobuf", "zstandard")


def _modules_after(argv: list[str]) -> set[str]:
    """Top-level packages imported by a fresh interpreter that ran ``tracker ARGV``."""
    code = ("import contextlib, io, json, sys\nfrom tracker.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):\n"
            f"    code = main({argv!r})\n"
            "print(json.dumps([code, sorted(sys.modules)]))")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    code, modules = json.loads(proc.stdout.strip().splitlines()[-1])
    assert code == 0
    return set(modules)


def _loaded(modules: set[str], package: str) -> bool:
    return any(m == package or m.startswith(package + ".") for m in modules)


@pytest.mark.parametrize("argv", [["--help"], ["--version"]])
def test_help_imports_nothing_heavy(argv):
    modules = _modules_after(argv)
    assert [p for p in HEAVY if _loaded(modules, p)] == []


def test_plc_map_imports_no_vision_and_no_recording():
    modules = _modules_after(["plc", "map"])
    assert [p for p in ("cv2", "numpy", "scipy", "filterpy", "mcap", "google.protobuf") if _loaded(modules, p)] == []


def test_every_command_line_in_help_matches_its_module():
    parser = build_parser(ALL)
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    assert {a.dest: a.help for a in sub._choices_actions} == {name: h for name, (_, h) in COMMANDS.items()}


@pytest.mark.parametrize("command,option", [("run", "--record"), ("replay", "--check"), ("synth", "--force"),
                                            ("plc", "map"), ("plc-sim", "--port"), ("calibrate", "intrinsics"),
                                            ("evaluate", "--json")])
def test_each_command_gets_its_real_parser(command, option, capsys):
    assert main([command, "--help"]) == 0
    assert option in capsys.readouterr().out

"""The README's Usage block lists every command and every option that `--help` has."""

from __future__ import annotations

import argparse
import re

from conftest import ROOT

from tracker.cli import build_parser


def _usage_entries() -> dict[str, str]:
    """README Usage block: {'run': 'tracker run [--source SRC] ...', 'calibrate belt': ...}."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    block = re.search(r"^## Usage\n+```\n(.*?)```", text, flags=re.S | re.M).group(1)
    entries, current = [], None
    for line in block.splitlines():
        if line.startswith("tracker "):
            current = [line]
            entries.append(current)
        elif line.strip() and current is not None:
            current.append(line)
    out = {}
    for lines in entries:
        tokens = " ".join(lines).split()[1:]
        parser, words = build_parser(), []
        while tokens and (sub := _subcommands(parser)) and tokens[0] in sub:
            parser = sub[tokens[0]]
            words.append(tokens.pop(0))
        out[" ".join(words)] = " ".join(lines)
    return out


def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _commands(parser: argparse.ArgumentParser, prefix: str = ""):
    sub = _subcommands(parser)
    if not sub and prefix:
        yield prefix, parser
    for name, child in sub.items():
        yield from _commands(child, f"{prefix} {name}".strip())


def test_readme_usage_lists_every_command_and_option():
    entries = _usage_entries()
    missing = []
    for name, parser in _commands(build_parser()):
        if name not in entries:
            missing.append(f"command 'tracker {name}'")
            continue
        for action in parser._actions:
            longs = [o for o in action.option_strings if o.startswith("--") and o != "--help"]
            if longs and not any(re.search(re.escape(o) + r"(?![\w-])", entries[name]) for o in longs):
                missing.append(f"tracker {name} {longs[0]}")
    assert not missing, f"README Usage lacks: {', '.join(missing)}"

"""The README's command list is the real command line: every line parses, every command is listed."""

from __future__ import annotations

import argparse
import re

from fleetlink.cli import build_parser
from tests.paths import ROOT


def _commands(parser: argparse.ArgumentParser, prefix: tuple[str, ...] = ()) -> set[tuple[str, ...]]:
    """Every command path of the parser: ("ros", "graph"), ("stack", "up") …"""
    found: set[tuple[str, ...]] = set()
    for action in parser._actions:  # argparse keeps its subcommands here
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                found.add((*prefix, name))
                found |= _commands(sub, (*prefix, name))
    return found


def _readme_commands() -> set[tuple[str, ...]]:
    text = (ROOT / "README.md").read_text()
    section = text[text.index("## The command line") :]
    block = re.search(r"```\n(.*?)```", section, re.DOTALL)
    assert block is not None
    listed: set[tuple[str, ...]] = set()
    for line in block.group(1).splitlines():
        words = line.split("#", 1)[0].split()
        assert words[0] == "fleetlink", line
        path: list[str] = []
        rest = words[1:]
        while rest and re.fullmatch(r"[a-z][a-z-]*", rest[0]):
            path.append(rest.pop(0))
        alternatives = [path[-1]] if path else []
        while len(rest) >= 2 and rest[0] == "|":
            alternatives.append(rest[1])
            rest = rest[2:]
        for alternative in alternatives:
            listed.add((*path[:-1], alternative))
            listed |= {tuple(path[: i + 1]) for i in range(len(path) - 1)}
    return listed


def test_every_readme_command_exists() -> None:
    real = _commands(build_parser())
    missing = sorted(_readme_commands() - real)
    assert not missing, f"README lists commands the parser does not have: {missing}"


def test_every_command_is_in_the_readme() -> None:
    real = {c for c in _commands(build_parser()) if len(c) <= 2}
    absent = sorted(real - _readme_commands())
    assert not absent, f"commands missing from the README's list: {absent}"

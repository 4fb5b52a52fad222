"""Every command in the docs' code blocks marked ``runnable`` runs and exits 0.

A block opened with ```` ```sh runnable ```` holds one command per line, run from the project
root with the project's ``fleetlink`` first on PATH.
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
BLOCK = re.compile(r"^```sh runnable\n(.*?)^```", re.MULTILINE | re.DOTALL)


def runnable_commands() -> list[tuple[str, str]]:
    found = []
    for doc in sorted([ROOT / "README.md", *(ROOT / "docs").rglob("*.md")]):
        for block in BLOCK.findall(doc.read_text()):
            for line in block.splitlines():
                command = line.split("  #", 1)[0].strip()
                if command:
                    found.append((str(doc.relative_to(ROOT)), command))
    return found


COMMANDS = runnable_commands()


def test_the_docs_have_runnable_commands() -> None:
    assert len(COMMANDS) >= 5


@pytest.mark.parametrize(("doc", "command"), COMMANDS, ids=[f"{d}: {c}" for d, c in COMMANDS])
def test_runnable_command(doc: str, command: str) -> None:
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}"}
    result = subprocess.run(
        shlex.split(command), cwd=ROOT, env=env, capture_output=True, text=True, timeout=120, check=False
    )
    assert result.returncode == 0, f"{doc}: `{command}` exited {result.returncode}:\n{result.stderr[-2000:]}"

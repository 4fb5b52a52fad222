"""The repository stands alone: nothing it holds points outside it or at one machine's folders."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

from tests.paths import BAGS, HUSKY, IROBOT, ROOT, TURTLEBOT3

pytestmark = pytest.mark.unit

# an absolute path into a machine's home or work folders
ABSOLUTE = re.compile(r"(?<![\w.])(/work/|/home/\w|/root/|/Users/\w|/tmp/\w+/\w)")
RELATIVE = re.compile(r"(?<![\w.])((?:\.\./)+[\w.-]*)")
TEXT_SUFFIXES = {
    ".py",
    ".md",
    ".yaml",
    ".yml",
    ".toml",
    ".json5",
    ".json",
    ".cfg",
    ".ini",
    ".sh",
    ".txt",
    ".service",
    ".html",
    ".js",
    ".css",
    "",
}


def tracked_text_files() -> list[str]:
    out = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True).stdout
    return [
        name
        for name in out.splitlines()
        if (ROOT / name).suffix in TEXT_SUFFIXES
        and (ROOT / name).is_file()
        and not (ROOT / name).is_symlink()
        and ROOT / name != Path(__file__)
    ]


def _inside(name: str, relative: str) -> bool:
    """Whether ``relative``, read from the folder of file ``name``, stays in the repository."""
    return (ROOT / name).parent.joinpath(relative).resolve().is_relative_to(ROOT)


def test_no_file_points_outside_the_repository() -> None:
    offenders = []
    for name in tracked_text_files():
        text = (ROOT / name).read_text(encoding="utf-8", errors="replace")
        for lineno, line in enumerate(text.splitlines(), 1):
            outside = [rel for rel in RELATIVE.findall(line) if not _inside(name, rel)]
            if ABSOLUTE.search(line) or outside:
                offenders.append(f"{name}:{lineno}: {line.strip()[:120]}")
    assert offenders == [], "paths outside the repository:\n" + "\n".join(offenders)


def test_the_recorded_data_is_in_the_repository_with_its_licences() -> None:
    for folder in (HUSKY, TURTLEBOT3):
        assert (folder / "metadata.yaml").is_file(), folder
        assert (folder / "SOURCE_LICENSE").read_text().count("BSD") or "Redistribution" in (
            folder / "SOURCE_LICENSE"
        ).read_text()
    assert (BAGS.parent / "README.md").is_file()
    assert (IROBOT / "LICENSE").is_file()
    assert len(list((IROBOT / "msg").glob("*.msg"))) == 19

"""Every repository file the docs name in backticks exists (``edge/runtime/sender.py``,
``tests/unit/wire/test_batches.py::test_x``), so a move or a removal shows up in the docs too.

A name counts as a file path when it has a '/' and ends in a source or config file extension;
paths on a target machine (``/var/lib/...``, ``~/...``) and templates (``<site>``, ``*``) do not.
It may be written from the repository's top or from the document's own folder, or be a file the
document itself writes (a code block marked ``file=PATH``).
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from tests.paths import DOCS, ROOT

pytestmark = pytest.mark.unit

_BACKTICKED = re.compile(r"`([^`\s]+)`")
_WRITTEN = re.compile(r"^```\S*\s+file=(\S+)", re.MULTILINE)
_FILE = re.compile(r"[\w.-]+(/[\w.-]+)+\.(py|md|ya?ml|json5?|toml|sh|html|css|js|msg|srv|avsc|txt|cfg|ini)")


def file_paths(text: str) -> list[tuple[int, str]]:
    """(line, path) of each backticked repository file path in a Markdown text."""
    found = []
    for number, line in enumerate(text.splitlines(), 1):
        for match in _BACKTICKED.finditer(line):
            path = match.group(1).split("::")[0]
            if _FILE.fullmatch(path):
                found.append((number, path))
    return found


def written(text: str) -> set[str]:
    """The files a document writes itself: its code blocks marked ``file=PATH``."""
    return set(_WRITTEN.findall(text))


def missing(doc: Path) -> list[str]:
    text = doc.read_text()
    return [
        f"{doc.relative_to(ROOT)}:{line}: {path}"
        for line, path in file_paths(text)
        if not (ROOT / path).exists() and not (doc.parent / path).exists() and path not in written(text)
    ]


def documents() -> list[Path]:
    return [ROOT / "README.md", *sorted(DOCS.rglob("*.md"))]


def test_docs_name_only_files_that_exist() -> None:
    named = [path for doc in documents() for _line, path in file_paths(doc.read_text())]
    assert len(named) > 50
    assert [problem for doc in documents() for problem in missing(doc)] == []


def test_what_counts_as_a_file_path() -> None:
    text = (
        "`edge/agent.py` and `tests/unit/wire/test_batches.py::test_x`, not `/var/lib/x.py`, "
        "`~/.cache/a.py`, `fleetlink/<site>/ingest`, `bench/bench_*.py`, `spool.max_bytes`, `a.py`\n"
        "`deploy/edge.example.yaml` `edge/gone.py`"
    )
    assert file_paths(text) == [
        (1, "edge/agent.py"),
        (1, "tests/unit/wire/test_batches.py"),
        (2, "deploy/edge.example.yaml"),
        (2, "edge/gone.py"),
    ]
    problems = [p for line, p in file_paths(text) if not (ROOT / p).exists()]
    assert problems == ["edge/gone.py"]


def test_a_file_the_document_writes_counts_as_there() -> None:
    text = "Save `var/x/made.yaml`:\n\n```yaml file=var/x/made.yaml\na: 1\n```\n"
    assert written(text) == {"var/x/made.yaml"}
    assert file_paths(text) == [(1, "var/x/made.yaml")]

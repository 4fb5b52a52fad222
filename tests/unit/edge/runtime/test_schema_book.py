"""The schema book: fingerprint -> schema JSON, durable, corrupt files skipped."""

from __future__ import annotations

from pathlib import Path

from fleetlink.edge.runtime.encoding import identity_of
from fleetlink.edge.runtime.schema_book import SchemaBook

SCHEMA_A = {"type": "record", "name": "A", "fields": [{"name": "x", "type": "long"}]}
SCHEMA_B = {"type": "record", "name": "B", "fields": [{"name": "y", "type": "string"}]}


def test_survives_a_restart(tmp_path: Path) -> None:
    a, b = identity_of(SCHEMA_A), identity_of(SCHEMA_B)
    book = SchemaBook(tmp_path / "schemas").load()
    book.add(a.fingerprint, a.json)
    book.add(a.fingerprint, a.json)
    book.add(b.fingerprint, b.json)
    assert sorted(p.name for p in (tmp_path / "schemas").iterdir()) == sorted(
        [f"{a.fingerprint.hex()}.json", f"{b.fingerprint.hex()}.json"]
    )
    again = SchemaBook(tmp_path / "schemas").load()
    found, missing = again.lookup([a.fingerprint, b.fingerprint, b"\x00" * 8])
    assert found == {a.fingerprint: a.json, b.fingerprint: b.json}
    assert missing == [b"\x00" * 8]
    assert len(again) == 2


def test_corrupt_or_misnamed_files_are_skipped(tmp_path: Path) -> None:
    a, b = identity_of(SCHEMA_A), identity_of(SCHEMA_B)
    folder = tmp_path / "schemas"
    folder.mkdir()
    (folder / f"{a.fingerprint.hex()}.json").write_text(b.json)  # content of another schema
    (folder / "nothex.json").write_text(a.json)
    (folder / f"{b.fingerprint.hex()}.json").write_text(b.json[:-3])  # torn
    book = SchemaBook(folder).load()
    assert len(book) == 0
    assert book.corrupt == 3


def test_in_memory_book_writes_nothing(tmp_path: Path) -> None:
    a = identity_of(SCHEMA_A)
    book = SchemaBook(None).load()
    book.add(a.fingerprint, a.json)
    assert a.fingerprint in book
    assert list(tmp_path.iterdir()) == []


def test_unwritable_directory_keeps_the_schema_in_memory(tmp_path: Path) -> None:
    a = identity_of(SCHEMA_A)
    folder = tmp_path / "schemas"
    book = SchemaBook(folder).load()
    folder.rmdir()
    (tmp_path / "schemas").write_text("a file where the folder was")
    book.add(a.fingerprint, a.json)
    assert a.fingerprint in book
    assert book.write_errors == 1

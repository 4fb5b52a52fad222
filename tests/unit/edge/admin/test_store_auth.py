"""The overlay file (atomic saves, clear errors), the service putting it back when a change cannot
be installed, and where the admin token comes from."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import pytest
from pydantic import SecretStr

from fleetlink.edge.admin.auth import ENV_TOKEN, ENV_TOKEN_FILE, authorized, load_token
from fleetlink.edge.admin.errors import InvalidChangeError, OverlayError, PersistError, TokenError
from fleetlink.edge.admin.overlay import Overlay, RobotTypeOverlay
from fleetlink.edge.admin.problems import document_path
from fleetlink.edge.admin.store import OverlayStore, default_overlay_path
from fleetlink.edge.config import EdgeConfig
from fleetlink.edge.errors import MappingError
from fleetlink.edge.mapping import MappingSpec, RobotTypeSpec
from tests.unit.edge.admin.world import world

OVERLAY = Overlay(
    robot_types={"kb": RobotTypeOverlay(match="/kb_*")},
    removed_robot_types=["old"],
    mappings=[
        {
            "name": "imu",
            "robot_type": "kb",
            "from": "/{robot}/imu",
            "to": "fleet.imu",
            "stages": [{"type": "throttle", "hz": 2.5}],
        }
    ],
    removed_mappings=["ir"],
)


def test_save_and_load(tmp_path: Path) -> None:
    store = OverlayStore(tmp_path / "state" / "admin-overlay.yaml")
    assert store.load() == Overlay()  # no file yet: nothing changed
    store.save(OVERLAY)
    assert store.load() == OVERLAY
    text = store.path.read_text()
    assert text.startswith("# Changes made through the fleetlink admin API")
    assert sorted(p.name for p in store.path.parent.iterdir()) == ["admin-overlay.yaml"]  # no temporary left


def test_default_place_is_next_to_the_spool(tmp_path: Path) -> None:
    assert default_overlay_path(tmp_path / "spool") == tmp_path / "admin-overlay.yaml"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("mappings: [", "not valid YAML"),
        ("version: 2\n", "version"),
        ("bogus: 1\n", "bogus: unknown key"),
        ("mappings:\n  - {from: /a}\n", "no mapping name"),
    ],
)
def test_broken_overlay_files(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "admin-overlay.yaml"
    path.write_text(text)
    with pytest.raises(OverlayError, match=message) as caught:
        OverlayStore(path).load()
    assert str(path) in str(caught.value)


def test_a_file_in_the_way_raises_persist_error(tmp_path: Path) -> None:
    (tmp_path / "blocker").write_text("a file, not a folder")
    with pytest.raises(PersistError, match="cannot save the admin overlay") as caught:
        OverlayStore(tmp_path / "blocker" / "admin-overlay.yaml").save(OVERLAY)
    assert caught.value.status == 503


class RefusingBackend:
    """Installs nothing: raises what the mapping table would."""

    def __init__(self, error: Exception) -> None:
        self.error = error

    def install(
        self, config: EdgeConfig, robot_types: Sequence[RobotTypeSpec], mappings: Sequence[MappingSpec]
    ) -> None:
        raise self.error


@pytest.mark.parametrize(
    ("error", "raised"),
    [
        (MappingError("robot type 'x' is declared twice"), InvalidChangeError),
        (RuntimeError("the agent is stopping"), RuntimeError),
    ],
)
def test_a_change_that_cannot_be_installed_leaves_the_saved_overlay_alone(
    tmp_path: Path, error: Exception, raised: type[Exception]
) -> None:
    path = tmp_path / "admin-overlay.yaml"
    w = world(path)
    w.service.add_mapping({"name": "imu", "from": "/{robot}/imu", "to": "fleet.imu"})
    saved = OverlayStore(path).load()
    refusing = RefusingBackend(error)
    w.backend.install = refusing.install  # type: ignore[method-assign]
    with pytest.raises(raised):
        w.service.remove_mapping("imu")
    assert OverlayStore(path).load() == saved
    assert w.service.overlay == saved
    assert [m.name for m in w.service.config.mappings] == ["battery", "imu"]


# -- the token ------------------------------------------------------------------------------------
def test_token_sources(tmp_path: Path) -> None:
    file = tmp_path / "token"
    file.write_text("  from-file\n")
    assert load_token({}) is None
    assert load_token({ENV_TOKEN: "  "}) is None
    token = load_token({ENV_TOKEN: "from-env"})
    assert token is not None
    assert token.get_secret_value() == "from-env"
    assert str(token) == "**********"  # never printed
    from_file = load_token({ENV_TOKEN: "from-env", ENV_TOKEN_FILE: str(file)})
    assert from_file is not None
    assert from_file.get_secret_value() == "from-file"
    explicit = load_token({}, file)
    assert explicit is not None
    assert explicit.get_secret_value() == "from-file"


@pytest.mark.parametrize("content", [None, ""])
def test_token_file_problems(tmp_path: Path, content: str | None) -> None:
    file = tmp_path / "token"
    if content is not None:
        file.write_text(content)
    with pytest.raises(TokenError, match=str(file)):
        load_token({ENV_TOKEN_FILE: str(file)})


@pytest.mark.parametrize(
    ("token", "header", "ok"),
    [
        (None, None, True),
        (None, "anything", True),
        ("s3cret", None, False),
        ("s3cret", "Bearer s3cret", True),
        ("s3cret", "bearer  s3cret ", True),
        ("s3cret", b"Bearer s3cret", True),
        ("s3cret", "Bearer s3cre", False),
        ("s3cret", "Basic s3cret", False),
        ("s3cret", "s3cret", False),
        ("s3cret", b"\xff\xfe", False),
    ],
)
def test_authorized(token: str | None, header: str | bytes | None, ok: bool) -> None:
    assert authorized(SecretStr(token) if token else None, header) is ok


@pytest.mark.parametrize(
    ("loc", "data", "path"),
    [
        (("stages", 0, "throttle", "hz"), {"stages": [{"type": "throttle"}]}, ("stages", 0, "hz")),
        (("stages", 0, "throttle"), {"stages": [{"type": "throttle"}]}, ("stages", 0)),
        (("stages", 0, "type"), {"stages": [{}]}, ("stages", 0, "type")),
        (("throttle", "hz"), {"type": "throttle", "throttle": {}}, ("throttle", "hz")),  # a real key wins
        (("to",), {"from": "/a"}, ("to",)),  # a missing key is still a key
    ],
)
def test_document_path_drops_union_tags(
    loc: tuple[str | int, ...], data: object, path: tuple[str | int, ...]
) -> None:
    assert document_path(loc, data) == path

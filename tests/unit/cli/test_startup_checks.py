"""What ``validate`` and ``run`` check on this machine: a config that validates also starts."""

from __future__ import annotations

from pathlib import Path

import pytest

from fleetlink.cli import main
from fleetlink.cli.startup_checks import writable_dir_problem, zenoh_problems
from fleetlink.cli.validate import validate_file
from fleetlink.common.errors import ConfigError
from fleetlink.common.zenoh_options import ZenohSection
from tests.paths import DEPLOY

EDGE = """\
site: a
spool: {{dir: {spool}}}
ros: {{message_paths: {paths}}}
zenoh: {zenoh}
robot_types:
  tb4:
    match: "/tb4_*"
    mappings:
      - {{name: ir, from: "/{{robot}}/ir", to: t.ir, type: {type}}}
"""


def _edge(tmp_path: Path, **values: str) -> Path:
    fields = {"spool": str(tmp_path / "spool"), "paths": "[]", "zenoh": "{}", "type": "std_msgs/msg/String"}
    path = tmp_path / "edge.yaml"
    path.write_text(EDGE.format(**(fields | values)))
    return path


def test_a_good_edge_passes(tmp_path: Path) -> None:
    assert validate_file(_edge(tmp_path))[0] == "edge"


@pytest.mark.parametrize(
    ("values", "message"),
    [
        ({"paths": "[/nonexistent/pkg]"}, "ros.message_paths[0] (line 3): /nonexistent/pkg is not a folder"),
        ({"paths": f"[{DEPLOY.parent / 'schemas' / 'msgs'}]"}, "give each package's folder"),
        ({"type": "my_msgs/msg/Nope"}, "robot_types.tb4.mappings[0].type (line 9): unknown ROS type"),
        (
            {"zenoh": f"{{config_file: {DEPLOY / 'zenoh' / 'edge-router-dev.json5'}}}"},
            "zenoh.config_file (line 4): zenoh config file",
        ),
        ({"zenoh": "{config_file: /nonexistent/z.json5}"}, "zenoh config file not found"),
        ({"zenoh": "{connect: [not-an-endpoint]}"}, "zenoh (line 4)"),
    ],
)
def test_what_would_stop_start_up_is_named_by_yaml_path(
    tmp_path: Path, values: dict[str, str], message: str
) -> None:
    with pytest.raises(ConfigError) as info:
        validate_file(_edge(tmp_path, **values))
    assert message in str(info.value)


def test_a_template_is_refused_with_the_render_command(tmp_path: Path) -> None:
    template = DEPLOY / "zenoh" / "cloud-router-dev.json5"
    (problem,) = zenoh_problems(ZenohSection(config_file=template))
    assert problem[0] == ("zenoh", "config_file")
    assert "${CONNECT}, ${LISTEN} have no value" in problem[1]
    assert "fleetlink zenoh render" in problem[1]


def test_zenoh_parser_refusals_are_reported(tmp_path: Path) -> None:
    bad = tmp_path / "z.json5"
    bad.write_text('{ mode: "router", listen: { endpoints: 7 } }')
    (problem,) = zenoh_problems(ZenohSection(config_file=bad))
    assert "Zenoh refuses it" in problem[1]


def test_a_folder_in_the_way_is_reported(tmp_path: Path) -> None:
    (tmp_path / "file").write_text("")
    assert writable_dir_problem(tmp_path / "file") == f"{tmp_path / 'file'} exists and is not a folder"
    assert "cannot create it" in str(writable_dir_problem(tmp_path / "file" / "spool"))
    assert writable_dir_problem(tmp_path / "new" / "spool") is None


def test_host_checks_can_be_left_out(tmp_path: Path) -> None:
    assert validate_file(_edge(tmp_path, paths="[/nonexistent]"), host_checks=False)[0] == "edge"


def test_set_and_env_change_what_is_checked(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _edge(tmp_path, type="my_msgs/msg/Nope")
    fix = "robot_types.tb4.mappings[0].type=std_msgs/msg/Int32"
    assert main(["validate", str(path), "--set", fix]) == 0
    assert "valid edge config (start-up checks passed)" in capsys.readouterr().out
    monkeypatch.setenv("FLEETLINK_SET", fix)
    assert main(["validate", str(path)]) == 0
    assert main(["validate", str(path), "--set", "spool.dir=" + str(path)]) == 1
    assert "spool.dir (set by --set):" in capsys.readouterr().err


def test_run_refuses_what_validate_refuses(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = _edge(tmp_path, paths="[/nonexistent/pkg]")
    assert main(["edge", "run", "-c", str(path)]) == 1
    assert "ros.message_paths[0] (line 3): /nonexistent/pkg is not a folder" in capsys.readouterr().err

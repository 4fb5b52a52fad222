"""``fleetlink zenoh render``: concrete configs zenohd reads, headed by the command that made them."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import zenoh

from fleetlink.cli import main
from fleetlink.common.zenoh_configs import concrete_json5, placeholders, render_router_config
from fleetlink.common.zenoh_options import load_zenoh_file
from tests.paths import DEPLOY

TEMPLATES = DEPLOY / "zenoh"


def test_render_writes_a_concrete_file_with_its_command(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "edge.json5"
    argv = [
        "zenoh",
        "render",
        str(TEMPLATES / "edge-router-dev.json5"),
        "--site",
        "s1",
        "-l",
        "tcp/0.0.0.0:7447",
    ]
    assert main([*argv, "-e", "tcp/cloud:7447", "-o", str(out)]) == 0
    text = out.read_text()
    assert text.splitlines()[1].strip("/ ").startswith("fleetlink zenoh render")
    assert not placeholders(text)
    conf = load_zenoh_file(out)
    assert json.loads(conf.get_json("connect/endpoints")) == ["tcp/cloud:7447"]
    assert json.loads(conf.get_json("metadata"))["name"] == "fleetlink-edge-s1-dev"
    assert capsys.readouterr().out.strip() == str(out)


def test_generated_acl_parts_come_out_as_json_with_the_same_meaning(tmp_path: Path) -> None:
    template = TEMPLATES / "cloud-router.json5"
    args = {"listen": ["tls/0.0.0.0:7447"], "cert_dir": "/etc/fleetlink/certs", "sites": ["a", "b"]}
    text = concrete_json5(template.read_text(), header="// x\n", **args)  # type: ignore[arg-type]
    assert text.startswith("// x\n{")
    ours = json.loads(str(zenoh.Config.from_json5(text)))
    assert ours == json.loads(str(render_router_config(template, **args)))  # type: ignore[arg-type]
    assert len(text) < 8000  # only what differs from Zenoh's defaults


def test_missing_values_are_errors(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["zenoh", "render", str(TEMPLATES / "edge-router-dev.json5")]) == 1
    assert "no value for placeholder(s) ${SITE}" in capsys.readouterr().err


def test_router_refuses_a_template(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["zenoh", "router", "-c", str(TEMPLATES / "cloud-router-dev.json5")]) == 1
    assert "is a template" in capsys.readouterr().err

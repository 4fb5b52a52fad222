"""Sending a command from the fleet console, on real processes: an uplink with one light-ring
command mapping and its console, a site with a repeater and a simulated robot. An operator
sends the command from the robot's page in Chromium; it goes through the mapping's Kafka topic
like an app's, the robot's light ring shows it, and the page shows its status from the command
status topic as it changes. Over the JSON API: a viewer may not send, a value that does not
fit the ROS type and a robot no site registered are refused.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import httpx
from playwright.sync_api import Page, expect

from fleetlink.common.console_config import ConsoleSection
from fleetlink.console.uplink import UplinkConsole, console_extensions
from fleetlink.console.users import hash_password
from fleetlink.repeater.service import Repeater
from fleetlink.uplink.service import Uplink
from tests.browser.conftest import shoot
from tests.helpers import wait_until
from tests.integration.test_commands_harness import (
    fleet,
    lightring_bed,
    repeater_config,
    wait_repeater_sees,
)

CHANGE = {"X-Fleetlink-Console": "1"}
RED_RING = "leds: [" + ", ".join(["{red: 255, green: 0, blue: 0}"] * 6) + "]\noverride_system: true"
GREEN_RING = RED_RING.replace("red: 255, green: 0", "red: 0, green: 255")


def test_an_operator_sends_a_command_and_sees_it_delivered(
    page: Page, kafka_bootstrap: str, schema_registry_url: str, tmp_path: Path
) -> None:
    users = tmp_path / "users.yaml"
    users.write_text(
        f"users:\n  - {{name: lin, role: operator, password_hash: '{hash_password('operator-pass-1')}'}}\n"
        f"  - {{name: sam, role: viewer, password_hash: '{hash_password('viewer-pass-1')}'}}\n"
    )
    with lightring_bed(kafka_bootstrap, schema_registry_url) as bed:
        console = ConsoleSection(listen="127.0.0.1:0", token_env=None, users_file=users, poll_interval=0.5)
        config = bed.config.model_copy(update={"console": console})
        bed.producer.register(config.topics.registrations, "tb4_01", bed.site.name)
        with (
            Repeater(repeater_config(bed.site, tmp_path / "state")) as repeater,
            fleet(bed.site, bed.ts, bed.leds) as robots,
            Uplink(config, extensions=console_extensions(config)) as uplink,
        ):
            router = uplink.commands
            assert router is not None
            wait_until(router.assigned.is_set, timeout=30, message="command partitions assigned")
            robots.add_robot("tb4_01")
            wait_repeater_sees(repeater, "/tb4_01/cmd_lightring")
            wait_until(lambda: "tb4_01" in uplink.directory.registered(), 15, message="tb4_01 registered")
            [extension] = uplink.extensions
            assert isinstance(extension, UplinkConsole)
            base = f"{extension.url}/console/"
            with (
                httpx.Client(base_url=base, auth=("lin", "operator-pass-1"), timeout=20) as operator,
                httpx.Client(base_url=base, auth=("sam", "viewer-pass-1"), timeout=20) as viewer,
            ):
                listed = viewer.get("api/command-mappings").json()
                assert [m["name"] for m in listed["mappings"]] == ["lightring"]
                command = {"mapping": "lightring", "robot": "tb4_01", "value": RED_RING}
                assert viewer.post("api/commands/send", json=command, headers=CHANGE).status_code == 403
                bad = operator.post(
                    "api/commands/send", json={**command, "value": "leds: not a list"}, headers=CHANGE
                )
                assert bad.status_code == 422, bad.text
                unknown = operator.post(
                    "api/commands/send", json={**command, "robot": "tb4_99"}, headers=CHANGE
                )
                assert unknown.status_code == 422
                assert "not registered" in unknown.json()["error"]
                sent = operator.post("api/commands/send", json=command, headers=CHANGE)
                assert sent.status_code == 201, sent.text
                command_id = sent.json()["result"]["command_id"]
                wait_until(lambda: bed.leds.first("tb4_01", "red") is not None, 10, message="the ring is red")
                statuses: dict[str, Any] = {}

                def delivered() -> bool:
                    statuses.update(viewer.get("api/commands/status", params={"ids": command_id}).json())
                    return any(s["status"] == "delivered" for s in statuses["statuses"].get(command_id, []))

                wait_until(delivered, 15, interval=0.3, message="the console shows the command delivered")
                assert bed.site.name in {s["site"] for s in statuses["statuses"][command_id]}

            # the same from the robot's page, as an operator would
            page.goto(base)
            page.fill("#user", "lin")
            page.fill("#token", "operator-pass-1")
            page.click("form.login button[type=submit]")
            page.wait_for_url("**/console/**")
            page.goto(f"{base}sites/{bed.site.name}/robots/tb4_01")
            expect(page.locator("#c-mapping option")).to_have_count(1)
            page.fill("#c-value", GREEN_RING)
            page.click("#send-command")
            expect(page.locator("#command-result")).to_contain_text("is in Kafka")
            row = page.locator("#sent-commands tbody tr").first
            expect(row).to_have_attribute("data-status", "delivered", timeout=15000)
            expect(row).to_contain_text(f"delivered at {bed.site.name}")
            assert bed.leds.first("tb4_01", "green") is not None
            print(f"screenshot: {shoot(page, 'fleet-robot-command-delivered')}")

"""The fleet console's pages in headless Chromium with two sites and two uplinks (the stack of
tests/integration/test_console_fleet.py), signed in as named users:

1. the fleet page lists both sites and the delivery of both uplinks;
2. a site's page shows that site alone, what Kafka acknowledged, and the last hour as charts;
3. a robot's page shows the latest value of its mapped topic and its registration history; a
   sample the edge dead-letters shows in the dead-letter browser with its stage, reason and
   bytes (hex, download);
4. a viewer sees their role and no audit link, and the robot-type editor is closed to them.

Screenshots are saved under var/screenshots/ (listed at the end of the run).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
import zenoh
from playwright.sync_api import Page, expect

from fleetlink.roswire.names import data_key_expr
from tests.browser.conftest import shoot
from tests.browser.test_console_browser import node, rate
from tests.helpers import wait_until, zenoh_peer_config
from tests.integration.test_console_fleet import PASSWORDS, Fleet2, two_sites


@pytest.fixture(scope="module")
def fleet2(
    kafka_bootstrap: str, schema_registry_url: str, tmp_path_factory: pytest.TempPathFactory
) -> Iterator[Fleet2]:
    with two_sites(kafka_bootstrap, schema_registry_url, tmp_path_factory.mktemp("fleet2b")) as running:
        yield running


def sign_in_as(page: Page, url: str, name: str) -> None:
    page.goto(url)
    page.fill("#user", name)
    page.fill("#token", PASSWORDS[name])
    page.click("form.login button[type=submit]")
    page.wait_for_url("**/console/**")
    expect(page.locator("#who")).to_contain_text(name)


def test_each_site_alone_robot_page_and_dead_letters(page: Page, fleet2: Fleet2) -> None:
    site_a, site_b = fleet2.sites
    base = fleet2.consoles[0]
    sign_in_as(page, base, "lin")
    expect(page.locator("#who")).to_have_text("lin · operator")
    for site in (site_a, site_b):
        expect(page.locator(f'#sites tr[data-site="{site}"]')).to_contain_text("edge-1")
        expect(page.locator(f'#fleet-uplinks tr[data-site="{site}"]')).to_have_count(1, timeout=15000)
    print(f"screenshot: {shoot(page, 'fleet-two-sites')}")

    page.goto(f"{base}sites/{site_a}")
    expect(node(page, "r:tb4_01")).to_be_visible()
    wait_until(lambda: rate(node(page, "k:fleet.ir")) > 0, 20, interval=0.3, message="Kafka acknowledged")
    page.check("#show-unmapped")  # even with every topic shown, the other site's robots are not
    expect(node(page, "t:/tb4_01/imu")).to_be_visible()
    expect(page.locator('[data-node-id^="r:kb_"], [data-node-id^="t:/kb_"]')).to_have_count(0)
    expect(page.locator('[data-node-id="r:fleetlink"]')).to_have_count(0)
    page.uncheck("#show-unmapped")
    acked = page.locator('#chart-rates path[data-series="acked"]')
    wait_until(
        lambda: int(acked.get_attribute("data-points") or 0) >= 2 if acked.count() else False,
        20,
        interval=0.5,
        message="two points of acknowledged records in the chart",
    )
    print(f"screenshot: {shoot(page, 'fleet-site-alone-with-history')}")

    page.goto(f"{base}sites/{site_a}/robots/tb4_01")
    expect(page.locator("#robot-state")).to_have_text("registered")
    expect(page.locator("#robot-type")).to_contain_text("discovered")
    expect(page.locator('#latest [data-topic="/tb4_01/ir_intensity"]')).to_contain_text("readings")
    expect(page.locator('#robot-topics tr[data-topic="/tb4_01/ir_intensity"]')).to_contain_text("fleet.ir")
    expect(page.locator("#command-result")).to_contain_text("not available")  # no command mapping here

    expect(page.locator("#robot-history tbody tr").first).to_contain_text("registered")
    print(f"screenshot: {shoot(page, 'fleet-robot-page')}")

    # a sample without its rmw_zenoh attachment on tb4_01's mapped topic: the edge dead-letters it
    page.goto(f"{base}sites/{site_a}/dead-letters")
    expect(page.locator("#dead-letters-state")).to_contain_text("0 of 0 dead letter(s) shown")
    garbage = bytes(range(48))
    with zenoh.open(zenoh_peer_config(fleet2.routers[0])) as vandal:
        keys: list[str] = []
        expr = data_key_expr(fleet2.domain, "/tb4_01/ir_intensity")
        subscriber = vandal.declare_subscriber(expr, lambda sample: keys.append(str(sample.key_expr)))
        wait_until(lambda: bool(keys), 10, message="the robot's key seen")
        subscriber.undeclare()
        vandal.put(keys[0], garbage)
    row = page.locator("#dead-letters tbody tr").first
    expect(row).to_contain_text("receive", timeout=20000)
    expect(row).to_contain_text("attachment")
    expect(row).to_contain_text(f"{site_a} / edge-1")
    row.locator("button.show").click()
    expect(page.locator("#dead-letter-hex")).to_contain_text("00 01 02 03 04 05")
    with page.expect_download() as download:
        page.click("#dead-letter-download")
    assert Path(download.value.path()).read_bytes() == garbage
    print(f"screenshot: {shoot(page, 'fleet-dead-letters')}")


def test_a_viewer_sees_their_role_and_cannot_edit_robot_types(page: Page, fleet2: Fleet2) -> None:
    base = fleet2.consoles[1]  # the other uplink's console shows the same fleet
    sign_in_as(page, base, "sam")
    expect(page.locator("#who")).to_have_text("sam · viewer")
    expect(page.locator(".audit-link")).to_have_count(0)
    page.goto(f"{base}sites/{fleet2.sites[1]}")
    expect(node(page, "r:kb_01")).to_be_visible()
    expect(node(page, "r:tb4_01")).to_have_count(0)
    expect(page.locator("#t-name")).to_be_disabled()  # the robot-type editor is an admin's
    expect(page.locator("#save-type")).to_be_disabled()


def test_an_admin_edits_robot_types_and_reads_the_audit(page: Page, fleet2: Fleet2) -> None:
    base = fleet2.consoles[1]
    page.goto(base)
    page.fill("#token", fleet2.token)  # no user name: the admin token, the bootstrap admin
    page.click("form.login button[type=submit]")
    page.wait_for_url("**/console/**")
    expect(page.locator("#who")).to_have_text("token · admin")
    page.goto(f"{base}sites/{fleet2.sites[1]}")
    page.fill("#t-name", "kb")
    page.fill("#t-match", "/kb_*")
    page.fill("#t-mappings", "{not: a list}")
    page.click("#save-type")
    expect(page.locator("#terror-mappings")).to_contain_text("a list of mappings is expected")
    # a valid one is saved (the same validation as the API), listed, then removed (confirmed)
    page.fill("#t-name", "kb")
    page.fill("#t-match", "/kb_*")
    page.fill("#t-mappings", "- {name: kb-ir, from: '/{robot}/ir_intensity', to: fleet.kb.ir}")
    page.click("#save-type")
    saved = page.locator('#robot-types tr[data-type="kb"]')
    expect(saved).to_contain_text("/kb_*")
    expect(saved).to_contain_text("kb-ir")
    saved.locator("button.remove").click()
    saved.locator("button.remove").click()  # "Confirm remove"
    expect(page.locator('#robot-types tr[data-type="kb"]')).to_have_count(0)
    page.click(".audit-link")
    row = page.locator('#audit tbody tr[data-action="robot_type.put"]').first
    expect(row).to_contain_text("token")
    expect(page.locator('#audit tbody tr[data-action="robot_type.put"]', has_text="422")).to_have_count(1)
    expect(page.locator('#audit tbody tr[data-action="robot_type.remove"]')).to_have_count(1)
    print(f"screenshot: {shoot(page, 'fleet-audit')}")

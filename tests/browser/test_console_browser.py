"""The web console in headless Chromium against a running stack (real Kafka and registry, real
Zenoh routers, the uplink with its fleet console, an edge agent with its console, simulated
TurtleBot 4 robots):

1. the graph shows the simulated robots and their topics with non-zero rates (edge console, and
   the fleet console over the Zenoh admin space);
2. a mapping added in the fleet console makes records flow to Kafka; removed there, it is gone;
3. an invalid mapping shows its error next to the offending field, and nothing is changed;
4. without the token nothing is shown.

Screenshots are saved under var/screenshots/ (listed at the end of the run).
"""

from __future__ import annotations

import re
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest
from playwright.sync_api import Locator, Page, expect

from tests.browser.conftest import shoot
from tests.browser.stack import Stack, console_stack
from tests.helpers import wait_until
from tests.integration.e2e_stack import TopicReader, headers


@pytest.fixture(scope="module")
def stack(
    kafka_bootstrap: str, schema_registry_url: str, tmp_path_factory: pytest.TempPathFactory
) -> Iterator[Stack]:
    with console_stack(kafka_bootstrap, schema_registry_url, tmp_path_factory.mktemp("console")) as running:
        yield running


def sign_in(page: Page, url: str, token: str) -> None:
    page.goto(url)
    expect(page.locator("#token")).to_be_visible()
    page.fill("#token", token)
    page.click("form.login button[type=submit]")
    page.wait_for_url("**/console/**")
    expect(page.locator("#token")).to_have_count(0)


def node(page: Page, node_id: str) -> Locator:
    return page.locator(f'[data-node-id="{node_id}"]')


def rate(locator: Locator) -> float:
    text = locator.get_attribute("data-rate") if locator.count() == 1 else None
    return float(text) if text else 0.0


def wait_live(page: Page, node_ids: list[str], timeout: float = 20) -> None:
    for node_id in node_ids:
        expect(node(page, node_id)).to_be_visible()
    wait_until(
        lambda: all(rate(node(page, n)) > 0 for n in node_ids),
        timeout,
        interval=0.2,
        message=f"non-zero rates on {node_ids}",
    )


def test_graph_shows_the_robots_and_their_topics_with_live_rates(page: Page, stack: Stack) -> None:
    sign_in(page, stack.edge_console, stack.token)
    expect(page.locator("#site-name")).to_have_text(stack.site)
    for robot in ("tb4_01", "tb4_02"):
        expect(node(page, f"r:{robot}")).to_contain_text(robot)
        expect(page.locator(f'#robots tr[data-robot="{robot}"]')).to_contain_text("registered")
    wait_live(page, ["t:/tb4_01/ir_intensity", "t:/tb4_02/ir_intensity", "m:ir", "k:fleet.ir"])
    expect(node(page, "t:/tb4_01/ir_intensity")).to_contain_text("msg/s")
    expect(node(page, "t:/tb4_01/imu")).to_have_count(0)  # topics no mapping takes: behind a switch
    page.check("#show-unmapped")
    expect(node(page, "t:/tb4_01/imu")).to_contain_text("not mapped")
    page.uncheck("#show-unmapped")
    page.fill("#filter", "tb4_02")  # the filter leaves the other robot and its topics out
    expect(node(page, "r:tb4_01")).to_have_count(0)
    expect(node(page, "t:/tb4_02/ir_intensity")).to_be_visible()
    expect(page.locator('#robots tr[data-robot="tb4_01"]')).to_be_hidden()
    page.fill("#filter", "")
    expect(page.locator("#graph-lines path.edge.live").first).to_be_attached()
    expect(page.locator("#health-spool")).to_contain_text("durable:")
    expect(page.locator("#health-wan")).to_contain_text("up")
    expect(page.locator("#commands-unavailable")).to_contain_text("not available on this process")
    print(f"screenshot: {shoot(page, 'edge-console-site')}")

    # the same site through the uplink's fleet console, over the Zenoh admin space (signed in
    # afresh: cookies do not tell ports apart, and both consoles take the same token)
    # leave the edge console first: its next poll, signed out, would navigate to its login page
    # and abort the navigation to the fleet console
    page.goto("about:blank")
    page.context.clear_cookies()
    sign_in(page, stack.fleet_console, stack.token)
    row = page.locator(f'#sites tr[data-site="{stack.site}"]')
    expect(row).to_contain_text("edge-1")
    print(f"screenshot: {shoot(page, 'fleet-console-sites')}")
    row.locator("a").click()
    page.wait_for_url(f"**/console/sites/{stack.site}")
    wait_live(page, ["t:/tb4_01/ir_intensity", "t:/tb4_02/ir_intensity", "m:ir"])
    expect(page.locator("#health-latency")).to_contain_text("median")
    expect(page.locator("#commands-unavailable")).to_contain_text("no command mappings")
    print(f"screenshot: {shoot(page, 'fleet-console-site')}")


def test_a_mapping_added_in_the_console_flows_to_kafka(page: Page, stack: Stack) -> None:
    topic = f"console.browser.imu.{uuid.uuid4().hex[:8]}"
    sign_in(page, f"{stack.fleet_console}sites/{stack.site}", stack.token)
    expect(page.locator('#f-robot_type option[value="tb4"]')).to_be_attached()
    page.fill("#f-name", "imu_console")
    page.select_option("#f-robot_type", "tb4")
    page.fill("#f-from", "/{robot}/imu")
    page.fill("#f-to", topic)
    page.fill("#f-type", "sensor_msgs/msg/Imu")
    page.fill("#f-stages", "- {type: throttle, hz: 5}")
    page.click("#dry-run-button")
    dry = page.locator("#dry-run-table")
    expect(dry).to_contain_text("/tb4_01/imu")
    expect(dry).to_contain_text("/tb4_02/imu")
    expect(dry).to_contain_text(topic)
    page.click("#submit-mapping")
    expect(page.locator("#form-result")).to_have_text("mapping imu_console created")
    row = page.locator('#mappings tr[data-mapping="imu_console"]')
    expect(row).to_contain_text(topic)
    assert "imu_console" in [m.name for m in stack.agent.table.list()]

    records = TopicReader(stack.bootstrap, stack.registry_url).read(topic, 6, timeout=20)
    assert {headers(m)["fleetlink.mapping"] for m in records} == {"imu_console"}
    assert {(m.key() or b"").decode() for m in records} <= {"tb4_01", "tb4_02"}
    value = TopicReader(stack.bootstrap, stack.registry_url).value(records[0])
    assert set(value) >= {"orientation", "angular_velocity", "linear_acceleration"}
    wait_live(page, ["m:imu_console", f"k:{topic}"])
    print(f"screenshot: {shoot(page, 'fleet-console-mapping-added')}")

    row.locator("button.remove").click()
    expect(row.locator("button.remove")).to_have_text("Confirm remove")
    row.locator("button.remove").click()
    expect(page.locator("#form-result")).to_have_text("mapping imu_console removed")
    expect(row).to_have_count(0)
    assert "imu_console" not in [m.name for m in stack.agent.table.list()]


def field_of(page: Page, error_id: str) -> Locator:
    """The form field box that holds an error element (its label, input and error)."""
    return page.locator(f".field:has(#{error_id})")


def test_an_invalid_mapping_shows_its_error_next_to_the_field(page: Page, stack: Stack) -> None:
    sign_in(page, stack.edge_console, stack.token)
    expect(page.locator('#f-robot_type option[value="tb4"]')).to_be_attached()
    before = [m.name for m in stack.agent.table.list()]
    page.fill("#f-name", "odom_bad")
    page.select_option("#f-robot_type", "tb4")
    page.fill("#f-from", "/{robot}/odom")
    page.fill("#f-to", "fleet.odom")
    page.fill("#f-stages", "- {type: throttle, hz: 0}")
    page.click("#submit-mapping")
    error = page.locator("#error-stages")
    expect(error).to_be_visible()
    expect(error).to_have_text("stages[0].hz: Input should be greater than 0")
    expect(field_of(page, "error-stages").locator("textarea#f-stages")).to_have_attribute(
        "aria-invalid", "true"
    )
    for other in ("name", "from", "to", "key", "type", "_form"):
        expect(page.locator(f"#error-{other}")).to_be_hidden()
    expect(page.locator("#form-result")).to_contain_text("does not validate")
    print(f"screenshot: {shoot(page, 'edge-console-invalid-stage')}")

    page.fill("#f-stages", "")
    page.fill("#f-from", "odom")
    page.click("#submit-mapping")
    expect(page.locator("#error-from")).to_be_visible()
    expect(field_of(page, "error-from").locator("input#f-from")).to_have_attribute("aria-invalid", "true")
    expect(page.locator("#error-stages")).to_be_hidden()
    print(f"screenshot: {shoot(page, 'edge-console-invalid-from')}")
    assert [m.name for m in stack.agent.table.list()] == before

    # changing a mapping: the form loads it, a bad change is refused on its field, a good one applies
    page.locator('#mappings tr[data-mapping="ir"] button.edit').click()
    expect(page.locator("#form-title")).to_have_text("Change mapping ir")
    expect(page.locator("#f-name")).to_have_value("ir")
    expect(page.locator("#f-name")).to_have_attribute("readonly", "")
    expect(page.locator("#f-stages")).to_have_value(re.compile(r'"hz":\s*2'))
    page.fill("#f-stages", "- {type: throttle, hz: 3, keep: sometimes}")
    page.click("#submit-mapping")
    expect(page.locator("#error-stages")).to_contain_text("stages[0].keep")
    page.fill("#f-stages", "- {type: throttle, hz: 3}")
    page.click("#submit-mapping")
    expect(page.locator("#form-result")).to_have_text("mapping ir changed")
    expect(page.locator('#mappings tr[data-mapping="ir"]')).to_contain_text("throttle(hz=3")
    assert [m.name for m in stack.agent.table.list()] == before


def test_nothing_is_shown_without_the_token(page: Page, stack: Stack) -> None:
    page.goto(f"{stack.edge_console}sites/{stack.site}")
    page.wait_for_url(re.compile(r".*/console/login\?next=/console/sites/.*"))
    page.fill("#token", "not-the-token")
    page.click("form.login button[type=submit]")
    expect(page.locator("#login-error")).to_have_text("wrong token")
    content = page.content()
    for shown in ("tb4_01", "fleet.ir", "ir_intensity", 'id="graph"'):  # no robot, mapping or graph
        assert shown not in content
    assert page.context.cookies() == []
    shot: Path = shoot(page, "console-sign-in-refused")
    print(f"screenshot: {shot}")

"""Headless Chromium for the console tests: Debian's ``/usr/bin/chromium`` driven by Playwright.

The browser is the system's (``apt-get install chromium``); Playwright's own browser download is
never used. Screenshots go to ``var/screenshots/`` of the repository (listed at the end of the
run); ``FLEETLINK_SCREENSHOTS`` puts them elsewhere.
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from playwright.sync_api import Browser, ConsoleMessage, Page, Playwright, sync_playwright

CHROMIUM = Path("/usr/bin/chromium")
ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
ROOT = Path(__file__).resolve().parents[2]


def screenshot_dir() -> Path:
    where = Path(os.environ.get("FLEETLINK_SCREENSHOTS", ROOT / "var" / "screenshots"))
    where.mkdir(parents=True, exist_ok=True)
    return where


def shoot(page: Page, name: str) -> Path:
    """Save a full-page screenshot named ``name`` (listed in the summary)."""
    path = screenshot_dir() / f"{name}.png"
    page.screenshot(path=str(path), full_page=True)
    return path


_began = time.time()


def pytest_terminal_summary(terminalreporter: pytest.TerminalReporter) -> None:
    # the screenshots of this run, whichever process took them (pytest-xdist workers included)
    where = Path(os.environ.get("FLEETLINK_SCREENSHOTS", ROOT / "var" / "screenshots"))
    taken = sorted(
        (p for p in where.glob("*.png") if p.stat().st_mtime >= _began), key=lambda p: p.stat().st_mtime
    )
    if taken:
        terminalreporter.write_sep("-", "console screenshots")
        for path in taken:
            terminalreporter.write_line(str(path))


@pytest.fixture(scope="session")
def playwright() -> Iterator[Playwright]:
    with sync_playwright() as driver:
        yield driver


@pytest.fixture(scope="session")
def browser(playwright: Playwright) -> Iterator[Browser]:
    if not CHROMIUM.exists():
        raise AssertionError(f"{CHROMIUM} is missing: apt-get install -y chromium (see .ci/run)")
    chromium = playwright.chromium.launch(executable_path=str(CHROMIUM), args=ARGS)
    try:
        yield chromium
    finally:
        chromium.close()


class PageErrors(list[str]):
    """Uncaught script errors and failed console messages of one page."""


@pytest.fixture
def page(browser: Browser) -> Iterator[Page]:
    context = browser.new_context(viewport={"width": 1400, "height": 1000}, locale="en-GB")
    tab = context.new_page()
    errors = PageErrors()

    def on_console(message: ConsoleMessage) -> None:
        if message.type == "error" and "status of 4" not in message.text:  # refusals are expected answers
            errors.append(message.text)

    tab.on("pageerror", lambda exc: errors.append(str(exc)))
    tab.on("console", on_console)
    tab.set_default_timeout(15_000)
    try:
        yield tab
        if errors:
            raise AssertionError(f"script errors on the page: {errors}")
    finally:
        context.close()

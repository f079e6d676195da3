"""The Zones panel in a real headless Chromium, against the dashboard alone (no robot, no
map: the page's default view): a zone drawn by clicking its vertices is a zone row, drawn
on the map in its colour; a refused one is shown with the API's reason; Remove deletes it.

The dashboard serves the page from this test's own event loop (the ``running`` fixture), so
every webdriver call goes through :func:`off_loop`. A webdriver call is a blocking HTTP
request to chromedriver, and chromedriver first waits for any navigation of the page to
finish (the page and its script, served by the dashboard). Made on the loop, the call
blocked the very server the page waited for: under load (13-18) the first
``execute_script`` after ``get`` hung until selenium's 120 s read timeout, chromedriver
waiting for a page the loop could no longer serve. The end-to-end dashboard test drives a
dashboard in a process of its own and has no such cycle.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Any, TypeVar

import pytest

from common.runtime import Runtime
from tests.contract.dashboard.conftest import Running
from tests.e2e.test_dashboard import browser, click_world, until

pytestmark = pytest.mark.timeout(240)
__all__ = ["browser"]  # the fixture, shared

SQUARE = [(2.0, 2.0), (5.0, 2.0), (5.0, 5.0), (2.0, 5.0)]
T = TypeVar("T")


async def off_loop(call: Callable[..., T], *args: Any) -> T:
    """Run a webdriver call in a thread, leaving the loop free to serve the page."""
    return await asyncio.to_thread(call, *args)


def pixel(driver: Any, x: float, y: float) -> list[int]:
    """The canvas colour at world point (x, y)."""
    rgb: list[int] = driver.execute_script(
        """
        const [px, py] = window.pnavDashboard.toCanvas(arguments[0], arguments[1]);
        const d = document.getElementById('map').getContext('2d')
            .getImageData(Math.round(px), Math.round(py), 1, 1).data;
        return [d[0], d[1], d[2]];
        """,
        x,
        y,
    )
    return rgb


def start_drawing(driver: Any, name: str, points: list[tuple[float, float]]) -> None:
    """Name the zone, press Draw and click its vertices (webdriver calls: off the loop)."""
    from selenium.webdriver.common.by import By

    field = driver.find_element(By.NAME, "name")
    field.clear()
    field.send_keys(name)
    driver.find_element(By.ID, "zone-draw").click()
    for x, y in points:
        click_world(driver, x, y)


def text_of(driver: Any, element_id: str) -> str:
    from selenium.webdriver.common.by import By

    text: str = driver.find_element(By.ID, element_id).text
    return text


def click(driver: Any, css: str) -> None:
    from selenium.webdriver.common.by import By

    driver.find_element(By.CSS_SELECTOR, css).click()


async def draw(driver: Any, name: str, points: list[tuple[float, float]]) -> None:
    await off_loop(start_drawing, driver, name, points)

    async def drafted() -> bool:
        script = "return (window.pnavDashboard.drawing || []).length"
        return bool(await off_loop(driver.execute_script, script) == len(points))

    await until(drafted, "the draft's vertices")
    await off_loop(click, driver, "#zone-add")


async def test_a_zone_is_drawn_vertex_by_vertex_added_shown_and_removed(
    browser: Any, running: Running, foreign: Runtime
) -> None:
    pool = foreign.database.pool

    async def page_up() -> bool:
        await off_loop(browser.get, running.url)
        script = "return !!(window.pnavDashboard || {}).connected"
        return bool(await off_loop(browser.execute_script, script))

    async def says(element_id: str, text: str) -> bool:
        return text in await off_loop(text_of, browser, element_id)

    async def colour() -> list[int]:
        return await off_loop(pixel, browser, 3.5, 3.5)

    await until(page_up, "the page to connect", within=60)
    blank = await colour()

    # a bow tie: refused with the table's reason, nothing written, still drawing
    await draw(browser, "bowtie", [(2.0, 2.0), (5.0, 5.0), (5.0, 2.0), (2.0, 5.0)])
    await until(lambda: says("message", "edges 1 and 3 cross"), "the refusal on the page")
    assert await pool.fetchval("SELECT count(*) FROM zone") == 0
    await off_loop(click, browser, "#zone-discard")

    await draw(browser, "dock-7", SQUARE)
    row = await until(
        lambda: pool.fetchrow("SELECT kind, xs, ys FROM zone WHERE name = 'dock-7'"),
        "the zone row the clicks write",
    )
    assert row["kind"] == "keepout"
    for (x, y), (rx, ry) in zip(SQUARE, zip(row["xs"], row["ys"], strict=True), strict=True):
        assert abs(rx - x) < 0.05 and abs(ry - y) < 0.05, (row, SQUARE)
    await until(lambda: says("zones", "dock-7"), "the zone listed")

    async def coloured() -> list[int] | None:
        p = await colour()
        return p if p != blank else None

    red = await until(coloured, "the zone drawn on the map")
    assert red[0] > red[1] and red[0] > red[2], red  # keepout red

    await off_loop(click, browser, "#zones button")
    await until(lambda: pool.fetchval("SELECT count(*) = 0 FROM zone"), "the zone row removed")

    async def cleared() -> bool:
        return await colour() == blank

    await until(cleared, "the zone gone from the map")

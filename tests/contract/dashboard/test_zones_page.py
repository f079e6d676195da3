"""The Zones panel in a real headless Chromium, against the dashboard alone (no robot, no
map: the page's default view): a zone drawn by clicking its vertices is a zone row, drawn
on the map in its colour; a refused one is shown with the API's reason; Remove deletes it."""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from common.runtime import Runtime
from tests.contract.dashboard.conftest import Running
from tests.e2e.test_dashboard import browser, click_world, until

pytestmark = pytest.mark.timeout(240)
__all__ = ["browser"]  # the fixture, shared

SQUARE = [(2.0, 2.0), (5.0, 2.0), (5.0, 5.0), (2.0, 5.0)]


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


async def draw(driver: Any, name: str, points: list[tuple[float, float]]) -> None:
    from selenium.webdriver.common.by import By

    field = driver.find_element(By.NAME, "name")
    field.clear()
    field.send_keys(name)
    driver.find_element(By.ID, "zone-draw").click()
    for x, y in points:
        click_world(driver, x, y)
    await until(
        lambda: (
            driver.execute_script("return (window.pnavDashboard.drawing || []).length")
            == len(points)
        ),
        "the draft's vertices",
    )
    driver.find_element(By.ID, "zone-add").click()


async def test_a_zone_is_drawn_vertex_by_vertex_added_shown_and_removed(
    browser: Any, running: Running, foreign: Runtime
) -> None:
    from selenium.webdriver.common.by import By

    pool = foreign.database.pool

    async def page_up() -> bool:
        await asyncio.to_thread(browser.get, running.url)
        return bool(browser.execute_script("return !!(window.pnavDashboard || {}).connected"))

    await until(page_up, "the page to connect", within=60)
    blank = pixel(browser, 3.5, 3.5)

    # a bow tie: refused with the table's reason, nothing written, still drawing
    await draw(browser, "bowtie", [(2.0, 2.0), (5.0, 5.0), (5.0, 2.0), (2.0, 5.0)])
    message = browser.find_element(By.ID, "message")
    await until(lambda: "edges 1 and 3 cross" in message.text, "the refusal on the page")
    assert await pool.fetchval("SELECT count(*) FROM zone") == 0
    browser.find_element(By.ID, "zone-discard").click()

    await draw(browser, "dock-7", SQUARE)
    row = await until(
        lambda: pool.fetchrow("SELECT kind, xs, ys FROM zone WHERE name = 'dock-7'"),
        "the zone row the clicks write",
    )
    assert row["kind"] == "keepout"
    for (x, y), (rx, ry) in zip(SQUARE, zip(row["xs"], row["ys"], strict=True), strict=True):
        assert abs(rx - x) < 0.05 and abs(ry - y) < 0.05, (row, SQUARE)
    await until(lambda: "dock-7" in browser.find_element(By.ID, "zones").text, "the zone listed")
    red = await until(
        lambda: (p := pixel(browser, 3.5, 3.5)) != blank and p, "the zone drawn on the map"
    )
    assert red[0] > red[1] and red[0] > red[2], red  # keepout red

    browser.find_element(By.CSS_SELECTOR, "#zones button").click()
    await until(lambda: pool.fetchval("SELECT count(*) = 0 FROM zone"), "the zone row removed")
    await until(lambda: pixel(browser, 3.5, 3.5) == blank, "the zone gone from the map")

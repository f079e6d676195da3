"""The dashboard in a real headless Chromium, against a real stack (sim, bridge, the four
scenario services and the dashboard, as ``pnav up`` runs them).

The page must draw the robot where odometry says, send a goal where the map is clicked (a
goal row appears, the robot moves), switch strategy from its list, and show a decision's
provenance. Set ``PNAV_DASHBOARD_SCREENSHOT=docs/dashboard.png`` to keep the screenshot it
takes at the end (that is how docs/dashboard.png is made).
"""

from __future__ import annotations

import asyncio
import math
import os
import shutil
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from common.config import ServiceConfig
from common.runtime import Runtime
from pnav.run.launcher import launched
from pnav.run.stack_options import DashboardOptions, StackOptions

pytestmark = pytest.mark.timeout(240)

CHROMIUM = Path("/usr/bin/chromium")
CHROMEDRIVER = Path("/usr/bin/chromedriver")
ROBOT = "r1"
GOAL = (3.7, 2.5)  # down the first aisle of the warehouse, in sight of r1's start
CHROME_ARGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--no-first-run",
    "--window-size=1440,1280",
)


@pytest.fixture
def browser(tmp_path: Path) -> Iterator[Any]:
    if not (CHROMIUM.is_file() and CHROMEDRIVER.is_file()):
        pytest.skip(
            "needs Debian's chromium and chromium-driver (/usr/bin/chromium, "
            "/usr/bin/chromedriver): scripts/setup installs them where apt-get works"
        )
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = str(CHROMIUM)
    for arg in (*CHROME_ARGS, f"--user-data-dir={tmp_path / 'chromium'}"):
        options.add_argument(arg)
    # the driver's path is given: selenium-manager never tries to download one
    driver = webdriver.Chrome(service=Service(str(CHROMEDRIVER)), options=options)
    try:
        yield driver
    finally:
        driver.quit()


async def until(check: Callable[[], Any], what: str, within: float = 60.0) -> Any:
    """Wait for ``check()`` (sync, or a coroutine function) to be truthy; return it."""
    deadline = time.monotonic() + within
    while True:
        value = check()
        if asyncio.iscoroutine(value):
            value = await value
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {within:.0f} s waiting for {what}")
        await asyncio.sleep(0.2)


def drawn(driver: Any) -> dict[str, Any] | None:
    """Where the page last drew r1 (world and canvas), and the canvas colour just behind
    its centre (inside the footprint, clear of the heading line)."""
    result: dict[str, Any] | None = driver.execute_script(
        """
        const s = window.pnavDashboard;
        const d = s && s.connected && s.drawn[arguments[0]];
        const r = s && s.robots[arguments[0]];
        if (!d || !r || !r.pose) return null;
        const px = Math.round(d.px - 4 * Math.cos(r.pose.yaw));
        const py = Math.round(d.py + 4 * Math.sin(r.pose.yaw));
        const rgb = document.getElementById('map').getContext('2d')
            .getImageData(px, py, 1, 1).data;
        return {x: d.x, y: d.y, color: d.color, pixel: [rgb[0], rgb[1], rgb[2]]};
        """,
        ROBOT,
    )
    return result


def hex_rgb(color: str) -> list[int]:
    return [int(color[i : i + 2], 16) for i in (1, 3, 5)]


def click_world(driver: Any, x: float, y: float) -> None:
    """Click the canvas at world point (x, y), through the page's own transform."""
    from selenium.webdriver.common.action_chains import ActionChains

    canvas, dx, dy = _at_world(driver, x, y)
    ActionChains(driver).move_to_element_with_offset(canvas, dx, dy).click().perform()


def drag_world(driver: Any, x: float, y: float, right_px: int, up_px: int, shift: bool) -> None:
    """Press the canvas at world point (x, y), drag by (right, up) pixels, release; with Shift
    held if ``shift``."""
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.keys import Keys

    # the form steps may have scrolled the page: actions outside the viewport are lost
    driver.execute_script("document.getElementById('map').scrollIntoView({block: 'center'})")
    canvas, dx, dy = _at_world(driver, x, y)
    chain = ActionChains(driver)
    if shift:
        chain = chain.key_down(Keys.SHIFT)
    chain = chain.move_to_element_with_offset(canvas, dx, dy).click_and_hold()
    chain = chain.move_by_offset(right_px // 2, -up_px // 2).move_by_offset(
        right_px - right_px // 2, -(up_px - up_px // 2)
    )
    chain = chain.release()
    if shift:
        chain = chain.key_up(Keys.SHIFT)
    chain.perform()


def _at_world(driver: Any, x: float, y: float) -> tuple[Any, int, int]:
    """The canvas and the offset of world point (x, y) from its centre (W3C actions)."""
    from selenium.webdriver.common.by import By

    canvas = driver.find_element(By.ID, "map")
    dx, dy = driver.execute_script(
        """
        const c = document.getElementById('map');
        const [px, py] = window.pnavDashboard.toCanvas(arguments[0], arguments[1]);
        const rect = c.getBoundingClientRect();
        const sx = rect.width / c.width, sy = rect.height / c.height;
        return [px * sx - rect.width / 2, py * sy - rect.height / 2];
        """,
        x,
        y,
    )
    return canvas, int(dx), int(dy)


async def test_the_page_draws_the_robot_sends_a_goal_switches_strategy_and_explains(
    browser: Any, tmp_path: Path
) -> None:
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select

    options = StackOptions(
        world="warehouse",
        rate="2",
        robots=1,
        zenoh_port=None,
        log_dir=tmp_path / "logs",
        dashboard=DashboardOptions(port=None),
    )
    async with launched(options) as stack:
        url = stack.dashboard_url
        assert url is not None
        rt = await Runtime.open(
            ServiceConfig(
                service="e2e", database_url=stack.local.database_url, zenoh=stack.local.zenoh
            )
        )
        pool = rt.database.pool
        try:
            await until(
                lambda: pool.fetchval("SELECT count(*) FROM odometry WHERE robot_id = 'r1'"),
                "r1's first odometry",
            )

            async def page_up() -> bool:
                # before the dashboard listens Chromium shows its own error page: load again
                try:
                    await asyncio.to_thread(browser.get, url)
                    return bool(browser.execute_script("return !!window.pnavDashboard"))
                except Exception:
                    return False

            await until(page_up, "the dashboard to answer", within=60)

            # 1. the robot is drawn where odometry says (it stands still: no goal yet)
            seen = await until(lambda: drawn(browser), "the page to draw r1")
            pose = await pool.fetchrow(
                "SELECT x, y FROM odometry WHERE robot_id = 'r1' ORDER BY id DESC LIMIT 1"
            )
            assert math.hypot(seen["x"] - pose["x"], seen["y"] - pose["y"]) < 0.05, (seen, pose)
            assert seen["pixel"] == hex_rgb(seen["color"]), seen  # really painted there
            start = (seen["x"], seen["y"])

            # 2. a click on the map is a goal row there, and the robot drives off
            click_world(browser, *GOAL)
            goal = await until(
                lambda: pool.fetchrow(
                    "SELECT id, x, y FROM goal WHERE robot_id = 'r1' AND status = 'active'"
                ),
                "the goal row the click writes",
                within=30,
            )
            assert math.hypot(goal["x"] - GOAL[0], goal["y"] - GOAL[1]) < 0.05, dict(goal)
            await until(
                lambda: f"goal {goal['id']} set" in browser.find_element(By.ID, "message").text,
                "the page to say the goal was set",
                within=30,
            )

            def moved() -> dict[str, Any] | None:
                now = drawn(browser)
                far = now and math.hypot(now["x"] - start[0], now["y"] - start[1]) > 0.3
                return now if far else None

            await until(moved, "the page to show r1 driving toward the goal", within=90)

            # 3. a strategy switch from the list is a user command the strategy service obeys
            Select(browser.find_element(By.ID, "strategy-select")).select_by_value("GOTO_DIRECT")
            browser.find_element(By.ID, "strategy-set").click()
            await until(
                lambda: pool.fetchval(
                    "SELECT strategy_code = 'GOTO_DIRECT' FROM active_strategy "
                    "WHERE robot_id = 'r1'"
                ),
                "the strategy service to switch r1 to GOTO_DIRECT",
                within=30,
            )
            await until(
                lambda: "GOTO_DIRECT accepted" in browser.find_element(By.ID, "message").text,
                "the page to say the switch was accepted",
                within=30,
            )
            await until(
                lambda: (
                    "strategy GOTO_DIRECT (user" in browser.find_element(By.ID, "timeline").text
                ),
                "the switch on the timeline",
                within=30,
            )

            # 4. a click on the decision shows its provenance, back to the sensor rows
            await until(
                lambda: browser.find_element(By.ID, "decision").get_attribute("data-decision"),
                "a decision",
            )
            browser.find_element(By.ID, "decision").click()
            provenance = browser.find_element(By.ID, "provenance")
            await until(provenance.is_displayed, "the provenance panel", within=30)
            await until(
                lambda: "← odometry" in provenance.text or "← laser_scan" in provenance.text,
                "the sensor rows behind the decision",
                within=30,
            )

            # 5. the page's form adds a strategy with no description (stored empty)
            form = browser.find_element(By.ID, "strategy-form")
            form.find_element(By.NAME, "code").send_keys("calm")
            form.find_element(By.CSS_SELECTOR, "button[type=submit]").click()
            await until(
                lambda: "strategy CALM added" in browser.find_element(By.ID, "message").text,
                "the page to say the strategy was added",
                within=30,
            )
            assert await pool.fetchval("SELECT description FROM strategy WHERE code = 'CALM'") == ""

            # 6. a row older than the contract's bounds (an owner's, params 3000 deep) is
            # listed as unreadable, and the page goes on
            await pool.execute(
                "ALTER TABLE strategy DROP CONSTRAINT strategy_params_bounded;"
                "INSERT INTO strategy (code, params) VALUES "
                "('DEEP', ('{\"k\": ' || repeat('[', 3000) || repeat(']', 3000) || '}')::jsonb);"
                "ALTER TABLE strategy ADD CONSTRAINT strategy_params_bounded "
                "CHECK (strategy_params_bounded(params)) NOT VALID"
            )
            option = "#strategy-select option[value=DEEP]"
            await until(
                lambda: browser.find_elements(By.CSS_SELECTOR, option),
                "the unreadable strategy in the list (the dashboard reads every table again)",
                within=30,
            )
            deep = browser.find_element(By.CSS_SELECTOR, option)
            assert deep.text == "DEEP (unreadable)" and not deep.is_enabled()
            assert drawn(browser) is not None

            # 7. a drag sets the heading: Shift+drag a waypoint facing up (+y), then a drag
            # to the right a goal facing +x, sent with the waypoint before it
            if browser.find_element(By.ID, "provenance").is_displayed():
                browser.find_element(By.ID, "provenance-close").click()
            drag_world(browser, 2.0, 2.5, 0, 40, shift=True)
            message = browser.find_element(By.ID, "message")
            try:
                await until(
                    lambda: "waypoint 1 placed" in message.text,
                    "the page to say the waypoint was placed",
                    within=30,
                )
            except AssertionError as exc:
                raise AssertionError(f"{exc}; it says {message.text!r}") from None
            drag_world(browser, *GOAL, 40, 0, shift=False)
            await until(
                lambda: "through 1 waypoint" in browser.find_element(By.ID, "message").text,
                "the page to say the goal pose was set",
                within=30,
            )
            posed = await pool.fetchrow(  # the newest goal (whatever the planner made of it)
                "SELECT id, x, y, yaw, yaw_tolerance_rad, status, reason FROM goal "
                "WHERE robot_id = 'r1' ORDER BY id DESC LIMIT 1"
            )
            assert abs(posed["yaw"]) < 0.05 and posed["yaw_tolerance_rad"] == 0.1, dict(posed)
            assert math.hypot(posed["x"] - GOAL[0], posed["y"] - GOAL[1]) < 0.05, dict(posed)
            waypoint = await pool.fetchrow(
                "SELECT seq, x, y, yaw FROM goal_waypoint WHERE goal_id = $1", posed["id"]
            )
            assert waypoint["seq"] == 1 and abs(waypoint["yaw"] - math.pi / 2) < 0.05
            assert math.hypot(waypoint["x"] - 2.0, waypoint["y"] - 2.5) < 0.05, dict(waypoint)

            shot = tmp_path / "dashboard.png"
            assert browser.save_screenshot(str(shot))
            assert shot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
            keep = os.environ.get("PNAV_DASHBOARD_SCREENSHOT")
            if keep:
                shutil.copyfile(shot, keep)
        finally:
            await rt.close()

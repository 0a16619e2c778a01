"""``petswarm watch`` in a real headless browser (Debian's chromium, driven by Selenium): the page loads,
shows the right number of robots, and they move as the run goes on, live from a hub and from a record."""

from __future__ import annotations

import re
import shutil
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from petswarm.lab.processes import Supervisor
from petswarm.lab.watch_frames import parse_replay

from ..waiting import wait_for
from .world_samples import write_record

pytestmark = pytest.mark.process

CHROMIUM = "/usr/bin/chromium"
CHROMEDRIVER = "/usr/bin/chromedriver"
ARTIFACTS = Path(__file__).resolve().parents[1] / "artifacts"
# without the background-networking flags chromium keeps calling out to hosts this machine cannot reach
CHROMIUM_FLAGS = (
    "--headless=new",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-dev-shm-usage",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--window-size=1400,850",
)


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    """Headless chromium under chromedriver, both named explicitly (nothing is downloaded)."""
    missing = [p for p in (CHROMIUM, CHROMEDRIVER) if not Path(p).exists()]
    if missing:
        pytest.skip(f"{', '.join(missing)} not installed (apt-get install chromium chromium-driver; .ci/run tries)")
    from selenium import webdriver
    from selenium.webdriver.chrome.options import Options
    from selenium.webdriver.chrome.service import Service

    options = Options()
    options.binary_location = CHROMIUM
    profile = tempfile.mkdtemp(prefix="petswarm-chromium-")
    for flag in (*CHROMIUM_FLAGS, f"--user-data-dir={profile}"):
        options.add_argument(flag)
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=options)
    try:
        yield driver
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)


def _start_watch(sup: Supervisor, *args: str) -> str:
    """``petswarm watch <args> --port 0``; the page's URL from its first line."""
    sup.spawn("watch", ["watch", *args, "--port", "0"])
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline:
        assert not sup.dead(), sup.log_tail("watch")
        found = re.search(r"watch: (http://\S+/)", sup.log_tail("watch"))
        if found:
            return found.group(1)
        time.sleep(0.1)
    raise AssertionError("petswarm watch did not start:\n" + sup.log_tail("watch"))


def _page(driver: Any) -> dict[str, Any]:
    """What the page shows: the robot counter, the frames it drew, each body's position from its row."""
    return driver.execute_script(
        """
        const rows = [...document.querySelectorAll('#bodies tr')];
        return {
          robots: document.getElementById('robot-count').textContent,
          frames: Number(document.body.dataset.frames),
          t_us: Number(document.body.dataset.tUs || -1),
          mode: document.body.dataset.mode,
          users: rows.filter(r => r.dataset.kind === 'user').length,
          user_x: Math.max(...rows.filter(r => r.dataset.kind === 'user').map(r => Number(r.dataset.x)), -1e9),
          positions: Object.fromEntries(rows.filter(r => r.dataset.kind === 'robot')
                                          .map(r => [r.dataset.id, [Number(r.dataset.x), Number(r.dataset.y)]])),
        };"""
    )


def _wait(driver: Any, test: Any, what: str, timeout: float = 15.0) -> dict[str, Any]:
    deadline = time.monotonic() + timeout
    page: dict[str, Any] = {}
    while time.monotonic() < deadline:
        page = _page(driver)
        if test(page):
            return page
        time.sleep(0.1)
    raise AssertionError(f"the page never showed {what}: {page}")


def _screenshot(driver: Any, name: str) -> Path:
    ARTIFACTS.mkdir(exist_ok=True)
    path = ARTIFACTS / name
    driver.save_screenshot(str(path))
    print(f"screenshot: {path}")
    return path


def _seek(driver: Any, fraction: float) -> None:
    """Drag the replay's timeline to ``fraction`` of the record, as a person would."""
    driver.execute_script(
        "const s = document.getElementById('timeline'); s.value = arguments[0]; s.dispatchEvent(new Event('input'));",
        round(1000 * fraction),
    )


def _fraction_of_the_walk(world_log: Path) -> float:
    """Where in the record, as a fraction of its span, the middle of the span with a user in the world lies."""
    frames = parse_replay(world_log.read_text().splitlines()).frames
    with_user = [f["t_us"] for f in frames if any(b["kind"] == "user" for b in f["bodies"])]
    assert with_user, f"{world_log} never shows the user"
    start, end = frames[0]["t_us"], frames[-1]["t_us"]
    return ((with_user[0] + with_user[-1]) / 2 - start) / (end - start)


def _still(browser) -> dict | None:
    """The page, when its model time did not move over 0.3 s; else None."""
    before = _page(browser)["t_us"]
    time.sleep(0.3)
    page = _page(browser)
    return page if page["t_us"] == before else None


def _moved(before: dict[str, list[float]], after: dict[str, list[float]]) -> bool:
    return any(abs(after[i][0] - xy[0]) + abs(after[i][1] - xy[1]) > 0.01 for i, xy in before.items() if i in after)


def test_the_replay_page_shows_every_robot_moving_and_pauses_and_seeks(browser, tmp_path):
    record = write_record(tmp_path / "run", frames=200, robots=4)
    sup = Supervisor(tmp_path / "logs")
    try:
        browser.get(_start_watch(sup, "--replay", str(record)))
        first = _wait(browser, lambda p: p["robots"] == "4" and len(p["positions"]) == 4, "4 robots")
        assert first["mode"] == "replay"
        later = _wait(browser, lambda p: p["t_us"] >= first["t_us"] + 500_000, "the replay going on")
        assert _moved(first["positions"], later["positions"])

        browser.find_element("id", "pause").click()
        # a frame already on its way may still land, later than any fixed wait on a loaded machine: take the
        # time once it stood still for 0.3 s (were the pause ignored, it never would), then check it holds
        held = wait_for("the replay paused", lambda: _still(browser), 10, every=0)["t_us"]
        time.sleep(0.6)
        assert _page(browser)["t_us"] == held  # paused: model time stands still

        browser.execute_script(
            "const s = document.getElementById('timeline'); s.value = 900; s.dispatchEvent(new Event('input'));"
        )
        _wait(browser, lambda p: p["t_us"] >= 0.85 * 199 * 100_000, "the frame sought on the timeline")
        time.sleep(0.3)
        _screenshot(browser, "watch-replay.png")
    finally:
        sup.stop_all()


SCENARIO = """
name = "watch-test"
duration_s = 60
[[obstacles]]
kind = "circle"
x = 2.0
y = 2.5
r = 0.4
[[obstacles]]
kind = "wall"
x0 = -1.0
y0 = -2.5
x1 = 6.0
y1 = -2.5
[user]
owner = 1
start = [0, 1, 0]
walk_at = 0
path = [ {walk = 30, speed = 1.0} ]
"""


def test_the_live_page_follows_a_real_run_and_replays_its_world_log(browser, make_air, tmp_path):
    scenario, world_log = tmp_path / "scenario.toml", tmp_path / "world.jsonl"
    scenario.write_text(SCENARIO)
    air = make_air(hub_args=("--scenario", str(scenario), "--world-log", str(world_log)))
    for rid, pos in {1: (0.0, -1.0), 2: (1.5, -1.0), 3: (3.0, -1.0)}.items():
        air.robot(rid, pos)
    where = ["--hub", air.endpoint, "--world", air.world]
    sup = Supervisor(tmp_path / "logs")
    try:
        browser.get(_start_watch(sup, *where))
        sup.spawn("user", ["user", "--scenario", str(scenario), *where])  # the person walks east at 1 m/s
        first = _wait(browser, lambda p: p["robots"] == "3" and p["users"] == 1, "3 robots and the user")
        assert first["mode"] == "live"
        later = _wait(browser, lambda p: p["frames"] >= first["frames"] + 10, "new frames arriving")
        assert later["t_us"] > first["t_us"]
        assert later["user_x"] > first["user_x"] + 0.3, (first, later)  # the walking user moved on the page
        _screenshot(browser, "watch-live.png")
    finally:
        sup.stop_all()
    air.close()  # the hub has written its world log: replay it

    sup = Supervisor(tmp_path / "logs-replay")
    try:
        browser.get(_start_watch(sup, "--replay", str(world_log)))
        # the robots attached before the user came: the replay opens on them alone
        _wait(browser, lambda p: p["robots"] == "3" and p["mode"] == "replay", "the replay")
        # seek to the middle of the user's walk rather than wait for it: when the user came in the live run
        # depends on how fast this machine started the processes
        _seek(browser, _fraction_of_the_walk(world_log))
        _wait(browser, lambda p: p["robots"] == "3" and p["users"] == 1, "the user walking in the replay")
    finally:
        sup.stop_all()

"""``petswarm watch`` in a real headless browser (Debian's chromium, driven by Selenium): the page loads,
shows the right number of robots, and they move as the run goes on, live from a hub and from a record."""

from __future__ import annotations

import re
import shutil
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import msgpack
import pytest

from cli.processes import Supervisor
from cli.watch import world_key
from radio_hub.interface import open_session

from .world_samples import frame, write_record

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
        time.sleep(0.3)  # a frame already on its way may still land
        held = _page(browser)["t_us"]
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


def _publish_frames(endpoint: str, world: str, robots: int, stop: threading.Event) -> None:
    """What the hub publishes: a frame every 0.1 s on the world key, until stopped."""
    from radio_hub.interface import Keys

    session = open_session("client", endpoint)
    try:
        key, k = world_key(Keys(world)), 0
        while not stop.is_set() and k < 600:
            session.put(key, msgpack.packb(frame(k, robots), use_bin_type=True))
            k += 1
            time.sleep(0.1)
    finally:
        session.close()


def test_the_live_page_follows_the_world_the_hub_publishes(browser, make_air, tmp_path):
    air = make_air()
    stop = threading.Event()
    publisher = threading.Thread(target=_publish_frames, args=(air.endpoint, air.world, 3, stop), daemon=True)
    sup = Supervisor(tmp_path / "logs")
    try:
        browser.get(_start_watch(sup, "--hub", air.endpoint, "--world", air.world))
        publisher.start()
        first = _wait(browser, lambda p: p["robots"] == "3" and len(p["positions"]) == 3, "3 robots")
        assert first["mode"] == "live"
        later = _wait(browser, lambda p: p["frames"] >= first["frames"] + 8, "new frames arriving")
        assert later["t_us"] > first["t_us"] and _moved(first["positions"], later["positions"])
        _screenshot(browser, "watch-live.png")
    finally:
        stop.set()
        publisher.join(5)
        sup.stop_all()

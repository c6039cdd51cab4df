"""Issue 20 item 3: the group page (headless Chromium) and ``--set`` on ``view`` and ``demo``."""
from __future__ import annotations

import json
import subprocess
import sys
import threading
import urllib.request

import pytest

import stereocam
from stereocam.tools.viewer.server import ViewerServer
from tests.support.browser import Chromium, find_chromium
from tests.support.hangs import terminated

CHROMIUM = find_chromium()
needs_browser = pytest.mark.skipif(CHROMIUM is None, reason="no Chromium on this machine (apt-get install chromium)")


@pytest.fixture(scope="module")
def browser():
    if CHROMIUM is None:
        pytest.skip("no Chromium on this machine")
    b = Chromium(CHROMIUM)
    yield b
    b.close()


@pytest.fixture
def group_viewer():
    """Two in-process heads on one trigger line driven by the first, viewed as a group."""
    from stereocam.device_sim import SimulatedCamera, TriggerLine
    from stereocam.tools.viewer.group_session import GroupViewerSession

    line = TriggerLine()
    sims = [SimulatedCamera(serial=f"GRP{i}", seed=50 + i, trigger_line=line) for i in range(2)]
    group = stereocam.CameraGroup([f"sim://?serial={s.serial}" for s in sims], settle=0.3, timeout=5.0,
                                  config=dict(width=160, height=120, num_disparities=16, block_size=9, fps=10))
    group.open()
    server = ViewerServer(GroupViewerSession(group))
    threading.Thread(target=server.serve_forever, kwargs={"poll_interval": 0.1}, daemon=True).start()
    yield server, sims, group
    server.shutdown()
    server.server_close()
    server.session.close()
    group.close()
    for s in sims:
        s.close()


def _page(browser: Chromium, url: str) -> str:
    page = browser.page(url)
    browser.wait_for(page, "document.querySelectorAll('img.head').length === 4 && "
                           "[...document.querySelectorAll('img.head')].every(i => i.naturalWidth > 0) && "
                           "document.getElementById('param-exposure_us') !== null")
    return page


@needs_browser
def test_a_head_that_misses_keeps_its_last_frame_marked_with_its_age(browser, group_viewer):
    server, sims, _ = group_viewer
    page = _page(browser, server.url)
    ticks = browser.evaluate(page, "[...document.querySelectorAll('#ticks span')].map(s => s.textContent)")
    assert ticks and all(t.endswith(" m") for t in ticks)  # the colour bar, in metres
    sims[1].trigger_input.miss_next = 10_000  # GRP1 misses every edge from now on
    badge = browser.wait_for(page, "document.getElementById('fig-GRP1-left').classList.contains('missed') && "
                                   "document.querySelector('#fig-GRP1-left .badge').textContent")
    assert badge.startswith("missed trigger") and " s old" in badge
    browser.wait_for(page, "document.getElementById('trigger-id').textContent > "
                           "document.getElementById('fig-GRP1-left').dataset.trigger")
    assert browser.evaluate(page, "[...document.querySelectorAll('#fig-GRP1-left img, #fig-GRP1-disparity img')]"
                                  ".every(i => i.complete && i.naturalWidth > 0)")  # its last frame, not a 404
    assert not browser.evaluate(page, "document.getElementById('fig-GRP0-left').classList.contains('missed')")


@needs_browser
def test_start_stop_trigger_and_settings_for_every_head(browser, group_viewer):
    server, _, group = group_viewer
    page = _page(browser, server.url)
    heads = list(group.cameras.values())

    def click(element_id: str) -> str:
        before = browser.evaluate(page, "document.getElementById('action').textContent")
        browser.evaluate(page, f"document.getElementById({element_id!r}).click()")
        return browser.wait_for(page, f"document.getElementById('action').textContent !== {json.dumps(before)} && "
                                      "document.getElementById('action').textContent")

    browser.evaluate(page, "(() => { const i = document.getElementById('in-gain'); i.value = 40; "
                           "i.dispatchEvent(new Event('change')); })()")
    browser.wait_for(page, "document.querySelector('#param-gain .reason').textContent === 'gain = 40'")
    assert [c.config()["gain"] for c in heads] == [40, 40]
    browser.evaluate(page, "(() => { const i = document.getElementById('in-width'); i.value = 320; "
                           "i.dispatchEvent(new Event('change')); })()")  # only a stopped head takes it
    reason = browser.wait_for(page, "document.querySelector('#param-width .reason').textContent.includes('refused') "
                                    "&& document.querySelector('#param-width .reason').textContent")
    assert "camera GRP0" in reason and [c.config()["width"] for c in heads] == [160, 160]
    assert browser.evaluate(page, "document.getElementById('in-width').value") == "160"  # snapped back
    assert browser.evaluate(page, "document.getElementById('param-trigger_mode')") is None  # the group's own

    assert "refused" in click("trigger")  # streaming: the master triggers already
    assert click("stop") == "stop: done" and not any(c.streaming for c in heads)
    browser.wait_for(page, "document.getElementById('streaming').textContent === 'no'")
    shown = int(browser.evaluate(page, "document.getElementById('trigger-id').textContent"))
    assert click("trigger").startswith("one set: trigger ")
    browser.wait_for(page, f"Number(document.getElementById('trigger-id').textContent) > {shown}")
    assert not any(c.streaming for c in heads)
    assert click("start") == "start: done" and all(c.streaming for c in heads)


def test_view_with_several_urls_sets_every_head():
    from stereocam.device_sim.process import ServedSimulator

    line = f"viewset-{id(object())}"
    servers = [ServedSimulator("tcp:127.0.0.1:0", seed=60 + i, extra=["--trigger-line", line]) for i in range(2)]
    try:
        proc = subprocess.Popen([sys.executable, "-m", "stereocam.tools.cli", "view", *(s.url for s in servers),
                                 "--no-browser", "--set", "fps=4", "--set", "width=320", "--set", "height=240"],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            url = proc.stdout.readline().strip()
            assert url.startswith("http://127.0.0.1:"), proc.stderr.read()
            state = json.loads(urllib.request.urlopen(url + "api/group/state", timeout=30).read())
            assert state["config_names"]["fps"] == 4 and state["config_names"]["width"] == 320
        finally:
            assert (rc := terminated(proc)) == 0, (rc, proc.stderr.read())
    finally:
        for srv in servers:
            srv.stop()


def test_demo_set_reaches_the_camera_and_a_refused_value_is_a_message(tmp_path):
    r = subprocess.run([sys.executable, "-m", "stereocam.tools.cli", "demo", "--out", str(tmp_path), "--seconds", "0.5",
                        "--set", "gain=999"], capture_output=True, text=True, timeout=300)
    assert r.returncode != 0 and "gain=999" in r.stderr and "Traceback" not in r.stderr

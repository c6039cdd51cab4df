"""Issue 20 item 1: the viewer page shows the camera's real state, driven in headless Chromium.

One browser for the module (starting Chromium is the slow part); a fresh simulated camera and
viewer per test. Every assertion compares what the page shows with what the camera holds."""
from __future__ import annotations

import io
import json
import threading
import urllib.request

import cv2
import numpy as np
import pytest

import stereocam
from stereocam.protocol.params import BY_NAME, Output
from stereocam.tools.viewer.server import ViewerServer
from stereocam.tools.viewer.session import ViewerSession
from stereocam.tools.viewer.settings import OTHER, group_of
from tests.support.browser import Chromium, find_chromium
from tests.support.device import SMALL
from tests.support.waiting import stays, wait_until

CHROMIUM = find_chromium()
pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="no Chromium on this machine (apt-get install chromium)")


@pytest.fixture(scope="module")
def browser():
    b = Chromium(CHROMIUM)
    yield b
    b.close()


@pytest.fixture
def viewer(tmp_path):
    cam = stereocam.open("sim://?seed=6", timeout=2.0)
    cam.configure(**SMALL, fps=10)
    server = ViewerServer(ViewerSession(cam, tmp_path))
    threading.Thread(target=server.serve_forever, kwargs={"poll_interval": 0.1}, daemon=True).start()
    cam.start()
    yield server
    server.shutdown()
    server.server_close()
    server.session.close()
    cam.close()


class Page:
    """The viewer's page in a tab of the shared browser."""

    def __init__(self, browser: Chromium, url: str):
        self.browser = browser
        self.session = browser.page(url)
        self.wait("document.getElementById('left').naturalWidth > 0 && "
                  "document.getElementById('param-exposure_us') !== null")

    def js(self, expression: str):
        return self.browser.evaluate(self.session, expression)

    def wait(self, expression: str, timeout: float = 60.0):
        return self.browser.wait_for(self.session, expression, timeout)

    def text(self, element_id: str) -> str:
        return self.js(f"document.getElementById({element_id!r}).textContent")

    def set(self, name: str, value: object) -> None:
        """Type ``value`` into a setting's control (a number field or a menu) and leave it."""
        self.js(f"(() => {{ const i = document.getElementById('in-{name}'); i.value = {json.dumps(str(value))}; "
                f"i.dispatchEvent(new Event('change')); }})()")

    def enter(self, name: str) -> None:
        """Press Enter in a setting's field (without changing it)."""
        self.js(f"document.getElementById('in-{name}').dispatchEvent(new KeyboardEvent('keydown', {{key: 'Enter'}}))")

    def shown(self, name: str) -> str:
        return self.js(f"document.getElementById('in-{name}').value")

    def reason(self, name: str) -> str:
        return self.js(f"document.querySelector('#param-{name} .reason').textContent")

    def click(self, element_id: str) -> None:
        self.js(f"document.getElementById({element_id!r}).click()")

    def refreshes(self, count: int) -> None:
        """Wait until the page has refreshed the camera's state ``count`` more times."""
        for _ in range(count):
            t = self.js("lastCounters.t")
            self.wait(f"lastCounters.t > {t}")


@pytest.fixture
def page(browser, viewer):
    p = Page(browser, viewer.url)
    yield p
    browser.send("Target.closeTarget", {"targetId": browser.send("Target.getTargets")["targetInfos"][-1]["targetId"]})


def _get(url: str) -> bytes:
    with urllib.request.urlopen(url, timeout=30) as r:
        return r.read()


def test_a_refused_value_snaps_back_with_its_reason_until_the_next_change(viewer, page):
    cam = viewer.session.cam
    page.set("trigger_mode", 1)  # software: only a stopped camera takes it
    page.wait("document.querySelector('#param-trigger_mode .reason').textContent.includes('refused')")
    assert cam.config()["trigger_mode"] == 0 and page.shown("trigger_mode") == "0"  # the camera's, not the refused
    page.refreshes(2)
    assert "refused" in page.reason("trigger_mode") and page.shown("trigger_mode") == "0"  # still said
    page.set("block_size", 10)
    page.wait("document.querySelector('#param-block_size .reason').textContent.includes('must be odd')")
    assert page.shown("block_size") == str(cam.config()["block_size"]) == str(SMALL["block_size"])
    page.set("block_size", 13)  # the next change clears the reason
    page.wait("document.querySelector('#param-block_size .reason').textContent.includes('= 13')")
    assert cam.config()["block_size"] == 13


def test_enter_on_an_unchanged_field_sends_it_and_a_cleared_field_sends_nothing(viewer, page):
    cam = viewer.session.cam
    page.enter("gain")  # unchanged: the camera's value again, answered
    page.wait("document.querySelector('#param-gain .reason').textContent === 'gain = 0'")
    page.set("gain", "")
    page.wait("document.querySelector('#param-gain .reason').textContent.includes('not sent')")
    assert cam.config()["gain"] == 0 and page.shown("gain") == "0"


def test_a_refused_trigger_keeps_its_reason_past_the_state_refresh(viewer, page):
    page.click("trigger")  # free-run mode: the device refuses
    reason = page.wait("document.getElementById('action').textContent.includes('refused') && "
                       "document.getElementById('action').textContent")
    page.refreshes(2)
    assert page.text("action") == reason and "trigger" in reason


def test_settings_are_grouped_with_named_choices_and_proper_units(viewer, page):
    groups = page.js("[...document.querySelectorAll('#config fieldset')].map(f => f.id)")
    assert groups[:5] == ["group-capture", "group-matching", "group-post-processing", "group-trigger", "group-link"]
    assert page.js("document.querySelector('#group-post-processing #param-speckle_window_size') !== null")
    assert page.js("document.querySelector('#group-trigger #param-trigger_mode') !== null")
    names = page.js("[...document.querySelectorAll('#in-trigger_mode option')].map(o => o.textContent)")
    assert names == ["free_run (default)", "software", "external"]
    assert page.js("[...document.querySelectorAll('#in-algorithm option')].map(o => o.value)") == ["0", "1"]
    assert "µs" in page.js("document.querySelector('#param-exposure_us .range').textContent")
    planes = [bool(BY_NAME["outputs"].default & plane) for plane in Output]  # a box per plane, the default ticked
    assert page.js("[...document.querySelectorAll('#in-outputs input')].map(i => i.checked)") == planes
    assert group_of("temporal_alpha") == group_of("lr_check") == group_of("hole_fill") == "post-processing"
    assert group_of("a_future_setting") == OTHER


def test_reset_to_defaults_and_presets_saved_and_loaded(viewer, page, tmp_path):
    cam = viewer.session.cam
    page.set("gain", 50)
    page.wait("document.querySelector('#param-gain .reason').textContent === 'gain = 50'")
    page.js("document.getElementById('preset-name').value = 'bench'")
    page.click("preset-save")
    page.wait("document.getElementById('preset-note').textContent.includes('saved')")
    assert json.loads((tmp_path / "bench.preset.json").read_text())["config"]["gain"] == 50
    page.wait("[...document.querySelectorAll('#preset-list option')].some(o => o.value === 'bench')")
    page.set("exposure_us", 2500)
    page.click("reset")
    page.wait("document.getElementById('preset-note').textContent.includes('default')")
    assert cam.config()["gain"] == 0 and cam.config()["exposure_us"] == 4000 and cam.streaming
    page.wait("document.getElementById('in-gain').value === '0'")
    page.click("preset-load")
    page.wait("document.getElementById('preset-note').textContent.includes('loaded')")
    assert cam.config()["gain"] == 50 and cam.config()["width"] == SMALL["width"]
    page.wait("document.getElementById('in-gain').value === '50'")


def test_images_fill_the_window(browser, viewer, page):
    widths = []
    for width in (1200, 2400):
        browser.send("Emulation.setDeviceMetricsOverride", {"width": width, "height": 900, "deviceScaleFactor": 1,
                                                            "mobile": False}, page.session)
        widths.append(page.js("document.getElementById('left').getBoundingClientRect().width"))
    assert widths[1] > 1.5 * widths[0] and widths[1] > 500


def test_counters_table_histogram_and_near_far_range(viewer, page):
    page.refreshes(2)
    fps_rate = page.js("Number(document.querySelector('#counters tr[data-name=\"frames\"]').cells[2].textContent)")
    assert fps_rate > 0
    hist = page.js("current.histogram")
    assert sum(hist["counts"]) > 0 and hist["near_m"] < hist["far_m"]
    for field, value in (("near", 1), ("far", 3)):  # typed: each an input event, near losing focus to far
        page.js(f"(() => {{ const e = document.getElementById('{field}'); e.focus(); e.value = {value}; "
                f"e.dispatchEvent(new Event('input')); }})()")
    page.js("document.activeElement.blur()")  # the user looks at the image before pressing Apply
    page.refreshes(3)  # the redraws of new frames must not put the typed values back
    assert page.js("[document.getElementById('near').value, document.getElementById('far').value]") == ["1", "3"]
    page.click("range-apply")
    wait_until(lambda: viewer.session.span_m == (1.0, 3.0), timeout=10, what="the range applied")
    page.wait("current.histogram.near_m === 1 && current.histogram.far_m === 3")
    ticks = page.js("current.colorbar.ticks.map(t => t.metres)")
    assert ticks and all(1 <= t <= 3 for t in ticks)


def test_planes_that_stop_coming_are_marked(viewer, page):
    cam = viewer.session.cam
    page.js("(() => { const f = document.getElementById('in-outputs'); "
            "f.querySelectorAll('input')[1].checked = false; f.querySelectorAll('input')[2].checked = false; "
            "f.dispatchEvent(new Event('change')); })()")
    wait_until(lambda: cam.config()["outputs"] == 1, timeout=10, what="outputs=1")
    badge = page.wait("document.getElementById('badge-disparity').textContent.startsWith('off') && "
                      "document.getElementById('badge-disparity').textContent")
    assert page.js("document.getElementById('fig-disparity').classList.contains('absent')")
    assert "off" in badge and "outputs=1" in badge and "last seen" in badge
    assert page.js("document.getElementById('fig-right').classList.contains('absent')")
    assert not page.js("document.getElementById('fig-left').className")


def test_a_camera_waiting_for_an_external_trigger_says_so(viewer, page):
    cam = viewer.session.cam
    cam.stop()
    cam.configure(trigger_mode=2)  # nothing drives this unit's trigger line
    cam.start()
    waiting = page.wait("document.getElementById('waiting').textContent.includes('no pulse seen') && "
                        "document.getElementById('waiting').textContent")
    assert waiting.startswith("waiting for external trigger")
    assert page.js("document.getElementById('in-trigger_mode').value") == "2"


def test_raw_snapshots_are_data(viewer):
    wait_until(lambda: viewer.session.newest(wait=1), timeout=30, what="a frame")
    viewer.session.cam.stop()  # every snapshot of the same frame
    png16 = cv2.imdecode(np.frombuffer(_get(viewer.url + "snapshot/disparity16.png"), np.uint8), cv2.IMREAD_UNCHANGED)
    assert png16.dtype == np.uint16 and png16.shape == (240, 320) and png16.max() > 0
    raw = np.load(io.BytesIO(_get(viewer.url + "snapshot/disparity.npy")))
    assert raw.dtype == np.int16 and raw.shape == (240, 320)
    assert np.array_equal(png16, np.where(raw < 0, 0, raw).astype(np.uint16))  # the same frame, same units
    ply = _get(viewer.url + "snapshot/points.ply?colour=depth")
    header, _, body = ply.partition(b"end_header\n")
    n = int(header.split(b"element vertex ")[1].split(b"\n")[0])
    rec = np.frombuffer(body, dtype=[("xyz", "<f4", 3), ("rgb", "u1", 3)])
    assert len(rec) == n > 1000 and b"property uchar red" in header
    assert len({tuple(c) for c in rec["rgb"][::50]}) > 5 and np.any(rec["rgb"][:, 0] != rec["rgb"][:, 2])  # colour


def _canvas_pixels(browser: Chromium, page: Page) -> np.ndarray:
    """The 3-D view's canvas as it is on screen (RGB), cut from a screenshot of the page."""
    box = json.loads(page.js("JSON.stringify(document.getElementById('cloud').getBoundingClientRect())"))
    shot = cv2.imdecode(np.frombuffer(browser.screenshot(page.session), np.uint8), cv2.IMREAD_COLOR)[:, :, ::-1]
    x, y = int(box["x"]) + 2, int(box["y"]) + 2
    return shot[y:y + int(box["height"]) - 4, x:x + int(box["width"]) - 4]


def _drawn(pixels: np.ndarray) -> np.ndarray:
    return np.any(np.abs(pixels.astype(int) - 26) > 6, axis=2)  # not the background (#1a1a1a)


def test_the_3d_view_draws_the_point_cloud_orbits_and_colours_by_the_left_image(browser, viewer, page):
    page.wait("cloud.drawn > 1000")
    before = _canvas_pixels(browser, page)
    assert _drawn(before).mean() > 0.2  # a non-empty cloud on screen
    assert np.abs(before[..., 0].astype(int) - before[..., 2]).max() > 60  # coloured by depth
    viewer.session.cam.stop()  # one frame from here on: only the orbit changes the picture
    # A frame already on its way when the stream stopped can still land after stop() returns: wait
    # until the page shows whatever the session holds newest, read again on every poll.
    wait_until(lambda: page.js("cloud.sequence") == viewer.session.newest(wait=0).sequence,
               timeout=60.0, what="the 3-D view shows the session's newest frame")
    page.js("cloud.draw()")
    still = _canvas_pixels(browser, page)
    box = json.loads(page.js("JSON.stringify(document.getElementById('cloud').getBoundingClientRect())"))
    x, y = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
    for kind, dx in (("mousePressed", 0), ("mouseMoved", 80), ("mouseReleased", 80)):
        browser.send("Input.dispatchMouseEvent", {"type": kind, "x": x + dx, "y": y, "button": "left",
                                                  "buttons": 1 if kind != "mouseReleased" else 0, "clickCount": 1},
                     page.session)
    page.wait("cloud.yaw > 0.5")
    turned = _canvas_pixels(browser, page)
    assert _drawn(turned).mean() > 0.05 and np.abs(turned.astype(int) - still).mean() > 5  # seen from aside
    page.js("(() => { const s = document.getElementById('cloud-colour'); s.value = 'left'; "
            "s.dispatchEvent(new Event('change')); })()")
    page.wait("cloud.rgb !== null && cloud.rgb[0] === cloud.rgb[1] && cloud.rgb[1] === cloud.rgb[2] && "
              "cloud.rgb[30] === cloud.rgb[31]")
    grey = _canvas_pixels(browser, page)
    mask = _drawn(grey)
    assert mask.mean() > 0.05 and np.abs(grey[mask][:, 0].astype(int) - grey[mask][:, 2]).max() <= 2


def test_a_state_asked_before_stop_recording_was_answered_does_not_undo_the_saved_line(viewer, page, monkeypatch):
    """The page asks for the state every second while Stop is clicked, and the server answers in
    parallel: a state taken while still recording, answered after the stop, put the button back to
    'Stop recording' and then blanked the 'saved' line (a full-suite run waited 60 s for it)."""
    session = viewer.session
    page.js("document.getElementById('record').click()")
    page.wait("document.getElementById('record').textContent === 'Stop recording'")
    real, held, entered, release = session.recording, [], threading.Event(), threading.Event()

    def recording():
        state = real()
        if not held and state is not None:  # the first state taken from now on: answered late
            held.append(state)
            entered.set()
            release.wait(30)
        return state

    monkeypatch.setattr(session, "recording", recording)
    try:
        wait_until(entered.is_set, timeout=30, what="a state request taken while recording")
        page.js("document.getElementById('record').click()")
        page.wait("document.getElementById('recording').textContent.startsWith('saved')")
    finally:
        release.set()  # the old state's answer arrives now, after the stop's
    assert stays(lambda: page.js("document.getElementById('recording').textContent").startswith("saved")
                 and page.js("document.getElementById('record').textContent") == "Record", 2.5)

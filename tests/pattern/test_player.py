"""player.html in a real browser: Debian's chromium, headless, at devicePixelRatio 1 and 2

Every loop entry of the player (the default sequence: the start marker, 8
rotating-star frames, 13 identity frames, the checkerboard), screenshotted
through the DevTools protocol (over --remote-debugging-pipe, a minimal client
below), must equal its PNG pixel for pixel; the check screen's 1-px stripes must be exact; the warning
must appear when the page cannot map one pattern pixel to one device pixel.
Skipped, with the reason, where /usr/bin/chromium is absent (Debian package
`chromium`, installed by the Makefile's test set-up).
"""

from __future__ import annotations

import base64
import json
import os
import select
import shutil
import subprocess
import sys
import tempfile

import cv2
import numpy as np
import pytest

from rotstar_mrcal.pattern.loop import expected_levels, player_loop
from rotstar_mrcal.pattern.player import player_config, render_player
from rotstar_mrcal.pattern.layout import layout_from_dict

CHROMIUM = os.environ.get("ROTSTAR_CHROMIUM", "/usr/bin/chromium")
needs_chromium = pytest.mark.skipif(
    not os.access(CHROMIUM, os.X_OK),
    reason=f"{CHROMIUM} not found: install Debian's chromium (apt-get install chromium; the Makefile's "
    "test set-up does) to run the browser tests of player.html",
)
TIMEOUT = 120.0


class Chromium:
    """Headless chromium driven over the DevTools protocol on fds 3 and 4

    SYNOPSIS

        with Chromium(1180, 820, dpr=2) as b:
            b.load("file:///tmp/pattern/player.html")
            b.evaluate("rotstar.show(3)")
            img = b.screenshot()                 # (1640, 2360, 3) uint8, BGR
    """

    def __init__(self, width: int, height: int, dpr: float = 1.0, screen: tuple[int, int] | None = None):
        self.profile = tempfile.mkdtemp(prefix="rotstar-chromium-")
        to_child_r, self._to_child = os.pipe()
        self._from_child, from_child_w = os.pipe()

        def fds():  # in the child: commands on fd 3, replies on fd 4
            a, b = os.dup(to_child_r), os.dup(from_child_w)
            os.dup2(a, 3)
            os.dup2(b, 4)

        self.proc = subprocess.Popen(
            [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
             "--disable-component-update", "--no-first-run", "--no-default-browser-check",
             "--disable-extensions", "--disable-sync", "--mute-audio", "--hide-scrollbars",
             f"--user-data-dir={self.profile}", "--remote-debugging-pipe",
             f"--window-size={width},{height}", f"--force-device-scale-factor={dpr}", "about:blank"],
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            pass_fds=(3, 4), preexec_fn=fds)
        os.close(to_child_r)
        os.close(from_child_w)
        self._buf = b""
        self._id = 0
        self.events: list[dict] = []
        try:
            page = next(t for t in self._call("Target.getTargets")["targetInfos"] if t["type"] == "page")
            self.session = self._call("Target.attachToTarget", {"targetId": page["targetId"], "flatten": True})["sessionId"]
            self.call("Page.enable")
            self.emulate(width, height, dpr, screen)
        except Exception:
            self.close()
            raise

    def emulate(self, width: int, height: int, dpr: float, screen: tuple[int, int] | None = None) -> None:
        """Viewport width x height CSS px at this devicePixelRatio (takes effect at the next load)"""
        sw, sh = screen or (width, height)
        self.call("Emulation.setDeviceMetricsOverride", {
            "width": width, "height": height, "deviceScaleFactor": float(dpr), "mobile": False,
            "screenWidth": sw, "screenHeight": sh})

    # ---- protocol --------------------------------------------------------
    def _message(self) -> dict:
        while b"\0" not in self._buf:
            r, _, _ = select.select([self._from_child], [], [], TIMEOUT)
            chunk = os.read(self._from_child, 1 << 20) if r else b""
            if not chunk:
                raise RuntimeError("chromium stopped answering" if not r else "chromium closed the pipe")
            self._buf += chunk
        msg, self._buf = self._buf.split(b"\0", 1)
        return json.loads(msg)

    def _call(self, method: str, params: dict | None = None, session: str | None = None) -> dict:
        self._id += 1
        msg = {"id": self._id, "method": method, "params": params or {}}
        if session:
            msg["sessionId"] = session
        os.write(self._to_child, json.dumps(msg).encode() + b"\0")
        while True:
            m = self._message()
            if m.get("id") == self._id:
                if "error" in m:
                    raise RuntimeError(f"{method}: {m['error']}")
                return m["result"]
            self.events.append(m)

    def call(self, method: str, params: dict | None = None) -> dict:
        return self._call(method, params, self.session)

    def wait_event(self, method: str) -> dict:
        while True:
            for i, e in enumerate(self.events):
                if e.get("method") == method:
                    return self.events.pop(i)
            self.events.append(self._message())

    # ---- page ------------------------------------------------------------
    def load(self, url: str) -> dict:
        """Open the player and wait until it decoded its frames; returns rotstar.status()"""
        self.events.clear()
        self.call("Page.navigate", {"url": url})
        self.wait_event("Page.loadEventFired")
        return self.evaluate("rotstar.ready")

    def evaluate(self, expr: str):
        r = self.call("Runtime.evaluate", {"expression": expr, "awaitPromise": True, "returnByValue": True})
        if "exceptionDetails" in r:
            raise RuntimeError(f"{expr}: {r['exceptionDetails']}")
        return r["result"].get("value")

    def screenshot(self) -> np.ndarray:
        self.evaluate("new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))")
        png = base64.b64decode(self.call("Page.captureScreenshot", {"format": "png", "optimizeForSpeed": True})["data"])
        return cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)

    def key(self, key: str, code: str | None = None, vk: int = 0) -> None:
        for t in ("keyDown", "keyUp"):
            self.call("Input.dispatchKeyEvent", {"type": t, "key": key, "code": code or key,
                                                 "windowsVirtualKeyCode": vk, "text": key if len(key) == 1 else ""})

    def close(self) -> None:
        try:
            if self.proc.poll() is None:
                try:
                    self._call("Browser.close")
                except Exception:
                    pass
                try:
                    self.proc.wait(10)
                except subprocess.TimeoutExpired:
                    self.proc.kill()
                    self.proc.wait()
        finally:
            for fd in (self._to_child, self._from_child):
                try:
                    os.close(fd)
                except OSError:
                    pass
            shutil.rmtree(self.profile, ignore_errors=True)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


# ---- fixtures --------------------------------------------------------------
@pytest.fixture(scope="module")
def ipad(tmp_path_factory):
    """rotstar-pattern's default output (an 11-inch iPad Pro, 2360x1640), player.html included"""
    out = tmp_path_factory.mktemp("pattern")
    r = subprocess.run([sys.executable, "-m", "rotstar_mrcal.cli.pattern", "--out", str(out)],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "player.html" in r.stderr
    return out


@pytest.fixture(scope="module")
def browsers():
    """One headless chromium per devicePixelRatio, started with --force-device-scale-factor"""
    if not os.access(CHROMIUM, os.X_OK):
        pytest.skip(f"{CHROMIUM} not found")
    started = {}

    def get(dpr: int) -> Chromium:
        if dpr not in started:
            started[dpr] = Chromium(2360 // dpr, 1640 // dpr, dpr)
        return started[dpr]

    yield get
    for b in started.values():
        b.close()


def loop_images(folder) -> list[np.ndarray]:
    """What every loop entry must look like: the start marker black, then the PNGs"""
    d = json.loads((folder / "pattern.json").read_text())
    out = []
    for e in player_loop(d["frames"]):
        if e["file"] is None:
            out.append(np.zeros((d["screen"]["height"], d["screen"]["width"]), np.uint8))
        else:
            out.append(cv2.imread(str(folder / e["file"]), cv2.IMREAD_UNCHANGED))
    return out


def expected_panel(kind: str, x0: int, y0: int, x1: int, y1: int) -> np.ndarray:
    y, x = np.mgrid[y0:y1, x0:x1]
    v = {"vstripes": x & 1, "hstripes": y & 1, "checker1": (x + y) & 1,
         "checker2": ((x >> 1) + (y >> 1)) & 1}[kind]
    return (v * 255).astype(np.uint8)


def assert_gray_equal(shot: np.ndarray, want: np.ndarray, what: str) -> None:
    assert shot.shape[:2] == want.shape, f"{what}: screenshot {shot.shape[1]}x{shot.shape[0]}, want {want.shape[1]}x{want.shape[0]}"
    bad = np.any(shot != want[..., None], axis=-1)
    assert not bad.any(), (f"{what}: {int(bad.sum())} pixels differ, first at (x, y) = "
                           f"{tuple(int(v) for v in np.argwhere(bad)[0][::-1])}")


# ---- tests without a browser -----------------------------------------------
def test_player_config_embeds_the_loop(ipad):
    d = json.loads((ipad / "pattern.json").read_text())
    html = (ipad / "player.html").read_text()
    assert "/*ROTSTAR-CONFIG*/" not in html
    cfg = json.loads(html.split('<script id="rotstar-config" type="application/json">')[1].split("</script>")[0])
    assert (cfg["width"], cfg["height"]) == (2360, 1640)
    assert [e["file"] for e in cfg["loop"]] == [None] + [f["file"] for f in d["frames"]]
    # the default sequence: the start marker, 8 rotating-star frames, 13 identity frames, the checkerboard
    assert [e["kind"] for e in cfg["loop"]] == ["start-marker"] + ["rotstar"] * 8 + ["identity"] * 13 + ["checkerboard"]
    assert cfg["loop"][9]["file"] == "identity_00.png"
    png = base64.b64decode(cfg["loop"][1]["src"].split(",", 1)[1])
    assert png == (ipad / d["frames"][0]["file"]).read_bytes()
    with pytest.raises(ValueError, match="no PNG"):
        player_config(d, {})


def test_expected_levels_match_the_pngs(ipad):
    """The closed-form mean luminance of each loop entry equals the rendered frames' mean"""
    from rotstar_mrcal.pattern.render import decode_display

    d = json.loads((ipad / "pattern.json").read_text())
    layout = layout_from_dict(d)
    lev = expected_levels(layout, player_loop(d["frames"]))
    got = [float(decode_display(im).mean()) for im in loop_images(ipad)]
    assert lev[0] == 0.0
    np.testing.assert_allclose(lev, got, atol=2e-3)


# ---- browser tests ---------------------------------------------------------
@pytest.mark.slow  # make test-slow: an end-to-end run, left out of make test
@needs_chromium
@pytest.mark.parametrize("dpr", [1, 2])
def test_frames_pixel_exact(ipad, browsers, dpr):
    want = loop_images(ipad)
    H, W = want[0].shape
    b = browsers(dpr)
    b.emulate(W // dpr, H // dpr, dpr)
    st = b.load((ipad / "player.html").as_uri())
    assert st["mode"] == "check" and st["ok"], st["problems"]
    assert st["dpr"] == dpr and st["page"] == [W, H]
    assert len(want) == st["entries"] == 23 and st["kinds"].count("identity") == 13
    for k, img in enumerate(want):
        assert b.evaluate(f"rotstar.show({k})")
        assert_gray_equal(b.screenshot(), img, f"DPR {dpr}, loop entry {k} ({st['files'][k]})")


@needs_chromium
@pytest.mark.parametrize("dpr", [1, 2])
def test_check_screen_stripes_exact(ipad, browsers, dpr):
    W, H = 2360, 1640
    b = browsers(dpr)
    b.emulate(W // dpr, H // dpr, dpr)
    st = b.load((ipad / "player.html").as_uri())
    assert st["ok"], st["problems"]
    shot = b.screenshot()
    text = b.evaluate("document.getElementById('status').textContent")
    assert text == "check: OK"
    panels = b.evaluate("rotstar.checkPanels()")
    assert {p["kind"] for p in panels} == {"vstripes", "hstripes", "checker1", "checker2"}
    for p in panels:
        x0, y0, x1, y1 = p["x0"], p["y0"], p["x1"], p["y1"]
        assert x1 - x0 > W // 3 and y1 - y0 > H // 5
        assert_gray_equal(shot[y0:y1, x0:x1], expected_panel(p["kind"], x0, y0, x1, y1), f"DPR {dpr} {p['kind']}")
    # the one-pixel white frame along the screen edge, and the "OK" box (#042) between the panels
    assert np.all(shot[0] == 255) and np.all(shot[-1] == 255) and np.all(shot[:, 0] == 255) and np.all(shot[:, -1] == 255)
    assert np.all(shot[1:8, 1:-1] == 24)
    assert tuple(shot[H // 2, 9]) == (0x22, 0x44, 0x00)


@pytest.mark.slow  # make test-slow: an end-to-end run, left out of make test
@needs_chromium
def test_warning_fractional_dpr_and_wrong_size(ipad, browsers):
    url = (ipad / "player.html").as_uri()
    b = browsers(1)
    # browser zoom / display scaling 150 %
    b.emulate(1573, 1093, 1.5)
    st = b.load(url)
    assert not st["ok"]
    assert any("devicePixelRatio is 1.5" in p for p in st["problems"]), st["problems"]
    assert "WARNING" in b.evaluate("document.getElementById('status').textContent")
    shot = b.screenshot()
    assert tuple(shot[shot.shape[0] // 2, 9]) == (0, 0, 0x44)  # the red box of the warning
    # a smaller page (not full screen) on a screen of the right size, then portrait
    b.emulate(1280, 800, 1, screen=(2360, 1640))
    st = b.load(url)
    assert not st["ok"] and any("smaller than the pattern's 2360 x 1640" in p and "cut off" in p
                                for p in st["problems"]), st["problems"]
    assert not any("this screen is" in p for p in st["problems"])
    b.emulate(1640, 2360, 1)
    st = b.load(url)
    assert any("portrait" in p for p in st["problems"]), st["problems"]
    # a screen that is not the one of pattern.json
    b.emulate(1920, 1080, 1)
    st = b.load(url)
    assert any("this screen is 1920 x 1080" in p for p in st["problems"]), st["problems"]
    # pinch zoom
    b.emulate(2360, 1640, 1)
    assert b.load(url)["ok"]
    b.call("Emulation.setPageScaleFactor", {"pageScaleFactor": 2})
    st = b.evaluate("new Promise(r => requestAnimationFrame(() => requestAnimationFrame(() => r(rotstar.status()))))")
    b.call("Emulation.setPageScaleFactor", {"pageScaleFactor": 1})
    assert any("pinch-zoomed (scale 2.00)" in p for p in st["problems"]), st["problems"]


def played_runs(b, refreshes: int) -> list[list[int]]:
    """[entry, refreshes shown] of each run of equal positions of the playing player, over this many animation frames"""
    seq = b.evaluate(f"""new Promise(done => {{
        const out = []; const f = () => {{ out.push(rotstar.status().pos);
          if (out.length < {refreshes}) requestAnimationFrame(f); else done(out); }};
        requestAnimationFrame(f); }})""")
    runs = []
    for p in seq:
        if runs and runs[-1][0] == p:
            runs[-1][1] += 1
        else:
            runs.append([p, 1])
    return runs


@needs_chromium
def test_playback_holds_and_keys(tmp_path, browsers):
    """Playing, each entry is shown for exactly `hold` refreshes, in loop order; keys step and pause"""
    from rotstar_mrcal.pattern.layout import make_layout

    layout = make_layout(screen=(480, 420), pitch=60, band=16)
    d = layout.to_dict()
    blank = cv2.imencode(".png", np.zeros((420, 480), np.uint8))[1].tobytes()
    html = render_player(player_config(d, {f["file"]: blank for f in d["frames"]}, hold=3, marker_hold=5))
    (tmp_path / "p.html").write_text(html)
    b = browsers(1)
    b.emulate(480, 420, 1)
    st = b.load((tmp_path / "p.html").as_uri() + "#play")
    assert st["mode"] == "play" and st["hold"] == 3 and st["markerHold"] == 5
    n = st["entries"]
    runs = played_runs(b, 3 * (n * 3 + 2))
    inner = runs[1:-1]
    assert len(inner) >= n + 2
    for (a, _), (c, _) in zip(inner, inner[1:]):
        assert c == (a + 1) % n
    assert all(length == (5 if p == 0 else 3) for p, length in inner), runs
    b.key(" ", "Space", 32)
    assert b.evaluate("rotstar.status().mode") == "pause"
    p0 = b.evaluate("rotstar.status().pos")
    b.key("ArrowRight", vk=39)
    b.key("ArrowRight", vk=39)
    assert b.evaluate("rotstar.status().pos") == (p0 + 2) % n
    b.key("ArrowLeft", vk=37)
    assert b.evaluate("rotstar.status().pos") == (p0 + 1) % n
    b.key("c", "KeyC", 67)
    assert b.evaluate("rotstar.status().mode") == "check"


# ---- the paper's whole sequence ----------------------------------------------
@pytest.fixture(scope="module")
def ipad_paper(tmp_path_factory):
    """rotstar-pattern --paper-sequence on the iPad: 8 phase-shift frames after the identity frames, the star last"""
    out = tmp_path_factory.mktemp("paper")
    r = subprocess.run([sys.executable, "-m", "rotstar_mrcal.cli.pattern", "--out", str(out), "--paper-sequence"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    return out


@pytest.mark.slow  # make test-slow: the iPad's whole paper sequence written (7 s); the default sequence's levels stay
def test_paper_sequence_levels_match_the_pngs(ipad_paper):
    """The closed forms of the phase and star frames' mean luminance equal the decoded PNGs' means"""
    from rotstar_mrcal.pattern.render import decode_display

    d = json.loads((ipad_paper / "pattern.json").read_text())
    loop = player_loop(d["frames"])
    assert [e["kind"] for e in loop] == ["start-marker"] + ["rotstar"] * 8 + ["identity"] * 13 + ["phase"] * 8 + \
        ["checkerboard", "star"]
    lev = expected_levels(layout_from_dict(d), loop)
    got = [float(decode_display(im).mean()) for im in loop_images(ipad_paper)]
    np.testing.assert_allclose(lev, got, atol=2e-3)


@pytest.mark.slow  # make test-slow: as above; the default sequence's pixel-exact checks in chromium stay in make test
@needs_chromium
def test_paper_sequence_pixel_exact(ipad_paper, browsers):
    """The phase-shift frames (gamma-encoded fringes: any colour conversion would change their values) and the
    star frame reach the screen pixel for pixel"""
    want = loop_images(ipad_paper)
    H, W = want[0].shape
    b = browsers(1)
    b.emulate(W, H, 1)
    st = b.load((ipad_paper / "player.html").as_uri())
    assert st["mode"] == "check" and st["ok"], st["problems"]
    assert st["entries"] == 32 and st["kinds"][-10:] == ["phase"] * 8 + ["checkerboard", "star"]
    for k in range(22, 32):
        assert b.evaluate(f"rotstar.show({k})")
        assert_gray_equal(b.screenshot(), want[k], f"loop entry {k} ({st['files'][k]})")


def test_playback_holds_per_kind(tmp_path, browsers):
    """The identity frames held shorter than the rotating star (the config's kind holds, and from the URL)"""
    from rotstar_mrcal.pattern.layout import make_layout
    from rotstar_mrcal.pattern.loop import SHORT_HOLDS, entry_holds

    layout = make_layout(screen=(480, 420), pitch=60, band=16)
    d = layout.to_dict()
    blank = cv2.imencode(".png", np.zeros((420, 480), np.uint8))[1].tobytes()
    html = render_player(player_config(d, {f["file"]: blank for f in d["frames"]}, hold=None))  # SHORT_HOLDS
    b = browsers(1)
    b.emulate(480, 420, 1)
    for k, (url, want) in enumerate((("#play", entry_holds(player_loop(d["frames"]))),
                                     ("#play&hold=4&identityhold=2",
                                      entry_holds(player_loop(d["frames"]), 4, {"identity": 2},
                                                  SHORT_HOLDS["start-marker"])))):
        (tmp_path / f"p{k}.html").write_text(html)  # (another file: a new hash alone does not load the page)
        st = b.load((tmp_path / f"p{k}.html").as_uri() + url)
        assert st["holds"] == want.tolist(), (url, st["holds"])
        n = st["entries"]
        runs = played_runs(b, 2 * int(want.sum()) + 20)
        inner = runs[1:-1]
        assert len(inner) >= n
        assert all(length == want[p] for p, length in inner), (url, runs)

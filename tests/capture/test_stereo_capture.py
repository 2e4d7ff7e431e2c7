"""Both infrared imagers (Y12I) and the colour camera: lockstep capture, one set of frame boundaries, errors

The recordings are simulated (capture.simulated): the player's loop seen by a
left and a right camera at two poses (12-bit values, 25 fps) and by a colour
camera at its own size, rate (30 fps) and clock (started 23 ms later). The
capture path is the real one: rotstar-capture -> RigSource -> V4L2Source ->
v4l2.Device -> the fake D435 of test_capture_v4l2 at the system-call
boundary, which packs the left and right frames into Y12I buffers with the
reference packer and the colour frames into YUYV (or MJPG), and streams
both nodes on one clock.
"""

from __future__ import annotations

import io
import json
import sys

import cv2
import numpy as np
import pytest

from rotstar_mrcal import simulate
from rotstar_mrcal.capture import uvc_xu, v4l2
from rotstar_mrcal.capture.backend_replay import save_recording
from rotstar_mrcal.capture.backend_v4l2 import V4L2Source
from rotstar_mrcal.capture.colour import pack_yuyv, to_grey
from rotstar_mrcal.capture.interleaved import pack_y8i, pack_y12i
from rotstar_mrcal.capture.pose import quick_check
from rotstar_mrcal.capture.rig import RigSource, record_rig
from rotstar_mrcal.capture.rig_segment import segment_rig
from rotstar_mrcal.capture.segment import SegmentError
from rotstar_mrcal.capture.simulated import camera_stream, loop_irradiance, player_schedule
from rotstar_mrcal.cli.capture import main as rotstar_capture
from rotstar_mrcal.cli.detect import main as rotstar_detect
from rotstar_mrcal.cli.segment import main as rotstar_segment
from rotstar_mrcal.pattern.loop import player_loop
from rotstar_mrcal.pattern.layout import make_layout
from capture.test_v4l2 import FakeD435

LAYOUT = make_layout(screen=(800, 600), pitch=100, band=24)
FILES = [f["file"] for f in LAYOUT.frames()]
N_ENTRIES = len(player_loop(LAYOUT.frames()))
HOLD, LOOP_S = 18, N_ENTRIES * 18 / 60  # 6 s a loop
COLOUR_SIZE, COLOUR_FPS, COLOUR_T0 = (424, 240), 30, 0.023


def stereo_poses(model):
    """rt_cam_board of the left camera (a random pose) and of the right one, a tenth of the distance to its right"""
    import mrcal

    rt0 = simulate.random_poses(model, LAYOUT, 1, np.random.default_rng(3))[0]
    baseline = 0.1 * float(rt0[5])
    return [rt0, mrcal.compose_rt(np.array([0, 0, 0, -baseline, 0, 0.0]), rt0)]


@pytest.fixture(scope="module")
def loops():
    """One loop of each camera (repeating seamlessly): left, right (uint16, 12-bit values, 640x400, 150 frames at
    25 fps) and colour (uint8, 424x240, 180 frames at 30 fps on a clock 23 ms behind)"""
    model = simulate.preset_model("pinhole-small")
    rt = stereo_poses(model)
    sched = player_schedule(N_ENTRIES, hold=HOLD, duration=LOOP_S + 1)
    out = []
    for r in rt:
        E = loop_irradiance(LAYOUT, model, r, supersample=2)
        f, _ = camera_stream(E, sched, int(LOOP_S * 25), fps=25, exposure_s=0.012, noise=0.005, gain=0.6,
                             t0=0.013, rng=8)
        out.append((f >> 4).astype(np.uint16))  # 12-bit values, as Y12I carries them
    E = loop_irradiance(LAYOUT, model, rt[0], supersample=2)
    Ec = np.stack([cv2.resize(e, COLOUR_SIZE, interpolation=cv2.INTER_AREA) for e in E])
    f, _ = camera_stream(Ec, sched, int(LOOP_S * COLOUR_FPS), fps=COLOUR_FPS, exposure_s=0.012, noise=0.01,
                         gain=0.6, t0=0.013 + COLOUR_T0, bits=8, rng=9)
    out.append(f)
    assert out[0].max() < 4096 and out[0].max() > 1500
    return out


def fake_rig(loops, colour_format="YUYV"):
    """The fake D435: Y12I on the IR node (the exposure scales it), the colour camera on its own node and clock"""
    left, right, colour = loops
    fake = FakeD435()
    ir, rgb = fake.nodes["/dev/video2"], fake.nodes["/dev/video4"]

    def ir_frames(k, w, h, code):
        assert code == "Y12I" and (w, h) == (640, 400)
        f = ir.xu[uvc_xu.D4XX.EXPOSURE][3] / 4000
        return pack_y12i(*(np.clip(v[k % len(v)] * f, 0, 4095) for v in (left, right)))

    def rgb_frames(k, w, h, code):
        y = colour[k % len(colour)]
        if code == "MJPG":
            return cv2.imencode(".jpg", y, [cv2.IMWRITE_JPEG_QUALITY, 100])[1]
        return pack_yuyv(y, u=100, v=150)

    ir.frames, rgb.frames, rgb.t0 = ir_frames, rgb_frames, COLOUR_T0
    return fake


def open_fake_rig(fake, colour_format="YUYV"):
    ir = V4L2Source("/dev/video2", fourcc="Y12I", size=(640, 400), fps=25, sys=fake, stereo=True)
    rgb = V4L2Source("/dev/video4", fourcc=colour_format, size=COLOUR_SIZE, fps=COLOUR_FPS, camera="generic", sys=fake)
    return RigSource([ir, rgb])


# ---- the V4L2 path ------------------------------------------------------------------------------
def test_y12i_and_colour_through_the_fake_device(loops):
    """Y12I buffers come back as the left and right frames bit for bit; YUYV as its luma; the colour camera's
    newest frame at each infrared frame"""
    fake = fake_rig(loops)
    rig = open_fake_rig(fake)
    assert rig.cameras == 3 and rig.full_scales == [65535.0, 65535.0, 255.0]
    rig.start()
    recs = record_rig(rig, 10)
    rig.stop()
    rig.close()
    assert fake.fds == {} and not fake.streaming
    assert "Y12I" in [n.fmt[0] for n in fake.nodes.values()]
    left, right, colour = loops
    k = recs[0].sequence
    for rec, want in zip(recs, (left, right)):  # the camera's exposure, 8500 us: x 2.125, clipped at 4095
        np.testing.assert_array_equal(rec.frames, np.clip(want[k] * (8500 / 4000), 0, 4095).astype(np.uint16))
    assert not np.array_equal(recs[0].frames, recs[1].frames)
    # the colour camera: at infrared frame k (t = k / 25) its newest frame j (t = 0.023 + j / 30 <= k / 25)
    j = np.floor((k / 25 - COLOUR_T0) * COLOUR_FPS + 1e-9).astype(int)
    j[j < 0] = 0  # (its first frame, waited for)
    assert recs[2].sequence.tolist() == j.tolist()
    np.testing.assert_array_equal(recs[2].frames, colour[j])


def test_mjpg_colour_frames_decode_to_grey(loops):
    fake = fake_rig(loops)
    src = V4L2Source("/dev/video4", fourcc="MJPG", size=COLOUR_SIZE, fps=30, camera="generic", sys=fake)
    src.start()
    f = src.read()
    src.close()
    assert f.image.shape == (240, 424) and f.image.dtype == np.uint8
    assert np.abs(f.image.astype(int) - loops[2][0]).mean() < 1.0  # JPEG at quality 100
    with pytest.raises(Exception, match="does not decode"):
        to_grey("MJPG", np.zeros(100, np.uint8), 424, 240)


def test_capture_cli_both_imagers_and_colour(loops, tmp_path, capsys, monkeypatch):
    """rotstar-capture --stereo --rgb-device: one pose -> pose000/camera-0,1,2 with every frame, split with the
    same boundaries; the IR node gets the exposure, gain and emitter of a one-camera capture"""
    (tmp_path / "pattern.json").write_text(LAYOUT.to_json())
    fake = fake_rig(loops)
    monkeypatch.setattr(sys, "stdin", io.StringIO("\nq\n"))
    out_dir = tmp_path / "seq"
    code = rotstar_capture(["--pattern", str(tmp_path), "--out", str(out_dir), "--size", "640x400", "--stereo",
                            "--rgb-device", "/dev/video4", "--rgb-size", "424x240", "--exposure", "4000",
                            "--frames", "330", "--keep-raw"], source=open_fake_rig(fake))
    out, err = capsys.readouterr()
    assert code == 0, err
    pose = out_dir / "exp4000us" / "pose000"
    assert out.split() == [str(pose)]
    ir = fake.nodes["/dev/video2"]
    assert ir.xu[uvc_xu.D4XX.EXPOSURE][3] == 4000 and ir.xu[uvc_xu.D4XX.EMITTER][3] == 0
    assert ir.controls[v4l2.CID_GAIN]["value"] == 16
    for k in range(3):
        assert f"pose000 at 4000 us camera-{k}: board complete (24/24)" in err
        assert sorted(p.name for p in (pose / f"camera-{k}").glob("*.png")) == sorted(FILES)
        assert (out_dir / "exp4000us" / f"coverage-camera-{k}.png").exists()
    sizes = [cv2.imread(str(pose / f"camera-{k}" / "checkerboard.png"), cv2.IMREAD_UNCHANGED).shape for k in range(3)]
    assert sizes == [(400, 640), (400, 640), (240, 424)]
    # the same frame boundaries: camera 1 averaged camera 0's frames; camera 2 the same or fewer at the edges
    seg = [json.loads((pose / f"camera-{k}" / "segment.json").read_text())["frames_averaged"] for k in range(3)]
    assert seg[0] == seg[1]
    for f in FILES:
        (a0, b0), (a2, b2) = seg[0][f], seg[2][f]
        assert a0 <= a2 < b2 <= b0 and b2 - a2 >= 4
    # 12-bit values are scaled by 16 into the 16-bit PNGs (as a 12-bit Y16 stream would be)
    assert "12-bit data in a 16-bit word? scaled by 16" in err
    raw = out_dir / "raw" / "pose000_exp4000us"
    assert {p.name for p in raw.iterdir()} == {f"camera-{k}.{e}" for k in range(3) for e in ("npy", "json")}
    log = json.loads((out_dir / "capture.json").read_text())
    assert log["source"]["cameras"] == 3 and log["source"]["sources"][1]["format"]["fourcc"] == "YUYV"
    assert log["poses"]["exp4000us"][0]["ok"] and log["poses"]["exp4000us"][0]["reference"] == 0

    # the multi-camera dataset as doc/dataset.md reads it: rotstar-detect finds every camera's board
    code = rotstar_detect([str(out_dir / "exp4000us"), "-o", str(tmp_path / "corners.vnl")])
    out, err = capsys.readouterr()
    assert all(f"camera-{k}: 1 of 1 poses gave a board" in err for k in range(3)), err
    assert code == 1 and "mrcal needs at least 2 per camera" in err  # (one pose: corners, but no command)
    paths = [ln.split()[0] for ln in (tmp_path / "corners.vnl").read_text().splitlines() if not ln.startswith("#")]
    assert {p.split("/")[-2] for p in paths} == {"camera-0", "camera-1", "camera-2"}

    # rotstar-segment splits the kept recordings again into the same layout
    code = rotstar_segment([str(raw), "--pattern", str(tmp_path), "--out", str(tmp_path / "again" / "pose000")])
    out, err = capsys.readouterr()
    assert code == 0, err
    for k in range(3):
        a = cv2.imread(str(pose / f"camera-{k}" / "rotstar_03.png"), cv2.IMREAD_UNCHANGED)
        b = cv2.imread(str(tmp_path / "again" / "pose000" / f"camera-{k}" / "rotstar_03.png"), cv2.IMREAD_UNCHANGED)
        np.testing.assert_array_equal(a, b)
        assert f"camera-{k}: board found" in err


def test_y8i_both_halves_and_labelled_rectified(tmp_path, capsys, monkeypatch):
    (tmp_path / "pattern.json").write_text(LAYOUT.to_json())
    y, x = np.mgrid[0:800, 0:1280]
    left, right = (x % 256).astype(np.uint8), (y % 200).astype(np.uint8)
    fake = FakeD435(lambda k, w, h, code: pack_y8i(left, right))
    src = V4L2Source("/dev/video2", fourcc="Y8I", size=(1280, 800), fps=30, sys=fake, stereo=True)
    src.start()
    got = src.read_views()
    src.close()
    np.testing.assert_array_equal(got[0].image, left)
    np.testing.assert_array_equal(got[1].image, right)
    src = RigSource([V4L2Source("/dev/video2", fourcc="Y8I", size=(1280, 800), fps=30, sys=fake, stereo=True)])
    monkeypatch.setattr(sys, "stdin", io.StringIO("\nq\n"))
    code = rotstar_capture(["--pattern", str(tmp_path), "--out", str(tmp_path / "s"), "--stereo", "--stereo-format",
                            "Y8I", "--frames", "5", "--exposure", "keep"], source=src)
    err = capsys.readouterr().err
    assert "warning: Y8I frames are rectified" in err and "quick look" in err
    assert code == 1 and "pose000: not usable: the recording is too short: 5 frame(s)" in err and "(on camera-0, camera-1)" in err


# ---- one set of frame boundaries ---------------------------------------------------------------
def lockstep(loops, n=240, colour_lag=0.0):
    """The three recordings as RigSource takes them: the colour camera's newest frame at each infrared frame"""
    left, right, colour = loops
    k = np.arange(n)
    j = np.maximum(np.floor((k / 25 - COLOUR_T0 - colour_lag) * COLOUR_FPS + 1e-9).astype(int), 0)
    return [left[k % len(left)], right[k % len(right)], colour[j % len(colour)]]


def true_corners():
    """The true corners of the left, right and colour camera (the left view resampled by area to 424x240)"""
    model = simulate.preset_model("pinhole-small")
    left, right = (simulate.true_corners(model, LAYOUT, r) for r in stereo_poses(model))
    scale = np.array(COLOUR_SIZE) / np.array([640, 400])
    return [left, right, (left + 0.5) * scale - 0.5]


def test_segment_rig_same_boundaries(loops):
    """Every camera's segmented frames give its true corners: the lockstep colour camera's too"""
    recs = lockstep(loops)
    rs = segment_rig(recs, LAYOUT.frames(), LAYOUT, [65535, 65535, 255])
    assert rs.reference == 0
    for k, (seg, truth, fs) in enumerate(zip(rs.cameras, true_corners(), (4095, 4095, 255))):
        r = quick_check(seg, LAYOUT, json.loads(LAYOUT.to_json()), fs)
        err = np.linalg.norm(r.corners - truth, axis=-1)
        print(f"camera-{k}: {r.n_valid} corners, {np.sqrt(np.mean(err ** 2)):.4f} px RMS from the truth, "
              f"worst {err.max():.4f} px")
        assert r.n_valid == 24 and np.sqrt(np.mean(err ** 2)) < 0.02 and err.max() < 0.04
    assert rs.cameras[1].ranges == rs.cameras[0].ranges
    for f in FILES:
        a0, b0 = rs.cameras[0].ranges[f]
        a2, b2 = rs.cameras[2].ranges[f]
        assert a0 <= a2 < b2 <= b0
        # each camera's average is of its own frames: camera 2's is its own still frames' mean
        np.testing.assert_allclose(rs.cameras[2].images[f], recs[2][a2:b2].mean(axis=0))
    # the right camera's average is not the left one's
    assert np.abs(rs.cameras[0].images["rotstar_00.png"] - rs.cameras[1].images["rotstar_00.png"]).mean() > 50


def test_segment_rig_bad_input(loops):
    recs = lockstep(loops)
    with pytest.raises(SegmentError, match=r"different frame counts \(camera-0: 240, camera-1: 240, camera-2: 239\)"):
        segment_rig([recs[0], recs[1], recs[2][:-1]], LAYOUT.frames(), LAYOUT, [65535, 65535, 255])
    # a colour camera half a display frame behind: its frames change in the middle of camera 0's ranges
    late = lockstep(loops, colour_lag=0.15)
    with pytest.raises(SegmentError, match=r"camera-2 did not see one still frame where camera-0 saw \S+\.png|"
                                           r"camera-2: only \d still frame"):
        segment_rig(late, LAYOUT.frames(), LAYOUT, [65535, 65535, 255])
    # a camera that saw another sequence (the marker never dark): the levels do not follow pattern.json
    other = np.ascontiguousarray(recs[1][::-1])
    with pytest.raises(SegmentError, match="camera-1"):
        segment_rig([recs[0], other, recs[2]], LAYOUT.frames(), LAYOUT, [65535, 65535, 255])
    # camera 0 covered: camera 1 sets the boundaries, and camera 0 fails their check
    dark = np.zeros_like(recs[0])
    with pytest.raises(SegmentError, match="camera-0: over the frames camera-1 split, flat levels"):
        segment_rig([dark, recs[1]], LAYOUT.frames(), LAYOUT, [65535, 65535])
    # the reference chosen: camera 1's boundaries, checked on camera 0
    rs = segment_rig(recs[:2], LAYOUT.frames(), LAYOUT, [65535, 65535], reference=1)
    assert rs.reference == 1 and rs.cameras[0].ranges == rs.cameras[1].ranges


def test_segment_cli_several_cameras_and_bad_input(loops, tmp_path, capsys):
    (tmp_path / "pattern.json").write_text(LAYOUT.to_json())
    recs = lockstep(loops)
    fns = []
    for k, r in enumerate(recs):
        fns.append(str(tmp_path / f"camera-{k}.npy"))
        save_recording(fns[-1], r, fps=25)
    code = rotstar_segment(fns + ["--pattern", str(tmp_path), "--out", str(tmp_path / "seq" / "pose000"), "--no-check"])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert out.split() == [str(tmp_path / "seq" / "pose000")]
    assert all((tmp_path / "seq" / "pose000" / f"camera-{k}" / "identity_00.png").exists() for k in range(3))
    assert (tmp_path / "seq" / "pattern.json").exists()
    # different frame counts: one line, exit 2
    save_recording(fns[2], recs[2][:200], fps=25)
    code = rotstar_segment(fns + ["--pattern", str(tmp_path), "--out", str(tmp_path / "x" / "pose000")])
    err = capsys.readouterr().err
    last = err.strip().splitlines()[-1]
    assert code == 2 and last.startswith("rotstar-segment: the cameras hold different frame counts")
    assert f"camera-2 ({fns[2]}): 200" in last and f"camera-0 ({fns[0]}): 240" in last
    # one camera's frames differ in size: a folder of frames with one odd frame
    folder = tmp_path / "cam1"
    folder.mkdir()
    for t in range(240):
        cv2.imwrite(str(folder / f"f{t:03d}.png"), np.zeros((400, 640) if t != 7 else (200, 320), np.uint16))
    code = rotstar_segment([fns[0], str(folder), "--pattern", str(tmp_path), "--out", str(tmp_path / "y" / "pose000")])
    err = capsys.readouterr().err
    assert code == 2 and "f007.png: 320x200" in err and "640x400" in err


def test_snapshot_shows_which_imager_is_covered(loops, tmp_path, capsys):
    """First contact: --snapshot with the left lens covered; camera-0 (left) goes dark, camera-1 does not"""
    left, right, colour = loops
    fake = fake_rig((np.zeros_like(left), right, colour))
    code = rotstar_capture(["--snapshot", str(tmp_path / "snap"), "--stereo", "--rgb-device", "/dev/video4",
                            "--size", "640x400", "--rgb-size", "424x240", "--exposure", "4000"],
                           source=open_fake_rig(fake))
    out = capsys.readouterr().out.splitlines()
    assert code == 0 and len(out) == 3
    assert out[0].startswith("camera-0 left IR (/dev/video2 Y12I 640x400)") and "mean 0.0, max 0 (uint16)" in out[0]
    assert out[1].startswith("camera-1 right IR") and float(out[1].split("mean ")[1].split(",")[0]) > 100
    assert out[2].startswith("camera-2 /dev/video4 (YUYV 424x240)") and "(uint8)" in out[2]
    img = cv2.imread(str(tmp_path / "snap" / "camera-1.png"), cv2.IMREAD_UNCHANGED)
    k = int(out[1].split("frame ")[1])
    np.testing.assert_array_equal(img, right[k % len(right)])  # exposure 4000 us: as simulated
    assert fake.nodes["/dev/video2"].xu[uvc_xu.D4XX.EMITTER][3] == 0 and fake.fds == {}


def test_segment_a_raw_y12i_dump(loops, tmp_path, capsys):
    """`v4l2-ctl --stream-to` in Y12I -> rotstar-segment --fourcc Y12I: camera-0 (left) and camera-1 (right), the same
    as splitting the left and right recordings"""
    (tmp_path / "pattern.json").write_text(LAYOUT.to_json())
    left, right, _ = lockstep(loops, n=240)
    with open(tmp_path / "dump.raw", "wb") as f:
        for a, b in zip(left, right):
            f.write(pack_y12i(a, b).tobytes())
    code = rotstar_segment([str(tmp_path / "dump.raw"), "--size", "640x400", "--fourcc", "Y12I", "--pattern",
                            str(tmp_path), "--out", str(tmp_path / "raw" / "pose000"), "--no-check"])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert "camera-0: " + str(tmp_path / "dump.raw") + " (left imager): 240 frames of 640x400, 16-bit" in err
    for k, r in enumerate((left, right)):
        save_recording(str(tmp_path / f"camera-{k}.npy"), r)
    code = rotstar_segment([str(tmp_path / "camera-0.npy"), str(tmp_path / "camera-1.npy"), "--pattern",
                            str(tmp_path), "--out", str(tmp_path / "npy" / "pose000"), "--no-check"])
    assert code == 0
    for k in range(2):
        a = cv2.imread(str(tmp_path / "raw" / "pose000" / f"camera-{k}" / "rotstar_05.png"), cv2.IMREAD_UNCHANGED)
        b = cv2.imread(str(tmp_path / "npy" / "pose000" / f"camera-{k}" / "rotstar_05.png"), cv2.IMREAD_UNCHANGED)
        np.testing.assert_array_equal(a, b)
    with open(tmp_path / "dump.raw", "ab") as f:
        f.write(b"\0")
    code = rotstar_segment([str(tmp_path / "dump.raw"), "--size", "640x400", "--fourcc", "Y12I", "--pattern",
                            str(tmp_path), "--out", str(tmp_path / "bad" / "pose000")])
    err = capsys.readouterr().err
    assert code == 2 and "is not a whole number of 640x400 Y12I frames (768000 bytes each)" in err


def test_capture_arguments_for_several_cameras(tmp_path, capsys):
    (tmp_path / "pattern.json").write_text(LAYOUT.to_json())
    base = ["--pattern", str(tmp_path), "--out", str(tmp_path / "s")]
    with pytest.raises(SystemExit) as e:
        rotstar_capture(base + ["--stereo", "--backend", "replay", "--device", "rec.npy"])
    assert e.value.code == 2 and "--stereo and --rgb-device record over V4L2" in capsys.readouterr().err
    with pytest.raises(SystemExit) as e:
        rotstar_capture(base + ["--stereo-format", "Y16"])
    assert e.value.code == 2
    fake = FakeD435()
    with pytest.raises(Exception, match="Y16 is not a stereo format"):
        V4L2Source("/dev/video2", fourcc="Y16", sys=fake, stereo=True)
    assert fake.fds == {}

"""VideoCorrector: frames in, corrected frames out, with the tracking and filter of the CLI."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest
from conftest import cli_binary

import unshear


def clip(face: np.ndarray, n: int = 16, k: float = 0.25) -> list[np.ndarray]:
    """A still face, sheared by k, drifting a pixel a frame on a 480 x 360 canvas."""
    frames = []
    sheared = unshear.distort(face, k)
    for i in range(n):
        canvas = np.full((360, 480, 3), 40, np.uint8)
        y, x = 50 + i % 3, 60 + i
        canvas[y : y + sheared.shape[0], x : x + sheared.shape[1]] = sheared
        frames.append(canvas)
    return frames


def run(video: unshear.VideoCorrector, frames: list[np.ndarray]) -> list[unshear.Frame]:
    out = []
    for f in frames:
        out += video.push(f)
    return out + video.finish()


def test_frames_come_back_in_order_corrected(faces: list[np.ndarray]) -> None:
    frames = clip(faces[0])
    video = unshear.VideoCorrector(fps=30)
    assert video.smoothing_lag == 6
    returned = [video.push(f) for f in frames]
    assert [len(r) for r in returned] == [0] * 6 + [1] * 10
    assert video.pending == 6
    out = [r[0] for r in returned if r] + video.finish()
    assert video.pending == 0
    assert [f.index for f in out] == list(range(16))
    for f in out:
        assert f.image.shape == frames[0].shape and f.image.dtype == np.uint8
        assert f.k_applied == f.k
    tracked = [f for f in out if f.k_raw is not None]
    assert len(tracked) >= 12
    assert all(abs(f.k - 0.25) < 0.05 for f in out[4:]), [round(f.k, 3) for f in out]
    assert all(len(f.faces) == 1 for f in tracked)
    d = out[-1].to_dict()
    assert set(d) == {
        "frame",
        "k_raw",
        "k",
        "k_source",
        "readout_fraction",
        "velocity",
        "faces",
    }
    assert d["frame"] == 15
    # A face drifting a pixel a frame cannot carry a shear of 0.25 under a rolling shutter:
    # no readout is calibrated, the faces decide.
    assert d["k_source"] == "faces" and d["readout_fraction"] is None
    assert "Frame(index=15" in repr(out[-1])
    # The corrected frame is the input de-sheared by k_applied.
    last = out[-1]
    assert last.k_applied is not None
    expected = unshear.distort(frames[-1], -last.k_applied)
    assert np.array_equal(last.image, expected)


def test_layouts_no_correction_and_lag_zero(faces: list[np.ndarray]) -> None:
    frames = clip(faces[1], n=5)
    grey = [np.ascontiguousarray(f[:, :, 1]) for f in frames]
    out = run(unshear.VideoCorrector(smoothing_lag=0, correct=False), grey)
    assert len(out) == 5 and all(f.k_applied is None for f in out)
    assert all(np.array_equal(a.image, b) for a, b in zip(out, grey))
    bgr = unshear.VideoCorrector(smoothing_lag=0, bgr=True)
    for f in frames:
        (got,) = bgr.push(np.ascontiguousarray(f[:, :, ::-1]))
        assert got.image.shape == f.shape
    sixteen = run(
        unshear.VideoCorrector(smoothing_lag=2), [f.astype(np.uint16) * 257 for f in frames]
    )
    assert all(f.image.dtype == np.uint16 for f in sixteen) and len(sixteen) == 5


def test_bad_frames_and_settings(faces: list[np.ndarray]) -> None:
    video = unshear.VideoCorrector(smoothing_lag=1)
    video.push(np.zeros((100, 120, 3), np.uint8))
    with pytest.raises(ValueError, match="first frame's size"):
        video.push(np.zeros((100, 121, 3), np.uint8))
    with pytest.raises(ValueError, match="first frame's size"):
        video.push(np.zeros((100, 120), np.uint8))
    with pytest.raises(ValueError, match="uint8 or uint16"):
        video.push(np.zeros((100, 120, 3), np.float32))
    assert len(video.finish()) == 1
    assert video.finish() == []
    with pytest.raises(ValueError, match="finish"):
        video.push(np.zeros((100, 120, 3), np.uint8))
    for kwargs, match in [
        ({"fps": 0}, "fps"),
        ({"hold": -1}, "hold"),
        ({"redetect": 0}, "redetect"),
        ({"smoothing_lag": 251}, "smoothing_lag"),
        ({"k_source": "best"}, "k_source"),
        ({"interp": "nearest"}, "interp"),
        ({"min_confidence": 2}, "confidence 2 is outside 0 to 1"),
        ({"readout_fraction": 1.5}, "readout fraction"),
        ({"readout_fraction": 0}, "readout fraction"),
    ]:
        with pytest.raises(ValueError, match=match):
            unshear.VideoCorrector(**kwargs)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="unexpected keyword argument 'frame_rate'"):
        unshear.VideoCorrector(frame_rate=30)  # type: ignore[call-arg]
    assert unshear.VideoCorrector().finish() == []


def test_agrees_with_unshear_video(tmp_path: Path, faces: list[np.ndarray]) -> None:
    """The same frames through `unshear video --json` and through VideoCorrector."""
    binary = cli_binary()
    if binary is None:
        pytest.skip("no unshear CLI binary: set UNSHEAR_BIN or run `cargo build` first")
    frames = clip(faces[2], n=12, k=-0.2)
    folder = tmp_path / "frames"
    folder.mkdir()
    for i, f in enumerate(frames):
        unshear.write(folder / f"{i:04}.png", f)
    out = subprocess.run(
        [str(binary), "video", str(folder), "--json", "--fps", "30"],
        check=True,
        capture_output=True,
        text=True,
        timeout=300,
    )
    cli = [json.loads(line) for line in out.stdout.splitlines()]
    ours = run(unshear.VideoCorrector(fps=30), frames)
    assert len(cli) == len(ours) == 12
    for a, b in zip(cli, ours):
        assert a["frame"] == b.index
        assert abs(a["k"] - b.k) <= 6e-5
        assert (a["k_raw"] is None) == (b.k_raw is None)
        if b.k_raw is not None:
            assert abs(a["k_raw"] - b.k_raw) <= 6e-5


def test_a_second_face_is_found_within_a_few_frames(faces: list[np.ndarray]) -> None:
    """With the network detector a face entering beside a tracked one is found within 5 frames
    (full detection every 5, as ``unshear video``), not after the 30 of the cascade."""
    a, b = faces[0], faces[1]
    h, w = max(a.shape[0], b.shape[0]), a.shape[1] + b.shape[1] + 40
    frames = []
    for i in range(14):
        canvas = np.full((h + 20, w, 3), 40, np.uint8)
        canvas[10 : 10 + a.shape[0], 10 : 10 + a.shape[1]] = a
        if i >= 3:
            x = 30 + a.shape[1]
            canvas[10 : 10 + b.shape[0], x : x + b.shape[1]] = b
        frames.append(canvas)
    out = run(unshear.VideoCorrector(fps=30, smoothing_lag=0), frames)
    found = [len(f.faces) for f in out]
    assert found[:3] == [1, 1, 1], found
    assert 2 in found[3:9], found
    # Asked for, the cascade's interval still applies.
    slow = run(unshear.VideoCorrector(fps=30, smoothing_lag=0, redetect=30), frames)
    assert [len(f.faces) for f in slow][3:] == [1] * 11, [len(f.faces) for f in slow]


def test_frames_read_by_columns_are_measured_and_corrected_vertically(
    faces: list[np.ndarray],
) -> None:
    """Frames of a clip recorded with the phone held upright, turned upright as OpenCV gives
    them: a pan shears them vertically, y' = y + k (x - W/2)."""

    def vertical(image: np.ndarray, k: float) -> np.ndarray:
        t = np.ascontiguousarray(np.swapaxes(image, 0, 1))
        return np.ascontiguousarray(np.swapaxes(unshear.distort(t, k), 0, 1))

    upright = clip(faces[0], k=0.0)
    frames = [vertical(f, 0.25) for f in upright]
    out = run(unshear.VideoCorrector(readout="columns"), frames)
    tracked = [f for f in out if f.k_raw is not None]
    assert len(tracked) >= 12
    assert all(abs(f.k - 0.25) < 0.06 for f in out[4:]), [round(f.k, 3) for f in out]
    # The frame comes back de-sheared along its columns: near the upright frame again.
    inside = (slice(60, -60), slice(60, -60))
    fixed, sheared = out[-1].image.astype(int), frames[-1].astype(int)
    assert np.abs(fixed[inside] - upright[-1][inside]).mean() < 4.0
    assert np.abs(sheared[inside] - upright[-1][inside]).mean() > 8.0
    # Read along the rows, the same frames give another k (a roll and a shear).
    rows = run(unshear.VideoCorrector(), frames)
    assert abs(rows[-1].k - out[-1].k) > 0.01
    with pytest.raises(ValueError, match="readout"):
        unshear.VideoCorrector(readout="diagonal")  # type: ignore[arg-type]


def test_a_pan_with_a_known_readout_is_corrected_from_motion() -> None:
    """A textured wall panned 40 px a frame, rows read over 0.8 of the frame interval (k =
    0.8 * 40 / 240): with the readout given, every frame's k comes from the measured motion,
    with no face in view."""
    rng = np.random.default_rng(3)
    blocks = rng.integers(0, 255, (60, 600), dtype=np.uint8)
    wall = np.repeat(np.repeat(blocks, 4, 0), 4, 1)
    v, rho = 40, 0.8
    k = rho * v / 240
    frames = []
    for n in range(12):
        x = 1200 - v * n  # the view moves left: the content moves right
        view = np.ascontiguousarray(wall[:, x : x + 320])
        frames.append(unshear.distort(view, k))
    out = run(unshear.VideoCorrector(fps=30, readout_fraction=rho), frames)
    assert len(out) == 12
    for f in out:
        assert f.k_source == "motion" and f.readout_fraction == rho
        assert f.velocity is not None and abs(f.velocity[0] - v) < 1.0
        assert abs(f.k - k) < 0.01, (f.index, f.k, k)
    faces_only = run(unshear.VideoCorrector(fps=30, readout_fraction=rho, motion=False), frames)
    assert all(f.k_source != "motion" for f in faces_only)


def test_deblur_exposure_sharpens_a_blurred_pan() -> None:
    """The same wall panned 40 px a frame, each row smeared by a box of 40 * 0.25 = 10 px
    (centred on its read time): with ``deblur_exposure=0.25`` the corrected frames come out
    nearer the unblurred pan corrected alike, and report the blur removed."""
    rng = np.random.default_rng(4)
    blocks = rng.integers(0, 255, (60, 600), dtype=np.uint8)
    wall = np.repeat(np.repeat(blocks, 4, 0), 4, 1).astype(np.float64)
    v, rho, exposure = 40, 0.8, 0.25
    k = rho * v / 240
    blur = int(v * exposure)
    # A box of `blur` px along the rows (an even length centred half a pixel off; the error
    # that leaves is far below the blur's own).
    smeared = np.stack([np.convolve(r, np.ones(blur) / blur, mode="same") for r in wall])
    sharp, blurred = [], []
    for n in range(16):
        x = 1200 - v * n
        for src, out in ((wall, sharp), (smeared, blurred)):
            view = np.ascontiguousarray(src[:, x : x + 320].round().astype(np.uint8))
            out.append(unshear.distort(view, k))
    ref = run(unshear.VideoCorrector(fps=30, readout_fraction=rho), sharp[:10])
    plain = run(unshear.VideoCorrector(fps=30, readout_fraction=rho), blurred[:10])
    fixed = run(
        unshear.VideoCorrector(fps=30, readout_fraction=rho, deblur_exposure=exposure),
        blurred[:10],
    )
    inside = (slice(20, -20), slice(60, -60))

    def error(frames: list[unshear.Frame]) -> float:
        return float(
            np.mean(
                [
                    np.abs(f.image[inside].astype(float) - r.image[inside]).mean()
                    for f, r in zip(frames, ref)
                ]
            )
        )

    assert error(fixed) < 0.7 * error(plain), (error(fixed), error(plain))
    assert all(f.blur is not None and abs(f.blur - v * exposure) < 1.0 for f in fixed)
    assert all(f.blur is None for f in plain)
    assert fixed[3].to_dict()["blur"] == fixed[3].blur
    for bad in (0.0, 1.5, -0.1, "fast"):
        with pytest.raises(ValueError, match="exposure"):
            unshear.VideoCorrector(deblur_exposure=bad)  # type: ignore[arg-type]
    # "auto": the exposure estimated from the blur over a first pass, then every frame
    # deblurred with it (the box of 10 px over 40 px of motion: 0.25).
    auto = unshear.VideoCorrector(fps=30, readout_fraction=rho, deblur_exposure="auto")
    for f in blurred:
        auto.analyse(f)
    auto.end_analysis()
    replayed = [auto.replay(f) for f in blurred]
    assert all(f.blur is not None and abs(f.blur - v * exposure) < 1.0 for f in replayed)


def test_two_passes_calibrate_the_readout_from_a_swinging_pan() -> None:
    """A textured wall seen by a camera whose speed swings (8-frame period, up to 60 px a
    frame), rows read over 0.8 of the frame interval, rendered row by row: two passes find the
    readout from the motion alone and correct every frame from motion with it."""
    rng = np.random.default_rng(5)
    blocks = rng.integers(0, 255, (60, 400), dtype=np.uint8)
    wall = np.repeat(np.repeat(blocks, 4, 0), 4, 1).astype(np.float64)
    h, w, rho, amp = 240, 320, 0.8, 60.0 * 8 / (2 * np.pi)
    cols = np.arange(w, dtype=np.float64)

    def position(t: float) -> float:
        return amp * (1.0 - np.cos(2 * np.pi * t / 8))  # content displacement, px

    frames = []
    for n in range(24):
        frame = np.empty((h, w), np.uint8)
        for y in range(h):
            x = 600 + cols - position(n + rho * y / h)
            frame[y] = np.interp(x, np.arange(wall.shape[1]), wall[y]).round().astype(np.uint8)
        frames.append(frame)
    video = unshear.VideoCorrector(fps=30)
    for f in frames:
        video.analyse(f)
    with pytest.raises(ValueError, match="analyse"):
        video.push(frames[0])
    with pytest.raises(ValueError, match="end_analysis"):
        video.replay(frames[0])
    found = video.end_analysis()
    assert found is not None and abs(found - rho) <= 0.05 * rho, found
    out = [video.replay(f) for f in frames]
    assert all(f.k_source == "motion" and f.readout_fraction == found for f in out)
    assert video.finish() == []

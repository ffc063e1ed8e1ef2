"""Files: read and write, and their errors as OSError with the Rust message."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from conftest import EXAMPLE, FACES

import unshear


def test_read_layouts(tmp_path: Path) -> None:
    rgb = unshear.read(EXAMPLE)
    assert rgb.shape == (243, 320, 3) and rgb.dtype == np.uint8
    bgr = unshear.read(str(EXAMPLE), bgr=True)
    assert np.array_equal(bgr, rgb[:, :, ::-1])
    grey = rgb[:, :, 0].copy()
    rgba = np.dstack([rgb, np.arange(rgb.shape[1], dtype=np.uint8)[None].repeat(243, 0)])
    deep = rgb.astype(np.uint16) * 257
    for name, img in [
        ("g.png", grey),
        ("a.png", rgba),
        ("d.png", deep),
        ("g16.png", grey.astype(np.uint16) * 3),
    ]:
        unshear.write(tmp_path / name, img)
        back = unshear.read(tmp_path / name)
        assert back.dtype == img.dtype and np.array_equal(back, img), name
    # The grey image comes back H x W, like cv2.IMREAD_GRAYSCALE; bgr=True leaves it alone.
    assert unshear.read(tmp_path / "g.png", bgr=True).shape == grey.shape


def test_write_formats_and_bgr(tmp_path: Path) -> None:
    rgb = unshear.read(FACES[0])
    unshear.write(tmp_path / "x.png", rgb[:, :, ::-1], bgr=True)
    assert np.array_equal(unshear.read(tmp_path / "x.png"), rgb)
    for ext in ("jpg", "bmp", "tif", "webp", "ppm"):
        unshear.write(tmp_path / f"x.{ext}", rgb, jpeg_quality=90)
        assert unshear.read(tmp_path / f"x.{ext}").shape == rgb.shape, ext
    with pytest.raises(ValueError, match="unsupported output format"):
        unshear.write(tmp_path / "x.gif", rgb)
    with pytest.raises(FileExistsError, match="x.png"):
        unshear.write(tmp_path / "x.png", rgb, overwrite=False)
    assert not [p for p in os.listdir(tmp_path) if "tmp" in p]


def test_file_errors_are_os_errors(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="missing.png"):
        unshear.read(tmp_path / "missing.png")
    (tmp_path / "notes.txt").write_text("not an image")
    with pytest.raises(OSError, match="notes.txt"):
        unshear.read(tmp_path / "notes.txt")
    truncated = EXAMPLE.read_bytes()[:2000]
    (tmp_path / "cut.png").write_bytes(truncated)
    with pytest.raises(OSError, match="cut.png"):
        unshear.read(tmp_path / "cut.png")
    (tmp_path / "cut.jpg").write_bytes(FACES[0].read_bytes()[:3000])
    with pytest.raises(OSError, match="truncated JPEG"):
        unshear.read(tmp_path / "cut.jpg")
    with pytest.raises(OSError):
        unshear.read(tmp_path)
    with pytest.raises(OSError, match="over the limit of 1000 pixels"):
        unshear.read(EXAMPLE, max_pixels=1000)
    with pytest.raises(OSError):
        unshear.write(tmp_path / "no" / "such" / "folder.png", np.zeros((4, 4), np.uint8))
    with pytest.raises(TypeError):
        unshear.read(5)  # type: ignore[arg-type]

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


def exif_jpeg(image: np.ndarray, orientation: int, path: Path) -> None:
    """A JPEG of ``image`` (written by unshear) with an EXIF segment holding ``orientation``
    inserted after its start marker (a big-endian TIFF block of one entry)."""
    unshear.write(path, image)
    data = path.read_bytes()
    tiff = b"MM\x00\x2a\x00\x00\x00\x08\x00\x01" + bytes(
        [0x01, 0x12, 0, 3, 0, 0, 0, 1, 0, orientation, 0, 0, 0, 0, 0, 0]
    )
    app1 = b"\xff\xe1" + (2 + 6 + len(tiff)).to_bytes(2, "big") + b"Exif\x00\x00" + tiff
    path.write_bytes(data[:2] + app1 + data[2:])


def test_correct_file_keeps_exif_and_never_writes_over_its_input(
    corrector: unshear.Unshear, tmp_path: Path
) -> None:
    sheared = unshear.distort(unshear.read(FACES[0]), 0.3, canvas="expand")
    src = tmp_path / "in.jpg"
    exif_jpeg(sheared, 1, src)
    before = src.read_bytes()
    dst = tmp_path / "out.jpg"
    report = corrector.correct_file(src, dst)
    assert report.k is not None and abs(report.k - 0.3) < 0.05, report
    assert report == corrector.estimate_file(src)
    assert b"Exif\x00\x00" in dst.read_bytes()[:200], "the EXIF block is kept"
    # What is written is what correct() gives on the same pixels.
    fixed = corrector.correct(unshear.read(src), report=report)
    assert np.abs(unshear.read(dst).astype(int) - fixed).mean() < 2.0  # JPEG's loss
    with pytest.raises(FileExistsError):
        corrector.correct_file(src, dst)
    corrector.correct_file(src, dst, 0.1, overwrite=True)
    with pytest.raises(FileExistsError):
        corrector.correct_file(src, src, overwrite=True)
    assert src.read_bytes() == before
    with pytest.raises(ValueError, match="unsupported output format"):
        corrector.correct_file(src, tmp_path / "out.gif")
    with pytest.raises(FileNotFoundError):
        corrector.correct_file(tmp_path / "missing.jpg", tmp_path / "x.jpg")
    blank = tmp_path / "blank.png"
    unshear.write(blank, np.full((90, 120, 3), 128, np.uint8))
    with pytest.raises(unshear.NoFaceError) as raised:
        corrector.correct_file(blank, tmp_path / "blank-out.png")
    # Nothing written, and the error says what was found (here nothing) for the record.
    assert not (tmp_path / "blank-out.png").exists()
    assert raised.value.report == corrector.estimate_file(blank)
    assert raised.value.report is not None and raised.value.report.k is None


def vertical(image: np.ndarray, c: float) -> np.ndarray:
    """``image`` sheared vertically, ``y' = y + c (x - W/2)``: ``distort`` on the transpose."""
    t = np.ascontiguousarray(np.swapaxes(image, 0, 1))
    return np.ascontiguousarray(np.swapaxes(unshear.distort(t, c), 0, 1))


def test_photos_turned_a_quarter_are_measured_along_their_columns(
    corrector: unshear.Unshear, tmp_path: Path
) -> None:
    """Orientation 6 (a phone held upright): the file holds the picture turned back, its
    sensor rows are the picture's columns, and a pan skews it vertically."""
    face = unshear.read(FACES[0])
    wide = np.full((face.shape[0], face.shape[1] + 160, 3), 128, np.uint8)
    wide[:, 80:-80] = face
    shown = vertical(wide, 0.3)
    src = tmp_path / "turned.jpg"
    exif_jpeg(np.ascontiguousarray(np.rot90(shown, 1)), 6, src)
    assert unshear.read(src).shape == shown.shape, "read turns it upright"
    report = corrector.estimate_file(src)
    assert report.readout == "columns" and report.to_dict()["readout"] == "columns"
    assert report.k is not None and abs(report.k - 0.3) < 0.05, report
    assert any("column by column" in w for w in report.warnings)
    # An array has no orientation: the same pixels are read along their rows.
    assert corrector.estimate(shown).readout == "rows"
    dst = tmp_path / "out.png"
    corrector.correct_file(src, dst)
    fixed = unshear.read(dst).astype(int)
    inside = (slice(40, -40), slice(100, -100))
    # Back to the upright face to within the blur of two resamplings and JPEG's loss.
    assert np.abs(fixed[inside] - wide[inside]).mean() < 6.0
    assert np.abs(shown[inside].astype(int) - wide[inside]).mean() > 12.0

#!/usr/bin/env python3
"""Accuracy on photos turned a quarter by their EXIF orientation (a phone held upright).

Each development photo with one face whose eyes are at least 40 px apart (the photos of the
accuracy tables) is sheared vertically, y' = y + c (x - W/2), as a camera reading it out
column by column would shear it, stored turned back with EXIF orientation 6, and estimated
through `Unshear.estimate_file` (which reads the orientation). The error is the estimate minus
the photo's own estimate at c = 0 (the face's own apparent shear) minus c; the rows model's
reading of the same pixels (`estimate` on the array) is reported beside it.

    pip install ./python && python3 scripts/turned_check.py [--photos N]

Needs ../shared/data (the Caltech development half and its annotations).
"""

from __future__ import annotations

import argparse
import random
import tempfile
from pathlib import Path

import numpy as np

import unshear

SHEARS = [0.1, -0.1, 0.2, -0.2, 0.3, -0.3]
DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "caltech-webfaces"


def vertical(image: np.ndarray, c: float) -> np.ndarray:
    """``image`` sheared vertically about its middle column: ``distort`` on the transpose."""
    t = np.ascontiguousarray(np.swapaxes(image, 0, 1))
    return np.ascontiguousarray(np.swapaxes(unshear.distort(t, c, canvas="expand"), 0, 1))


def turned_jpeg(image: np.ndarray, path: Path) -> None:
    """``image`` stored turned back (90 degrees counter-clockwise) with EXIF orientation 6."""
    unshear.write(path, np.ascontiguousarray(np.rot90(image, 1)), jpeg_quality=95)
    data = path.read_bytes()
    tiff = b"MM\x00\x2a\x00\x00\x00\x08\x00\x01" + bytes(
        [0x01, 0x12, 0, 3, 0, 0, 0, 1, 0, 6, 0, 0, 0, 0, 0, 0]
    )
    app1 = b"\xff\xe1" + (2 + 6 + len(tiff)).to_bytes(2, "big") + b"Exif\x00\x00" + tiff
    path.write_bytes(data[:2] + app1 + data[2:])


def one_big_face_photos() -> list[Path]:
    """Photos (the development half is all ../shared has) whose only annotated face has eyes
    at least 40 px apart."""
    faces: dict[str, list[float]] = {}
    for line in (DATA / "ground_truth.txt").read_text().split("\n"):
        parts = line.split()
        if len(parts) == 9:
            rx, ry, lx, ly = map(float, parts[1:5])
            faces.setdefault(parts[0], []).append(float(np.hypot(lx - rx, ly - ry)))
    return sorted(
        DATA / "images" / name
        for name, d in faces.items()
        if len(d) == 1 and d[0] >= 40 and (DATA / "images" / name).exists()
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--photos", type=int, default=300, help="random photos to use (seed 1)")
    args = parser.parse_args()
    photos = one_big_face_photos()
    random.seed(1)
    photos = random.sample(photos, min(args.photos, len(photos)))
    u = unshear.Unshear()
    rows = {c: [0, 0, 0, 0] for c in SHEARS}  # photos, accepted, within 0.05, rows model within
    used = 0
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "turned.jpg"
        for photo in photos:
            image = unshear.read(photo)
            base = u.estimate(image)
            if base.k is None or len(base.faces) != 1:
                continue
            used += 1
            for c in SHEARS:
                shown = vertical(image, c)
                turned_jpeg(shown, path)
                report = u.estimate_file(path)
                counts = rows[c]
                counts[0] += 1
                if report.k is not None:
                    counts[1] += 1
                    counts[2] += abs(report.k - base.k - c) <= 0.05
                plain = u.estimate(shown).k
                counts[3] += plain is not None and abs(plain - base.k - c) <= 0.05
    print(f"{used} photos with one face measured at c = 0 (of {len(photos)} drawn)\n")
    print("| c | accepted | within 0.05 of c | the rows model's reading within 0.05 |")
    print("|---:|---:|---:|---:|")
    for c, (n, accepted, within, plain) in rows.items():
        print(f"| {c:+.1f} | {accepted / n:.1%} | {within / n:.1%} | {plain / n:.1%} |")


if __name__ == "__main__":
    main()

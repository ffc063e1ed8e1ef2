"""What the benchmarks share: the repository's paths and the images they time."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np

import unshear

ROOT = Path(__file__).resolve().parents[2]
OUT = ROOT / "target" / "bench"
CALTECH = ROOT.parent / "shared" / "data" / "caltech-webfaces" / "images"
FIXTURES = sorted((ROOT / "tests" / "fixtures" / "faces").glob("*.jpeg"))


def upscale2(img: np.ndarray) -> np.ndarray:
    """Twice the size, bilinear (for a 640 px photo made from a 320 px fixture)."""
    f = img.astype(np.float32)
    rows = np.repeat(f, 2, axis=0)
    rows[1:-1:2] = (f[:-1] + f[1:]) / 2
    cols = np.repeat(rows, 2, axis=1)
    cols[:, 1:-1:2] = (rows[:, :-1] + rows[:, 1:]) / 2
    out: np.ndarray = np.clip(cols + 0.5, 0, 255).astype(np.uint8)
    return out


def photo_640x480() -> Path:
    """A 640 x 480 photo with a face: Caltech's pic00278.jpg when ../shared is there, otherwise
    a fixture face twice its size, sheared by 0.2, cut to 640 x 480 (written under target/)."""
    caltech = CALTECH / "pic00278.jpg"
    if caltech.is_file():
        return caltech
    OUT.mkdir(parents=True, exist_ok=True)
    path = OUT / "photo-640x480.png"
    if not path.is_file():
        big = upscale2(unshear.distort(unshear.read(FIXTURES[0]), 0.2))
        unshear.write(path, np.ascontiguousarray(big[:480, :640]))
    return path


def folder_of(n: int) -> Path:
    """A folder of ``n`` photos: the first ``n`` Caltech web photos when ../shared is there,
    otherwise the fixtures sheared by ``n`` shears from -0.4 to 0.4 on 640 x 480 canvases."""
    OUT.mkdir(parents=True, exist_ok=True)
    folder = OUT / f"photos{n}"
    if folder.is_dir() and len(list(folder.iterdir())) == n:
        return folder
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir()
    if CALTECH.is_dir():
        for src in sorted(CALTECH.glob("*.jpg"))[:n]:
            shutil.copy(src, folder / src.name)
        return folder
    faces = [unshear.read(p) for p in FIXTURES]
    for i, k in enumerate(np.linspace(-0.4, 0.4, n)):
        canvas = np.full((480, 640, 3), 100, np.uint8)
        face = unshear.distort(faces[i % len(faces)], float(k), canvas="expand")
        canvas[100 : 100 + face.shape[0], 100 : 100 + face.shape[1]] = face[:, :540]
        unshear.write(folder / f"face{i:03}.png", canvas)
    return folder

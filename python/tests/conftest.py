"""Shared fixtures: the repository's test faces and one corrector per setting, built once."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np
import pytest

import unshear

ROOT = Path(__file__).resolve().parents[2]
FACES = sorted((ROOT / "tests" / "fixtures" / "faces").glob("*.jpeg"))
EXAMPLE = ROOT / "assets" / "example" / "face-k0.30.png"


def cli_binary() -> Path | None:
    """The `unshear` CLI: $UNSHEAR_BIN, else the newer of those `cargo test` (target/debug) and
    `cargo build --release` left (an older one may predate the library the package was built
    from), else one on PATH."""
    env = os.environ.get("UNSHEAR_BIN")
    if env:
        return Path(env)
    built = [ROOT / "target" / p / "unshear" for p in ("release", "debug")]
    built = [p for p in built if p.is_file()]
    if built:
        return max(built, key=lambda p: p.stat().st_mtime)
    found = shutil.which("unshear")
    return Path(found) if found else None


@pytest.fixture(scope="session")
def corrector() -> unshear.Unshear:
    """The default corrector (the CLI's defaults)."""
    return unshear.Unshear()


@pytest.fixture(scope="session")
def quick() -> unshear.Unshear:
    """The quick face search (faster, for tests that only need a face found)."""
    return unshear.Unshear(search="quick")


@pytest.fixture(scope="session")
def faces() -> list[np.ndarray]:
    """The three fixture faces as RGB arrays."""
    assert len(FACES) == 3, FACES
    return [unshear.read(p) for p in FACES]


@pytest.fixture(scope="session")
def face(faces: list[np.ndarray]) -> np.ndarray:
    """One fixture face sheared by 0.3 (RGB, 320 x 243 before the shear)."""
    return unshear.distort(faces[0], 0.3, canvas="expand")

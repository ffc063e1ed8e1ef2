"""The helpers of scripts/recognition_dlib.py (the recognition table with dlib's ResNet): its
split, its LFW identity rule and its camera-like probes. dlib itself is not needed here."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
from conftest import ROOT


def load() -> ModuleType:
    path = ROOT / "scripts" / "recognition_dlib.py"
    spec = importlib.util.spec_from_file_location("recognition_dlib", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["recognition_dlib"] = module
    spec.loader.exec_module(module)
    return module


r = load()


def test_the_first_three_by_file_name_enrol() -> None:
    items = [r.Labelled(i, Path(f"{i}{n}.jpg")) for i in ("b", "a") for n in (3, 1, 10, 2, 0)]
    gallery, probes = r.split(items)
    assert [p.path.name for p in gallery] == [
        "a0.jpg",
        "a1.jpg",
        "a10.jpg",
        "b0.jpg",
        "b1.jpg",
        "b10.jpg",
    ]
    assert [p.path.name for p in probes] == ["a2.jpg", "a3.jpg", "b2.jpg", "b3.jpg"]


def test_lfw_probes_are_the_identities_never_trained_on() -> None:
    # As unshear::dev::dataset::lfw_trained_identity: sorted names, even positions trained.
    items = [r.Labelled(n, Path(f"{n}.jpg")) for n in ("Carol", "Alice", "Bob", "Alice")]
    assert r.lfw_untrained(items) == {"Bob"}


def test_the_row_blur_keeps_the_mean_and_smears_an_edge_over_its_length() -> None:
    row = np.zeros((1, 60))
    row[0, 30:] = 200.0
    out = r.box_blur_rows(row, 10.0)
    ramp = int(np.sum((out[0] > 1.0) & (out[0] < 199.0)))
    assert 9 <= ramp <= 11
    assert abs(out.mean() - row.mean()) < 2.0
    assert r.box_blur_rows(row, 0.5) is row


def test_a_camera_like_probe_is_sheared_blurred_and_cut() -> None:
    rng = np.random.default_rng(3)
    img = rng.integers(0, 255, (120, 200, 3), dtype=np.uint8)
    out = r.camera_like(img, 0.4, 1)
    # Rows cover columns from max(offsets) to W + min(offsets): about |k| H narrower.
    assert out.shape[0] == 120 and out.dtype == np.uint8
    assert 200 - 0.4 * 120 * 1.25 <= out.shape[1] <= 200 - 0.4 * 120 * 0.9
    # The blur (0.12 x 0.4 x 120 / 0.8 = 7 px) smooths the noise along the rows.
    assert (
        np.abs(np.diff(out.astype(float), axis=1)).mean()
        < 0.5 * np.abs(np.diff(img.astype(float), axis=1)).mean()
    )

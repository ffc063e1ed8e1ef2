"""The Ray Data example (examples/ray_batch.py) on a local Ray with 2 CPUs, when Ray is installed."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT

import unshear

pytest.importorskip(
    "ray.data",
    reason="Ray is not installed: `scripts/test-all --extras` (as CI) runs the Ray example",
)
pytest.importorskip("PIL", reason="Pillow is not installed (ray.data.read_images needs it)")

SHEARS = {"a.png": 0.2, "b.png": -0.3, "sub/c.jpg": 0.1, "sub/d.png": -0.15}


def test_ray_example_corrects_a_folder(tmp_path: Path, faces: list[np.ndarray]) -> None:
    source = tmp_path / "in"
    (source / "sub").mkdir(parents=True)
    for (name, k), face in zip(SHEARS.items(), faces * 2):
        unshear.write(source / name, unshear.distort(face, k, canvas="expand"))
    unshear.write(source / "sub" / "blank.png", np.full((90, 120, 3), 128, np.uint8))
    out = tmp_path / "out"
    run = subprocess.run(
        [
            sys.executable,
            str(ROOT / "examples" / "ray_batch.py"),
            str(source),
            str(out),
            "--num-cpus",
            "2",
            "--actors",
            "2",
            "--quick",
        ],
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert run.returncode == 0, run.stderr[-3000:]
    assert "5 images in" in run.stdout
    rows = [
        json.loads(line)
        for part in sorted((out / "results").iterdir())
        for line in part.read_text().splitlines()
    ]
    by_name = {str(Path(r["file"]).relative_to(source)): r for r in rows}
    assert sorted(by_name) == sorted([*SHEARS, "sub/blank.png"])
    assert by_name["sub/blank.png"]["k"] is None and by_name["sub/blank.png"]["output"] is None
    for name, k in SHEARS.items():
        row = by_name[name]
        assert abs(row["k"] - k) <= 0.05, (name, row["k"])
        assert len(row["faces"]) == 1 and set(row["faces"][0]) >= {"box", "k", "confidence"}
        stem, ext = name.rsplit(".", 1)
        written = out / "images" / f"{stem}.unshear.{ext}"
        assert row["output"] == str(written)
        fixed = unshear.read(written)
        assert fixed.shape == unshear.read(source / name).shape
    assert not (out / "images" / "sub" / "blank.unshear.png").exists()

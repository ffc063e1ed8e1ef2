"""The Ray Data example (examples/ray_batch.py) on a local Ray with 2 CPUs, when Ray is installed."""

from __future__ import annotations

import json
import os
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

SHEARS = {"a.png": 0.2, "b.png": -0.3, "sub/c.jpg": 0.1, "sub/d.png": -0.15}
EXAMPLE = str(ROOT / "examples" / "ray_batch.py")


def example(*args: str, cwd: Path, home: Path | None = None) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ, HOME=str(home)) if home else None
    return subprocess.run(
        [sys.executable, EXAMPLE, *args],
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
        cwd=cwd,
        env=env,
    )


def test_ray_example_corrects_a_relative_folder(tmp_path: Path, faces: list[np.ndarray]) -> None:
    """A relative input, a ``file://`` output; an image without a face and a corrupt one are
    reported in the results and the rest is corrected."""
    source = tmp_path / "in"
    (source / "sub").mkdir(parents=True)
    for (name, k), face in zip(SHEARS.items(), faces * 2):
        unshear.write(source / name, unshear.distort(face, k, canvas="expand"))
    unshear.write(source / "sub" / "blank.png", np.full((90, 120, 3), 128, np.uint8))
    (source / "broken.jpg").write_bytes(b"\xff\xd8\xff\xe0 not a JPEG")
    (source / "notes.txt").write_text("not an image")
    out = tmp_path / "out"
    run = example("in", f"file://{out}", "--num-cpus", "2", "--quick", cwd=tmp_path)
    assert run.returncode == 1, run.stderr[-3000:]  # an input failed, as the CLI's exit code
    assert "Traceback" not in run.stderr, run.stderr[-3000:]
    assert "6 images read: 4 corrected, 1 without a face (nothing written), 1 failed" in run.stdout
    assert "failed: " in run.stdout and "broken.jpg" in run.stdout
    assert "6/6 images, " in run.stderr, "the progress line"
    rows = [json.loads(line) for line in (out / "results.jsonl").read_text().splitlines()]
    by_name = {r["file"].removeprefix("in/"): r for r in rows}
    assert len(rows) == len(by_name) == 6, "one line per input"
    assert sorted(by_name) == sorted([*SHEARS, "sub/blank.png", "broken.jpg"])
    assert by_name["sub/blank.png"]["k"] is None and by_name["sub/blank.png"]["output"] is None
    assert "error" not in by_name["sub/blank.png"]
    broken = by_name["broken.jpg"]
    assert broken["k"] is None and broken["output"] is None and broken["error"]
    for name, k in SHEARS.items():
        row = by_name[name]
        assert abs(row["k"] - k) <= 0.05, (name, row["k"])
        assert len(row["faces"]) == 1 and set(row["faces"][0]) >= {"box", "k", "confidence"}
        written = out / "images" / name  # named as `correct --out-dir` names it
        assert row["output"] == f"file://{written}"
        assert unshear.read(written).shape == unshear.read(source / name).shape
    assert sorted(str(p.relative_to(out / "images")) for p in (out / "images").rglob("*.*")) == (
        sorted(SHEARS)
    )


def test_ray_example_says_what_is_wrong_with_its_paths(tmp_path: Path) -> None:
    """One line and exit code 1, before Ray starts: a missing input (also through ``~``), a
    folder without images, an output that cannot be written."""
    (tmp_path / "empty").mkdir()
    (tmp_path / "file").write_text("")
    (tmp_path / "photos").mkdir()
    unshear.write(tmp_path / "photos" / "a.png", np.zeros((8, 8, 3), np.uint8))
    cases = [
        (("missing", "out"), "missing: no such folder or file"),
        (("~/missing", "out"), f"{tmp_path}/missing: no such folder or file"),
        (("empty", "out"), "empty: no image found"),
        (("photos", "file/out"), "file/out: cannot write"),
    ]
    for args, message in cases:
        run = example(*args, cwd=tmp_path, home=tmp_path)
        assert run.returncode == 1, (args, run.stderr)
        assert run.stderr.startswith("ray_batch: ") and message in run.stderr, (args, run.stderr)
        assert len(run.stderr.splitlines()) == 1, run.stderr


def test_the_actor_copies_bucket_files_through_local_disk(
    tmp_path: Path, faces: list[np.ndarray], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A file system other than the local one (a bucket; here a sub-tree file system standing
    in for one) is read and written through pyarrow, the correction made on local copies."""
    import importlib.util

    import pyarrow.fs  # type: ignore[import-untyped]

    spec = importlib.util.spec_from_file_location("ray_batch", EXAMPLE)
    assert spec is not None and spec.loader is not None
    ray_batch = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, "ray_batch", ray_batch)  # for its dataclasses
    spec.loader.exec_module(ray_batch)
    bucket = pyarrow.fs.SubTreeFileSystem(str(tmp_path), pyarrow.fs.LocalFileSystem())
    (tmp_path / "photos").mkdir()
    unshear.write(tmp_path / "photos" / "a.jpg", unshear.distort(faces[0], 0.2, canvas="expand"))
    (tmp_path / "photos" / "bad.png").write_bytes(b"not a PNG")
    source = ray_batch.Location(bucket, "photos", "mem://photos")
    target = ray_batch.Location(bucket, "out", "mem://out")
    actor = ray_batch.Corrector(source, target, {"search": "quick"})
    rows = [json.loads(r) for r in actor({"name": np.array(["a.jpg", "bad.png"])})["row"]]
    assert rows[0]["file"] == "mem://photos/a.jpg" and abs(rows[0]["k"] - 0.2) < 0.05
    assert rows[0]["output"] == "mem://out/images/a.jpg"
    assert (
        unshear.read(tmp_path / "out" / "images" / "a.jpg").shape[:2]
        == (unshear.read(tmp_path / "photos" / "a.jpg").shape[:2])
    )
    assert rows[1]["k"] is None and rows[1]["output"] is None and rows[1]["error"]

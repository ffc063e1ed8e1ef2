"""docs/python.md's Python examples (the README snippet among them) run as written."""

from __future__ import annotations

import re
import shutil
import sys
import types
from pathlib import Path

import numpy as np
import pytest
from conftest import EXAMPLE, ROOT

import unshear

DOC = ROOT / "docs" / "python.md"
BLOCKS = re.findall(r"```python\n(.*?)```", DOC.read_text(), re.DOTALL)


def cv2_stand_in() -> types.ModuleType:
    """What the examples use of OpenCV, when it is not installed: BGR files in and out."""
    cv2 = types.ModuleType("cv2")

    def imread(path: str) -> np.ndarray:
        return unshear.read(path, bgr=True)

    def imwrite(path: str, image: np.ndarray) -> bool:
        unshear.write(path, image, bgr=True)
        return True

    cv2.imread = imread  # type: ignore[attr-defined]
    cv2.imwrite = imwrite  # type: ignore[attr-defined]
    return cv2


def test_the_readme_shows_the_snippet() -> None:
    readme = re.findall(r"```python\n(.*?)```", (ROOT / "README.md").read_text(), re.DOTALL)
    assert readme and readme[0] == BLOCKS[0], "README's Python example is docs/python.md's first"


def test_the_doc_has_the_readme_snippet() -> None:
    assert len(BLOCKS) >= 4
    snippet = BLOCKS[0].strip().splitlines()
    assert len(snippet) == 3 and "bgr=True" in snippet[2], snippet


@pytest.mark.parametrize("index", range(len(BLOCKS)))
def test_example_runs(index: int, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    code = BLOCKS[index]
    if code.startswith("# not run"):
        pytest.skip(code.splitlines()[0][2:])
    (tmp_path / "assets" / "example").mkdir(parents=True)
    shutil.copy(EXAMPLE, tmp_path / "assets" / "example" / EXAMPLE.name)
    monkeypatch.chdir(tmp_path)
    try:
        import cv2  # noqa: F401
    except ImportError:
        monkeypatch.setitem(sys.modules, "cv2", cv2_stand_in())
    namespace: dict[str, object] = {"__name__": "__doc_example__"}
    exec(compile(code, f"{DOC}:block{index}", "exec"), namespace)  # noqa: S102
    written = [p.name for p in tmp_path.iterdir() if p.is_file()]
    if "imwrite" in code or "unshear.write" in code:
        assert written, "the example writes its result"
    if "fixed" in namespace:
        fixed = namespace["fixed"]
        assert isinstance(fixed, np.ndarray) and fixed.dtype == np.uint8

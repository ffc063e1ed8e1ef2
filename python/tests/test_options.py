"""The settings are the library's options: every one a keyword of `Unshear` and
`VideoCorrector` (in the stubs and at run time), `max_shear` among them."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT

import unshear

STUB = ROOT / "python" / "unshear" / "__init__.pyi"


def stub_keywords(class_name: str) -> list[str]:
    """The keyword-only parameters of `class_name.__new__` in the stubs."""
    tree = ast.parse(Path(STUB).read_text())
    for node in tree.body:
        if isinstance(node, ast.ClassDef) and node.name == class_name:
            for item in node.body:
                if isinstance(item, ast.FunctionDef) and item.name == "__new__":
                    return [a.arg for a in item.args.kwonlyargs]
    raise AssertionError(f"no {class_name}.__new__ in the stubs")


NAMES = [o["name"] for o in unshear.options()]


def test_the_options_table() -> None:
    assert "max_shear" in NAMES and "min_confidence" in NAMES
    kinds = {"flag", "integer", "number", "numbers", "choice"}
    for o in unshear.options():
        assert o["kind"] in kinds, o
        assert o["help"] and o["default"], o
        assert bool(o["choices"]) == (o["kind"] == "choice"), o


@pytest.mark.parametrize("class_name", ["Unshear", "VideoCorrector"])
def test_every_option_is_a_keyword_in_the_stubs(class_name: str) -> None:
    keywords = stub_keywords(class_name)
    missing = [n for n in NAMES if n not in keywords]
    assert not missing, f"{class_name}: no keyword for {missing}"


def test_every_option_is_a_keyword_at_run_time() -> None:
    config = unshear.Unshear().config
    assert list(config) == NAMES
    # Each given as it is reported makes the same corrector.
    for name in NAMES:
        u = unshear.Unshear(**{name: config[name]})
        assert u.config == config, name


def test_max_shear_is_taken_and_refuses_larger_estimates(face: np.ndarray) -> None:
    u = unshear.Unshear(max_shear=0.3)
    assert u.config["max_shear"] == 0.3
    assert "max_shear=0.3" in repr(u)
    assert unshear.Unshear().config["max_shear"] == 0.6
    # The fixture face sheared by 0.3, and by 0.1 more: within the default, beyond 0.3.
    sheared = unshear.distort(face, 0.1, canvas="expand")
    accepted = unshear.Unshear().estimate(sheared)
    assert accepted.k is not None and abs(accepted.k - 0.4) < 0.05, accepted
    refused = unshear.Unshear(max_shear=0.3).estimate(sheared)
    assert refused.k is None, refused
    assert [f.refused for f in refused.faces] == ["implausible_shear"], refused


@pytest.mark.parametrize("value", [0, -0.1, 2.5, float("nan")])
def test_max_shear_out_of_range(value: float) -> None:
    with pytest.raises(ValueError, match="maximum shear"):
        unshear.Unshear(max_shear=value)


def test_video_corrector_takes_max_shear() -> None:
    assert unshear.VideoCorrector(max_shear=0.3) is not None

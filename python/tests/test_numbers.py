"""The numeric arguments and settings: out of range (negative, too large, NaN, infinite) is a
`ValueError` naming the argument and its range; not a number of the right kind (a float for a
count, a string, `bool`) is a `TypeError` naming it."""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pytest
from conftest import EXAMPLE

import unshear

U32 = 2**32 - 1
U64 = 2**64 - 1

Call = Callable[[unshear.Unshear, Path, Any], object]
IMAGE = np.zeros((8, 8, 3), np.uint8)


def read(max_pixels: Any) -> None:
    """``unshear.read`` of the example with ``max_pixels``, whose refusal of the example's size
    (a valid ``max_pixels``, only too small) does not count."""
    try:
        unshear.read(EXAMPLE, max_pixels=max_pixels)
    except OSError as e:
        if "over the limit" not in str(e):
            raise


# Every integer the API takes: (name, how to pass it, lowest, highest accepted).
INTEGERS: list[tuple[str, Call, int, int]] = [
    ("max_crops", lambda u, p, v: unshear.Unshear(max_crops=v), 1, 64),
    ("refinements", lambda u, p, v: unshear.Unshear(refinements=v), 0, 10),
    ("min_face", lambda u, p, v: unshear.Unshear(min_face=v), 0, U32),
    ("min_neighbors", lambda u, p, v: unshear.Unshear(min_neighbors=v), 0, U32),
    ("max_pixels", lambda u, p, v: unshear.Unshear(max_pixels=v), 0, U64),
    ("threads", lambda u, p, v: u.estimate_many([], threads=v), 1, 65535),
    ("max_pixels", lambda u, p, v: read(v), 0, U64),
    ("jpeg_quality", lambda u, p, v: unshear.write(p, IMAGE, jpeg_quality=v), 1, 100),
    ("smoothing_lag", lambda u, p, v: unshear.VideoCorrector(smoothing_lag=v), 0, 250),
    ("redetect", lambda u, p, v: unshear.VideoCorrector(redetect=v), 1, U64),
    ("lost_interval", lambda u, p, v: unshear.VideoCorrector(lost_interval=v), 1, U64),
    ("detect_width", lambda u, p, v: unshear.VideoCorrector(detect_width=v), 0, U32),
    ("max_pixels", lambda u, p, v: unshear.VideoCorrector(max_pixels=v), 0, U64),
    ("min_face", lambda u, p, v: unshear.VideoCorrector(min_face=v), 0, U32),
]
INTEGER_IDS = [f"{name}-{i}" for i, (name, *_) in enumerate(INTEGERS)]


@pytest.mark.parametrize(("name", "call", "lowest", "highest"), INTEGERS, ids=INTEGER_IDS)
@pytest.mark.parametrize("where", ["below", "above", "huge", "negative huge"])
def test_integers_out_of_range_raise_value_error(
    quick: unshear.Unshear,
    tmp_path: Path,
    name: str,
    call: Call,
    lowest: int,
    highest: int,
    where: str,
) -> None:
    value = {
        "below": lowest - 1,
        "above": highest + 1,
        "huge": 2**200,
        "negative huge": -(2**200),
    }[where]
    if where == "below" and lowest == 0:
        value = -5
    expected = f"{name} must be {lowest} to {highest}, got {value}"
    # (pytest matches the message and its notes: pyo3 notes "while processing 'name'".)
    with pytest.raises(ValueError, match=f"^{re.escape(expected)}(\n|$)"):
        call(quick, tmp_path / "out.jpg", value)
    assert not (tmp_path / "out.jpg").exists()


@pytest.mark.parametrize(("name", "call", "lowest", "highest"), INTEGERS, ids=INTEGER_IDS)
@pytest.mark.parametrize(
    ("value", "type_name"),
    [(2.0, "float"), ("3", "str"), (True, "bool"), (np.float64(2), "float64"), ([1], "list")],
)
def test_non_integers_raise_type_error(
    quick: unshear.Unshear,
    tmp_path: Path,
    name: str,
    call: Call,
    lowest: int,
    highest: int,
    value: object,
    type_name: str,
) -> None:
    with pytest.raises(TypeError, match=f"^{name} must be an integer, got {type_name}(\n|$)"):
        call(quick, tmp_path / "out.jpg", value)


@pytest.mark.parametrize(("name", "call", "lowest", "highest"), INTEGERS, ids=INTEGER_IDS)
def test_integers_at_the_ends_of_their_range_are_taken(
    quick: unshear.Unshear,
    tmp_path: Path,
    name: str,
    call: Call,
    lowest: int,
    highest: int,
) -> None:
    ends = [lowest, np.int64(lowest)]  # numpy integers are integers
    # The top of the range, where using it is quick (not 65535 threads).
    if name != "threads":
        ends.append(highest)
    for value in ends:
        call(quick, tmp_path / "out.jpg", value)


def test_jpeg_quality_is_applied(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    image = rng.integers(0, 256, (64, 64, 3), dtype=np.uint8)
    sizes = []
    for quality in (1, 50, 100):
        path = tmp_path / f"q{quality}.jpg"
        unshear.write(path, image, jpeg_quality=quality)
        sizes.append(path.stat().st_size)
    assert sizes == sorted(sizes) and sizes[0] < sizes[2]


NAN, INF = math.nan, math.inf

CALLS: dict[str, Callable[[unshear.Unshear, dict[str, Any]], object]] = {
    "Unshear": lambda u, kw: unshear.Unshear(**kw),
    "VideoCorrector": lambda u, kw: unshear.VideoCorrector(**kw),
    "correct": lambda u, kw: u.correct(IMAGE, **kw),
    "distort": lambda u, kw: unshear.distort(IMAGE, **{"k": 0.1, **kw}),
}

# Every float the API takes: (where, name, a bad value, the error, the message).
FLOATS: list[tuple[str, str, object, type, str]] = [
    ("Unshear", "min_confidence", NAN, ValueError, "confidence NaN is outside 0 to 1"),
    ("Unshear", "min_confidence", -INF, ValueError, "outside 0 to 1"),
    ("Unshear", "min_confidence", 10**400, ValueError, "min_confidence must be a finite number"),
    ("Unshear", "min_confidence", True, TypeError, "min_confidence must be a number, got bool"),
    ("Unshear", "scale_factor", NAN, ValueError, "at least 1.01 and at most 2"),
    ("Unshear", "scale_factor", INF, ValueError, "at least 1.01 and at most 2"),
    ("Unshear", "scale_factor", "1.2", TypeError, "scale_factor must be a number, got str"),
    ("Unshear", "shear_hypotheses", [0.1, NAN], ValueError, "between -2 and 2"),
    ("Unshear", "roll_hypotheses", [INF], ValueError, "between -90 and 90"),
    ("Unshear", "shear_hypotheses", [0.1, True], TypeError, r"hypotheses\[1\] must be a number"),
    ("Unshear", "roll_hypotheses", [None], TypeError, r"\[0\] must be a number, got NoneType"),
    ("correct", "k", NAN, ValueError, "k must be a finite number, got NaN"),
    ("correct", "k", -INF, ValueError, "k must be a finite number, got -inf"),
    ("correct", "k", True, TypeError, "k must be a number, got bool"),
    ("correct", "k", "0.1", TypeError, "k must be a number, got str"),
    ("distort", "k", INF, ValueError, "k must be a finite number, got inf"),
    ("distort", "k", False, TypeError, "k must be a number, got bool"),
    ("distort", "pivot", NAN, ValueError, "pivot must be a finite number, got NaN"),
    ("distort", "pivot", "4", TypeError, "pivot must be a number, got str"),
    ("VideoCorrector", "fps", 0, ValueError, "fps must be a positive number, got 0"),
    ("VideoCorrector", "fps", NAN, ValueError, "fps must be a positive number, got NaN"),
    ("VideoCorrector", "fps", INF, ValueError, "fps must be a positive number, got inf"),
    ("VideoCorrector", "fps", True, TypeError, "fps must be a number, got bool"),
    ("VideoCorrector", "hold", -1, ValueError, "hold must be a finite number of seconds >= 0"),
    ("VideoCorrector", "hold", INF, ValueError, "hold must be a finite number of seconds >= 0"),
    ("VideoCorrector", "decay", 0, ValueError, "decay must be a finite number of seconds > 0"),
    ("VideoCorrector", "decay", NAN, ValueError, "decay must be a finite number of seconds > 0"),
    ("VideoCorrector", "decay", "1", TypeError, "decay must be a number, got str"),
    ("VideoCorrector", "min_confidence", NAN, ValueError, "confidence NaN is outside 0 to 1"),
]


@pytest.mark.parametrize(("where", "name", "value", "error", "match"), FLOATS)
def test_bad_floats(
    quick: unshear.Unshear, where: str, name: str, value: object, error: type, match: str
) -> None:
    with pytest.raises(error, match=match):
        CALLS[where](quick, {name: value})


def test_floats_take_ints_and_numpy_floats(quick: unshear.Unshear) -> None:
    assert unshear.Unshear(min_confidence=1, scale_factor=np.float32(1.5)).config[
        "scale_factor"
    ] == pytest.approx(1.5)
    assert unshear.distort(IMAGE, 0, pivot=np.float64(4)).shape == IMAGE.shape
    assert quick.correct(IMAGE, np.float64(0.0)).shape == IMAGE.shape
    unshear.VideoCorrector(fps=30, hold=0, decay=np.float64(2))

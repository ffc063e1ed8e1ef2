"""Results pickle and copy whole: what `multiprocessing`, `concurrent.futures` and Ray do with
them when they cross processes."""

from __future__ import annotations

import copy
import pickle
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path

import numpy as np
import pytest
from conftest import EXAMPLE

import unshear


def fields(face: unshear.Face) -> tuple[object, ...]:
    """Every property of a face, the ones `to_dict()` leaves out included."""
    return (
        face.box,
        face.right_eye,
        face.left_eye,
        face.right_nostril,
        face.left_nostril,
        face.nose,
        face.mouth,
        face.k,
        face.k_measured,
        face.roll,
        face.confidence,
        face.face_score,
        face.refused,
        face.outvoted,
    )


def test_report_and_faces_round_trip(corrector: unshear.Unshear, face: np.ndarray) -> None:
    report = corrector.estimate(face)
    assert report.faces, report
    for protocol in range(2, pickle.HIGHEST_PROTOCOL + 1):
        back = pickle.loads(pickle.dumps(report, protocol=protocol))
        assert isinstance(back, unshear.Report)
        assert back == report and back is not report
        assert back.to_dict() == report.to_dict()
        assert (back.width, back.height, back.warnings) == (
            report.width,
            report.height,
            report.warnings,
        )
        assert [fields(f) for f in back.faces] == [fields(f) for f in report.faces]
    one = report.faces[0]
    assert pickle.loads(pickle.dumps(one)) == one
    assert copy.copy(one) == one and copy.deepcopy(report) == report


def test_refused_and_empty_reports_round_trip(face: np.ndarray) -> None:
    strict = unshear.Unshear(min_confidence=1.0)
    refused = strict.estimate(face)
    assert refused.k is None and refused.faces[0].refused == "low_confidence"
    assert pickle.loads(pickle.dumps(refused)) == refused
    empty = strict.estimate(np.full((120, 160), 90, np.uint8))
    assert pickle.loads(pickle.dumps(empty)) == empty


def test_equality_compares_values(corrector: unshear.Unshear, face: np.ndarray) -> None:
    a, b = corrector.estimate(face), corrector.estimate(face)
    assert a == b
    assert a != corrector.estimate(unshear.distort(face, 0.1, canvas="expand"))
    assert a.faces[0] != "a face"


def test_state_that_is_not_a_result_is_a_value_error() -> None:
    with pytest.raises(ValueError, match="not the state of an unshear result"):
        unshear.Report._from_state({"k": 0.1})  # type: ignore[attr-defined]


def test_frames_round_trip_with_their_image(face: np.ndarray) -> None:
    video = unshear.VideoCorrector(smoothing_lag=0)
    frame = video.push(face)[0]
    back = pickle.loads(pickle.dumps(frame))
    assert np.array_equal(back.image, frame.image)
    assert back.to_dict() == frame.to_dict()
    assert (back.k_causal, back.k_applied) == (frame.k_causal, frame.k_applied)


def estimate_file(path: Path) -> unshear.Report:
    return unshear.Unshear(search="quick").estimate(unshear.read(path))


def test_reports_come_back_from_worker_processes() -> None:
    """The everyday use: a process pool returns reports (pickled in the worker)."""
    with ProcessPoolExecutor(max_workers=2, mp_context=get_context("spawn")) as pool:
        reports = list(pool.map(estimate_file, [EXAMPLE, EXAMPLE]))
    here = estimate_file(EXAMPLE)
    assert reports == [here, here]
    assert here.k is not None and abs(here.k - 0.30) < 0.05

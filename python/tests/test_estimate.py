"""The estimate: accuracy on the fixtures, the settings, the report, and agreement with the CLI."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest
from conftest import EXAMPLE, FACES, cli_binary

import unshear

SHEARS = [-0.40, -0.20, 0.0, 0.20, 0.40]


def test_estimate_within_0_05_of_the_true_shear(
    corrector: unshear.Unshear, faces: list[np.ndarray]
) -> None:
    """The issue's requirement, as the Rust end-to-end test states it: each fixture, each k."""
    images = [unshear.distort(f, k, canvas="expand") for f in faces for k in SHEARS]
    truths = [k for _ in faces for k in SHEARS]
    for report, k, img in zip(corrector.estimate_many(images), truths, images):
        assert len(report.faces) == 1, (k, report)
        assert report.k is not None and abs(report.k - k) <= 0.05, (k, report)
        assert (report.width, report.height) == (img.shape[1], img.shape[0])


def test_filters_locator_within_0_05(faces: list[np.ndarray]) -> None:
    filters = unshear.Unshear(locator="filters")
    for k in (-0.3, 0.3):
        report = filters.estimate(unshear.distort(faces[1], k, canvas="expand"))
        assert report.k is not None and abs(report.k - k) <= 0.05, (k, report)
        assert report.faces[0].face_score is None


def test_correcting_removes_the_shear(corrector: unshear.Unshear, faces: list[np.ndarray]) -> None:
    base = corrector.estimate(faces[0]).k
    sheared = unshear.distort(faces[0], 0.3, canvas="expand")
    report = corrector.estimate(sheared)
    assert base is not None and report.k is not None
    fixed = corrector.correct(sheared, report=report)
    assert np.array_equal(fixed, corrector.correct(sheared))
    assert np.array_equal(fixed, corrector.correct(sheared, report.k))
    residual = corrector.estimate(fixed).k
    assert residual is not None
    assert abs(residual - (base + 0.3 - report.k)) <= 0.05


def test_distort_then_correct_by_k_is_the_identity_about_the_pivot(face: np.ndarray) -> None:
    u = unshear.Unshear(search="quick")
    back = u.correct(unshear.distort(face, -0.25), -0.25)
    assert np.array_equal(unshear.distort(face, 0.25), u.correct(face, -0.25))
    # Back where it was, but for the blur of resampling twice.
    inside = (slice(None), slice(70, -70))
    assert np.abs(back[inside].astype(int) - face[inside]).mean() < 2.0


def test_face_fields(corrector: unshear.Unshear) -> None:
    report = corrector.estimate(unshear.read(EXAMPLE))
    assert report.k is not None and abs(report.k - 0.3175) < 0.001
    (f,) = report.faces
    x, y, w, h = f.box
    assert x < f.right_eye[0] < f.left_eye[0] < x + w
    assert y < f.right_eye[1] < f.right_nostril[1] < y + h
    assert f.nose is not None and f.mouth is not None and f.mouth[1] > f.nose[1]
    assert f.k == f.k_measured and 0.0 <= f.confidence <= 1.0
    assert f.face_score is not None and f.face_score > 0.9
    assert abs(f.roll) < 10
    assert f.refused is None and not f.outvoted
    assert not report.faces_disagree and isinstance(report.warnings, list)
    d = report.to_dict()
    assert set(d) == {"k", "k_source", "faces", "faces_disagree", "warnings"}
    assert report.k_source == d["k_source"] == "faces" and not report.scene_disagrees
    assert set(d["faces"][0]) == {
        "box",
        "right_eye",
        "left_eye",
        "right_nostril",
        "left_nostril",
        "nose",
        "mouth",
        "k",
        "k_measured",
        "roll",
        "confidence",
        "refused",
        "outvoted",
    }
    json.dumps(d)
    assert "k=0.3175" in repr(report) and "Face(" in repr(f)


def test_refused_estimates_keep_their_measurement(face: np.ndarray) -> None:
    strict = unshear.Unshear(search="quick", min_confidence=1.0)
    report = strict.estimate(face)
    assert report.k is None
    assert report.faces and all(f.k is None for f in report.faces)
    assert report.faces[0].refused == "low_confidence"
    assert abs(report.faces[0].k_measured - 0.3) < 0.05
    with pytest.raises(unshear.NoFaceError) as raised:
        strict.correct(face)
    # The error carries what was found, so a batch can record it without estimating again.
    assert raised.value.report == report
    # Face regions too: every face refused leaves nothing to correct, not the image unchanged.
    with pytest.raises(unshear.NoFaceError, match="accepted estimate"):
        strict.correct(face, region="face")
    assert not np.array_equal(strict.correct(face, 0.3, region="face"), face)


def test_defaults_are_the_clis() -> None:
    assert unshear.Unshear().config == {
        "detector": "network",
        "locator": "network",
        "search": None,
        "min_confidence": 0.25,
        "max_shear": 0.6,
        "max_crops": None,
        "refinements": 0,
        "shear_model": None,
        "filter_type": "mosse",
        "min_face": None,
        "min_neighbors": 3,
        "scale_factor": 1.1,
        "proposals": True,
        "fallback_cascade": False,
        "search_every_view": False,
        "shear_hypotheses": None,
        "roll_hypotheses": None,
        "ruler": None,
    }
    assert unshear.Unshear().max_pixels == unshear.DEFAULT_MAX_PIXELS == 250_000_000


def test_every_setting_round_trips() -> None:
    config = {
        "detector": "viola-jones",
        "locator": "filters",
        "search": "quick",
        "min_confidence": 0.5,
        "max_shear": 0.4,
        "max_crops": 2,
        "refinements": 1,
        "shear_model": "equation5",
        "filter_type": "umace",
        "min_face": 40,
        "min_neighbors": 2,
        "scale_factor": 1.2,
        "proposals": False,
        "fallback_cascade": True,
        "search_every_view": True,
        "shear_hypotheses": [0.2, -0.2],
        "roll_hypotheses": [15.0],
        "ruler": "scene",
    }
    u = unshear.Unshear(**config)
    assert u.config == config
    assert unshear.Unshear(**u.config).config == config
    assert "search='quick'" in repr(u) and repr(unshear.Unshear()) == "Unshear()"
    # None means the default, for the settings whose default is None.
    assert unshear.Unshear(max_crops=None, min_face=None).config["min_face"] is None
    # A search is the cascade's: it chooses the Viola-Jones detector, as --quick does.
    assert unshear.Unshear(search="thorough").config["detector"] == "viola-jones"
    # The filters run with Viola-Jones even when the network detector is asked for, and say so.
    filters = unshear.Unshear(detector="network", locator="filters")
    assert filters.config["detector"] == "viola-jones"
    assert "detector='viola-jones'" in repr(filters)


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"locatr": "network"}, TypeError, "unexpected keyword argument 'locatr'"),
        ({"locator": "eyes"}, ValueError, "locator must be one of network, filters"),
        ({"locator": 1}, TypeError, "locator must be a string"),
        ({"search": "fast"}, ValueError, "thorough, quick, single"),
        ({"min_confidence": 1.5}, ValueError, "outside 0 to 1"),
        ({"min_confidence": "high"}, TypeError, "min_confidence must be a number"),
        ({"max_crops": 0}, ValueError, "1 to 64"),
        ({"max_crops": -1}, ValueError, "max_crops must be 1 to 64, got -1"),
        ({"max_crops": 2.5}, TypeError, "max_crops must be an integer"),
        ({"scale_factor": 1.0}, ValueError, "at least 1.01"),
        ({"scale_factor": 1.000001}, ValueError, "at least 1.01"),
        ({"proposals": 1}, TypeError, "True or False"),
        ({"shear_hypotheses": "0.1"}, TypeError, "sequence of numbers"),
        ({"shear_hypotheses": [3.0]}, ValueError, "between -2 and 2"),
        ({"roll_hypotheses": [90]}, ValueError, "between -90 and 90"),
        ({"search": "single", "shear_hypotheses": [0.1]}, ValueError, "one detection pass"),
        ({"search_every_view": True}, ValueError, "goes with search quick"),
        ({"min_face": True}, TypeError, "got bool"),
        ({"detector": "haar"}, ValueError, "network, viola-jones"),
        ({"detector": "network", "search": "quick"}, ValueError, "has none"),
    ],
)
def test_bad_settings(kwargs: dict[str, object], error: type, match: str) -> None:
    with pytest.raises(error, match=match):
        unshear.Unshear(**kwargs)  # type: ignore[arg-type]


def run_cli(args: list[str]) -> list[dict[str, object]]:
    binary = cli_binary()
    if binary is None:
        pytest.skip("no unshear CLI binary: set UNSHEAR_BIN or run `cargo build` first")
    out = subprocess.run(
        [str(binary), *args], check=True, capture_output=True, text=True, timeout=300
    )
    return [json.loads(line) for line in out.stdout.splitlines()]


def assert_same(cli: dict[str, object], report: unshear.Report) -> None:
    """The CLI's line (rounded to 4 decimals) and the report, field by field."""
    ours = report.to_dict()

    def close(a: object, b: object, where: str) -> None:
        if isinstance(a, list):
            assert isinstance(b, list) and len(a) == len(b), where
            for i, (x, y) in enumerate(zip(a, b)):
                close(x, y, f"{where}[{i}]")
        elif a is None or b is None:
            assert a is None and b is None, where
        else:
            assert abs(float(a) - float(b)) <= 6e-5, (where, a, b)  # type: ignore[arg-type]

    close(cli["k"], ours["k"], "k")
    for key in ("k_source", "scene_disagrees"):
        assert cli.get(key) == ours.get(key), key
    for key in ("scene_k", "scene_uncertainty", "k_rows"):
        close(cli.get(key), ours.get(key), key)
    assert report.scene_k == ours.get("scene_k")
    faces = cli["faces"]
    assert isinstance(faces, list) and len(faces) == len(ours["faces"])
    for i, (a, b) in enumerate(zip(faces, ours["faces"])):
        assert set(a) == set(b)
        for key in a:
            close(a[key], b[key], f"faces[{i}].{key}")


@pytest.mark.parametrize(
    ("flags", "config"),
    [
        ([], {}),
        (["--quick"], {"search": "quick"}),
        (["--thorough"], {"search": "thorough"}),
        (["--detector", "viola-jones"], {"detector": "viola-jones"}),
        (
            ["--locator", "filters", "--min-confidence", "0"],
            {"locator": "filters", "min_confidence": 0.0},
        ),
        (["--max-crops", "1", "--min-face", "60"], {"max_crops": 1, "min_face": 60}),
    ],
)
def test_agrees_with_the_cli_json(
    tmp_path: Path, faces: list[np.ndarray], flags: list[str], config: dict[str, object]
) -> None:
    """The same images, the same settings: the CLI's `estimate --json` and `estimate`."""
    paths = [EXAMPLE, *FACES]
    for i, k in enumerate([0.25, -0.35]):
        path = tmp_path / f"sheared{i}.png"
        unshear.write(path, unshear.distort(faces[i], k, canvas="expand"))
        paths.append(path)
    blank = tmp_path / "blank.png"
    unshear.write(blank, np.full((60, 80), 200, np.uint8))
    paths.append(blank)
    lines = run_cli(["estimate", "--json", *flags, *map(str, paths)])
    assert [line["file"] for line in lines] == [str(p) for p in paths]
    u = unshear.Unshear(**config)  # type: ignore[arg-type]
    reports = u.estimate_many([unshear.read(p) for p in paths])
    assert sum(r.k is not None for r in reports) >= 5
    for line, report in zip(lines, reports):
        assert_same(line, report)


def bent_pan(faces: list[np.ndarray]) -> tuple[np.ndarray, float, float]:
    """Two fixture faces, one in the upper half and one in the lower, under a pan speeding up
    during the readout: the shear grows from 0.10 at the upper face's middle row to 0.40 at the
    lower's (linear between, held beyond). Returns the frame and the two faces' rows."""
    a, b = faces[0], faces[2]
    h, w = a.shape[:2]
    frame = np.full((2 * h, 2 * w + 120, 3), 96, np.uint8)
    frame[:h, :w] = a
    frame[h:, w + 120 :] = b
    top, bottom = h / 2, 1.5 * h
    rows = np.arange(2 * h, dtype=np.float64)
    k = 0.10 + 0.30 * np.clip((rows - top) / (bottom - top), 0, 1)
    offsets = np.concatenate([[0.0], np.cumsum((k[1:] + k[:-1]) / 2)])
    offsets -= np.interp(h, rows, offsets)  # about the middle row
    pad = int(np.abs(offsets).max()) + 2
    wide = np.pad(frame, ((0, 0), (pad, pad), (0, 0)), constant_values=96).astype(np.float64)
    xs = np.arange(wide.shape[1], dtype=np.float64)
    out = np.empty_like(wide)
    for y in range(2 * h):  # the content of row y moves right by offsets[y]
        for c in range(3):
            out[y, :, c] = np.interp(xs - offsets[y], xs, wide[y, :, c])
    return out.round().astype(np.uint8), top, bottom


def test_faces_at_different_heights_bend_the_rows(tmp_path: Path, faces: list[np.ndarray]) -> None:
    """A pan changing speed during the readout: ``k_rows`` gives the shear at the two faces'
    rows, the CLI agrees, and ``correct`` straightens both faces."""
    img, top, bottom = bent_pan(faces)
    u = unshear.Unshear()
    report = u.estimate(img)
    assert report.k_rows is not None, report.to_dict()
    (y0, k0), (y1, k1) = report.k_rows
    assert abs(y0 - top) < 30 and abs(y1 - bottom) < 30, report.k_rows
    assert abs(k0 - 0.10) < 0.05 and abs(k1 - 0.40) < 0.05, report.k_rows
    assert report.to_dict()["k_rows"] == [[y0, k0], [y1, k1]]
    path = tmp_path / "bent.png"
    unshear.write(path, img)
    (line,) = run_cli(["estimate", "--json", str(path)])
    assert_same(line, report)
    again = u.estimate(u.correct(img, report=report))
    ks = [f.k for f in again.faces if f.k is not None]
    assert len(ks) == 2 and all(abs(k) < 0.05 for k in ks), ks
    assert again.k_rows is None


def test_the_scenes_verticals_are_reported_without_faces() -> None:
    """A drawing of upright posts and rails sheared by 0.2: no face, so ``k`` stays ``None``
    by default while the scene's shear is reported; ``ruler="scene"`` corrects by it."""
    img = np.full((360, 480), 210, np.uint8)
    for x in range(30, 460, 40):
        img[20:340, x : x + 6] = 40
    for y in (60, 180, 300):
        img[y : y + 5, 20:460] = 90
    sheared = unshear.distort(img, 0.2)
    report = unshear.Unshear().estimate(sheared)
    assert report.k is None and report.k_source is None
    assert report.scene_k is not None and report.scene_uncertainty is not None
    assert abs(report.scene_k - 0.2) < 0.02, report.scene_k
    d = report.to_dict()
    assert d["scene_k"] == report.scene_k and "k_source" not in d
    scene = unshear.Unshear(ruler="scene").estimate(sheared)
    assert scene.k_source == "scene" and scene.k is not None and abs(scene.k - 0.2) < 0.02


def test_correct_removes_a_motion_blur() -> None:
    """The example blurred along its rows by a box of 11 px: ``blur="auto"`` finds it and the
    corrected picture is nearer the unblurred example corrected alike."""
    img = unshear.read(EXAMPLE).astype(np.float64)
    box = np.ones(11) / 11

    def smear(rows: np.ndarray) -> np.ndarray:
        return np.stack([np.convolve(r, box, mode="same") for r in rows])

    if img.ndim == 2:
        blurred = smear(img)
    else:
        blurred = np.stack([smear(img[..., c]) for c in range(img.shape[2])], -1)
    blurred_u8 = blurred.round().clip(0, 255).astype(np.uint8)
    u = unshear.Unshear()
    ref = u.correct(img.astype(np.uint8), 0.316).astype(np.float64)
    plain = u.correct(blurred_u8, 0.316).astype(np.float64)
    fixed = u.correct(blurred_u8, 0.316, blur="auto").astype(np.float64)
    given = u.correct(blurred_u8, 0.316, blur=11.0).astype(np.float64)
    inside = (slice(20, -20), slice(40, -40))

    def error(a: np.ndarray) -> float:
        return float(np.abs(a[inside] - ref[inside]).mean())

    assert error(fixed) < 0.8 * error(plain), (error(fixed), error(plain))
    assert abs(error(given) - error(fixed)) < 0.1 * error(plain)
    for bad in (0.5, 300.0, "sharp"):
        with pytest.raises(ValueError, match="blur"):
            u.correct(blurred_u8, 0.316, blur=bad)  # type: ignore[arg-type]

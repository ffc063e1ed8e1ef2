#!/usr/bin/env python3
"""Measure the README's peer figures (OpenCV's cascade, MediaPipe) against unshear in one run.

Command (from the repository root, after the setup below)::

    target/peers-venv/bin/python scripts/compare_peers.py \\
        --data ../shared/data/caltech-webfaces --limit 200 --out target/peers.json

The machine should be otherwise idle. Where other sessions' jobs run even at ``nice 19``, the
kernel's autogroup scheduling (``/proc/sys/kernel/sched_autogroup_enabled``) still gives each
session an equal share of the cores, so two-thread timings come out no faster than one; the
figures were measured with the run in its own session whose autogroup ranks first::

    setsid bash -c 'echo -19 > /proc/$$/autogroup && exec target/peers-venv/bin/python \\
        scripts/compare_peers.py --limit 200 --out target/peers.json' < /dev/null

Setup (once; PyPI only, nothing is downloaded at run time)::

    python3 -m venv target/peers-venv
    target/peers-venv/bin/pip install --no-deps -r scripts/requirements-peers.txt
    target/peers-venv/bin/maturin build --release --manifest-path python/Cargo.toml \\
        --out target/peers-wheels
    target/peers-venv/bin/pip install --no-deps target/peers-wheels/unshear-*.whl

(``--no-deps``: mediapipe 0.10.21, the last release with the legacy ``mp.solutions`` and its
models inside the wheel, declares ``numpy<2`` and ``opencv-contrib-python``; it runs with the
pinned numpy 2 and ``opencv-python-headless`` 4.14, the OpenCV the README quotes.)

What it measures
----------------

**Photos.** The Caltech 10k Web Faces development photos (``DATA/images``, annotations in
``DATA/ground_truth.txt``: a name, then right eye, left eye, nose and mouth as x y pairs), whole
(no context crop), sorted by name; a photo is used when at least one of its annotated faces has
its eyes at least ``--min-eye-distance`` (40) px apart, and only those faces are scored. The
first ``--limit`` such photos (0: all 871, 928 faces). Each photo is sheared in memory by every
``k`` of ``--shears`` (default 0, +0.4, -0.4) as ``unshear eval shear --context 0`` does:
``x' = x + k (y - H/2)``, the canvas widened by ``ceil(|k| H)`` so nothing is cut, bilinear, the
edge pixel beyond the border (``cv2.warpAffine``, ``BORDER_REPLICATE``); the annotated points are
moved the same way.

**Peers, on every sheared photo:**

* ``opencv-cascade``: ``cv2.CascadeClassifier(models/haarcascade_frontalface_alt2.xml)``,
  ``detectMultiScale(gray, 1.1, 3)`` on ``cvtColor(BGR2GRAY)``, run twice: after
  ``cv2.setNumThreads(1)`` and with OpenCV's default thread count (both recorded).
* ``mediapipe-short`` / ``mediapipe-full``: ``mp.solutions.face_detection.FaceDetection`` with
  ``model_selection`` 0 (short-range model) and 1 (full-range model), confidence 0.5, on RGB;
  MediaPipe's own thread setting (not settable through ``mp.solutions``).
* ``mediapipe-facemesh``: ``mp.solutions.face_mesh.FaceMesh(static_image_mode=True,
  max_num_faces=10)`` (its own detector, then the 468-point mesh).
* ``unshear``: ``unshear.Unshear().estimate(rgb)`` (the defaults; rayon's default thread count).

**Found**: a face counts as found by a detector when one of its boxes contains both sheared
annotated eyes (as ``unshear eval shear``). A FaceMesh mesh (which has no box) finds a face when
both its eye centres lie within 0.35 eye distances of the annotated eyes.

**Shear read from landmarks** (the "tracking slope"). From a right eye ``R``, a left eye ``L`` and
the axis point ``A = (nose + mouth) / 2``, with ``(a, b) = L - R`` and ``(p, q) = A - (R + L) / 2``,
the shear read is the ``k`` for which de-shearing by ``k`` (``x -> x - k y``) makes the
eye-midpoint-to-axis-point vector perpendicular to the eye line:
``b q k^2 - (a q + b p) k + (a p + b q) = 0``, the root of smaller magnitude
(``k = 2 c / (m + sign(m) sqrt(m^2 - 4 b q c))``, ``m = a q + b p``, ``c = a p + b q``). For level
eyes (``b = 0``) this is ``k = p / q``: the horizontal offset of the axis point from the eye
midpoint per unit of its height below the eye line. Shears compose additively, so on exact
points this reads the face's own offset ``k0`` plus the applied ``k``; the annotations give a
slope of exactly 1 (the ``annotations`` row checks this). FaceMesh points: eyes = midpoints of
the eye corners (33, 133) and (362, 263); nose = tip (1); mouth = mean of the lip corners (61,
291) and the inner lip midpoints (13, 14). MediaPipe's detector keypoints (right eye, left eye,
nose tip, mouth centre) and unshear's own landmarks (``Face.right_eye``, ``left_eye``, ``nose``,
``mouth``) are read the same way. For each face and each ``k != 0`` the tracking slope is
``(read at k - read at 0) / k``; the table gives its median over those pairs. For unshear the
slope of its estimate (``Face.k_measured``, refused or not) is given too, with the median
``|k_measured - k|`` and the share within 0.05.

**Times per photo**: the median over photos of the call alone (the grey or RGB conversion is
done beforehand, except unshear's own internal grey conversion), wall clock.

**One 1920x1080 frame** (``--frame-runs``, at least 10, after one warm-up run): the bundled
``assets/example/face-k0.30.png`` (a face sheared by 0.30) enlarged bicubically to the full
height (1422x1080) and pasted in the middle of a mid-grey (128) 1920x1080 canvas, the face's
eyes about 240 px apart. Every peer above, plus unshear on one thread
(``estimate_many([frame], threads=1)``). Median wall time, and the process's CPU time over wall
time (how many cores it kept busy).

Output: a Markdown table on stdout, and with ``--out`` a JSON file with the figures, the
settings, the versions (OpenCV, MediaPipe, numpy, unshear and the repository's commit), the CPU
model from ``/proc/cpuinfo``, the load average, the run's scheduling group and the date.
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import platform
import statistics
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

import unshear

REPO = Path(__file__).resolve().parent.parent
CASCADE = REPO / "models" / "haarcascade_frontalface_alt2.xml"
EXAMPLE = REPO / "assets" / "example" / "face-k0.30.png"

Image = npt.NDArray[np.uint8]
Point = tuple[float, float]
Box = tuple[float, float, float, float]

# FaceMesh indices (the canonical 468-point mesh; the subject's right eye is on the image's left).
MESH_RIGHT_EYE = (33, 133)
MESH_LEFT_EYE = (362, 263)
MESH_NOSE = 1
MESH_MOUTH = (61, 291, 13, 14)
# How far (in eye distances) a mesh's eye may be from the annotated eye to count as that face.
MESH_MATCH = 0.35


@dataclass
class Face:
    """One annotated face: right eye, left eye, nose, mouth (x, y)."""

    right_eye: Point
    left_eye: Point
    nose: Point
    mouth: Point

    @property
    def eye_distance(self) -> float:
        return math.dist(self.right_eye, self.left_eye)

    def points(self) -> tuple[Point, Point, Point, Point]:
        return (self.right_eye, self.left_eye, self.nose, self.mouth)

    def sheared(self, k: float, pivot: float, shift: float) -> Face:
        def move(p: Point) -> Point:
            return (p[0] + k * (p[1] - pivot) + shift, p[1])

        return Face(move(self.right_eye), move(self.left_eye), move(self.nose), move(self.mouth))


@dataclass
class Photo:
    name: str
    path: Path
    faces: list[Face]


@dataclass
class Landmarks:
    """Points some method read for a face, for the shear-from-landmarks formula."""

    right_eye: Point
    left_eye: Point
    nose: Point
    mouth: Point


@dataclass
class Reading:
    """What one method gave for one face at one shear."""

    found: bool = False
    shear_read: float | None = None  # from its landmarks, by the formula
    estimate: float | None = None  # unshear's own k_measured
    accepted: bool | None = None  # unshear: k not refused


@dataclass
class Method:
    """A method's readings per (photo index, face index) and shear, and its times per shear."""

    name: str
    note: str
    readings: dict[tuple[int, int], dict[float, Reading]] = field(default_factory=dict)
    times: dict[float, list[float]] = field(default_factory=dict)

    def record(self, key: tuple[int, int], k: float, reading: Reading) -> None:
        self.readings.setdefault(key, {})[k] = reading


def shear_from_landmarks(lm: Landmarks) -> float | None:
    """The shear that makes the nose-mouth axis perpendicular to the eye line (see the module
    docstring); ``None`` when the points admit none."""
    a = lm.left_eye[0] - lm.right_eye[0]
    b = lm.left_eye[1] - lm.right_eye[1]
    ax = (lm.nose[0] + lm.mouth[0]) / 2
    ay = (lm.nose[1] + lm.mouth[1]) / 2
    p = ax - (lm.left_eye[0] + lm.right_eye[0]) / 2
    q = ay - (lm.left_eye[1] + lm.right_eye[1]) / 2
    m = a * q + b * p
    c = a * p + b * q
    disc = m * m - 4 * b * q * c
    if disc < 0:
        return None
    den = m + math.copysign(math.sqrt(disc), m)
    if den == 0:
        return None
    return 2 * c / den


def box_contains(box: Box, p: Point) -> bool:
    x, y, w, h = box
    return x <= p[0] <= x + w and y <= p[1] <= y + h


def load_photos(data: Path, min_eye_distance: float, limit: int) -> list[Photo]:
    images = data / "images"
    present = set(os.listdir(images))
    faces: dict[str, list[Face]] = {}
    for line in (data / "ground_truth.txt").read_text().splitlines():
        parts = line.split()
        if len(parts) < 9 or parts[0] not in present:
            continue
        v = [float(s) for s in parts[1:9]]
        face = Face((v[0], v[1]), (v[2], v[3]), (v[4], v[5]), (v[6], v[7]))
        if face.eye_distance >= min_eye_distance:
            faces.setdefault(parts[0], []).append(face)
    names = sorted(faces)
    if limit > 0:
        names = names[:limit]
    return [Photo(n, images / n, faces[n]) for n in names]


def shear_image(img: Image, k: float) -> tuple[Image, float, float]:
    """The image sheared by ``k`` about its middle row on a canvas widened so nothing is cut;
    returns it with the pivot row and the horizontal shift of the canvas."""
    h, w = img.shape[:2]
    pivot = h / 2
    if k == 0:
        return img, pivot, 0.0
    extra = math.ceil(abs(k) * h)
    shift = abs(k) * pivot
    m = np.array([[1.0, k, shift - k * pivot], [0.0, 1.0, 0.0]], dtype=np.float64)
    out = cv2.warpAffine(
        img, m, (w + extra, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE
    )
    return np.asarray(out, dtype=np.uint8), pivot, shift


def median(xs: Sequence[float]) -> float | None:
    return statistics.median(xs) if xs else None


# ---------------------------------------------------------------------------------------------
# The peers. Each runner takes the image (BGR, grey and RGB views) and returns its output in the
# image's pixels; timing covers the peer's own call only.


@dataclass
class Views:
    bgr: Image
    gray: Image
    rgb: Image


@dataclass
class Output:
    boxes: list[Box] = field(default_factory=list)
    landmarks: list[Landmarks | None] = field(default_factory=list)  # one per box, or per mesh
    unshear_faces: list[Any] = field(default_factory=list)


Runner = Callable[[Views], Output]


def cascade_runner(clf: cv2.CascadeClassifier, threads: int) -> Runner:
    def run(v: Views) -> Output:
        if cv2.getNumThreads() != threads:
            cv2.setNumThreads(threads)
        found = clf.detectMultiScale(v.gray, 1.1, 3)
        boxes = [(float(x), float(y), float(w), float(h)) for (x, y, w, h) in found]
        return Output(boxes=boxes, landmarks=[None] * len(boxes))

    return run


def mediapipe_detector_runner(detector: Any) -> Runner:
    def run(v: Views) -> Output:
        h, w = v.rgb.shape[:2]
        result = detector.process(v.rgb)
        out = Output()
        for d in result.detections or []:
            rb = d.location_data.relative_bounding_box
            out.boxes.append((rb.xmin * w, rb.ymin * h, rb.width * w, rb.height * h))
            kp = [(p.x * w, p.y * h) for p in d.location_data.relative_keypoints]
            # Keypoints: right eye, left eye, nose tip, mouth centre, right and left tragion.
            out.landmarks.append(Landmarks(kp[0], kp[1], kp[2], kp[3]) if len(kp) >= 4 else None)
        return out

    return run


def facemesh_runner(mesh: Any) -> Runner:
    def run(v: Views) -> Output:
        h, w = v.rgb.shape[:2]
        result = mesh.process(v.rgb)
        out = Output()
        for fl in result.multi_face_landmarks or []:
            pts = [(p.x * w, p.y * h) for p in fl.landmark]

            def mean(idx: Sequence[int], pts: list[Point] = pts) -> Point:
                return (
                    sum(pts[i][0] for i in idx) / len(idx),
                    sum(pts[i][1] for i in idx) / len(idx),
                )

            out.landmarks.append(
                Landmarks(
                    mean(MESH_RIGHT_EYE), mean(MESH_LEFT_EYE), pts[MESH_NOSE], mean(MESH_MOUTH)
                )
            )
        return out

    return run


def unshear_runner(model: unshear.Unshear, threads: int | None) -> Runner:
    def run(v: Views) -> Output:
        if threads is None:
            report = model.estimate(v.rgb)
        else:
            report = model.estimate_many([v.rgb], threads=threads)[0]
        out = Output()
        for f in report.faces:
            out.boxes.append(f.box)
            if f.nose is not None and f.mouth is not None:
                out.landmarks.append(Landmarks(f.right_eye, f.left_eye, f.nose, f.mouth))
            else:
                out.landmarks.append(None)
            out.unshear_faces.append(f)
        return out

    return run


def timed(run: Runner, v: Views) -> tuple[Output, float, float]:
    """The output, the wall time and the process's CPU time (all threads), in seconds."""
    c0, t0 = time.process_time(), time.perf_counter()
    out = run(v)
    t1, c1 = time.perf_counter(), time.process_time()
    return out, t1 - t0, c1 - c0


def read_face(kind: str, out: Output, face: Face) -> Reading:
    """Whether ``out`` found ``face``, and what it read of it."""
    re, le = face.right_eye, face.left_eye
    d = face.eye_distance
    if kind == "mesh":
        best: tuple[float, Landmarks] | None = None
        for lm in out.landmarks:
            if lm is None:
                continue
            err = max(math.dist(lm.right_eye, re), math.dist(lm.left_eye, le))
            if err <= MESH_MATCH * d and (best is None or err < best[0]):
                best = (err, lm)
        if best is None:
            return Reading()
        return Reading(found=True, shear_read=shear_from_landmarks(best[1]))
    # Detectors: the boxes containing both eyes; of those, the one whose eyes (if it has
    # landmarks) are nearest the annotated ones, else the smallest box.
    candidates = [i for i, b in enumerate(out.boxes) if box_contains(b, re) and box_contains(b, le)]
    if not candidates:
        return Reading()

    def rank(i: int) -> tuple[float, float]:
        lm = out.landmarks[i] if i < len(out.landmarks) else None
        err = max(math.dist(lm.right_eye, re), math.dist(lm.left_eye, le)) if lm else math.inf
        return (err, out.boxes[i][2] * out.boxes[i][3])

    i = min(candidates, key=rank)
    lm = out.landmarks[i] if i < len(out.landmarks) else None
    r = Reading(found=True, shear_read=shear_from_landmarks(lm) if lm else None)
    if kind == "unshear":
        f = out.unshear_faces[i]
        r.estimate = float(f.k_measured)
        r.accepted = f.k is not None
    return r


# ---------------------------------------------------------------------------------------------
# Summaries


def tracking_slopes(m: Method, attr: str) -> list[float]:
    slopes = []
    for per_k in m.readings.values():
        base = per_k.get(0.0)
        v0 = getattr(base, attr) if base is not None else None
        if v0 is None:
            continue
        for k, r in per_k.items():
            vk = getattr(r, attr)
            if k != 0.0 and vk is not None:
                slopes.append((vk - v0) / k)
    return slopes


def summarise(m: Method, shears: Sequence[float], n_faces: int) -> dict[str, Any]:
    per_shear: dict[str, Any] = {}
    for k in shears:
        rs = [per_k[k] for per_k in m.readings.values() if k in per_k]
        found = sum(r.found for r in rs)
        entry: dict[str, Any] = {
            "faces": n_faces,
            "found": found,
            "found_share": found / n_faces if n_faces else None,
            "median_ms_per_photo": (
                1e3 * statistics.median(m.times[k]) if m.times.get(k) else None
            ),
            "photos_timed": len(m.times.get(k, [])),
        }
        errs = [abs(r.estimate - k) for r in rs if r.estimate is not None]
        if errs:
            entry["median_abs_k_error"] = statistics.median(errs)
            entry["within_0_05"] = sum(e <= 0.05 for e in errs) / len(errs)
            entry["estimates"] = len(errs)
            entry["accepted"] = sum(bool(r.accepted) for r in rs)
        per_shear[f"{k:+.2f}"] = entry
    slopes_lm = tracking_slopes(m, "shear_read")
    slopes_est = tracking_slopes(m, "estimate")
    return {
        "note": m.note,
        "per_shear": per_shear,
        "tracking_slope_landmarks": median(slopes_lm),
        "tracking_slope_landmarks_pairs": len(slopes_lm),
        "tracking_slope_estimate": median(slopes_est),
        "tracking_slope_estimate_pairs": len(slopes_est),
        "readings": [
            {
                "photo": key[0],
                "face": key[1],
                **{
                    f"{k:+.2f}": {
                        "found": r.found,
                        "shear_read": r.shear_read,
                        "estimate": r.estimate,
                        "accepted": r.accepted,
                    }
                    for k, r in per_k.items()
                },
            }
            for key, per_k in sorted(m.readings.items())
        ],
    }


def frame_1920x1080() -> Image:
    """The bundled example enlarged to full height on a mid-grey 1920x1080 canvas."""
    ex = cv2.imread(str(EXAMPLE), cv2.IMREAD_COLOR)
    if ex is None:
        raise SystemExit(f"cannot read {EXAMPLE}")
    h, w = ex.shape[:2]
    scale = 1080 / h
    nw = min(1920, round(w * scale))
    big = cv2.resize(ex, (nw, 1080), interpolation=cv2.INTER_CUBIC)
    canvas = np.full((1080, 1920, 3), 128, dtype=np.uint8)
    x0 = (1920 - nw) // 2
    canvas[:, x0 : x0 + nw] = big
    return canvas


def views_of(bgr: Image) -> Views:
    gray = np.asarray(cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY), dtype=np.uint8)
    rgb = np.ascontiguousarray(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), dtype=np.uint8)
    return Views(bgr, gray, rgb)


def time_frame(
    runners: dict[str, tuple[str, Runner]], runs: int
) -> tuple[dict[str, Any], dict[str, Any]]:
    bgr = frame_1920x1080()
    v = views_of(bgr)
    results: dict[str, Any] = {}
    for name, (kind, run) in runners.items():
        run(v)  # warm-up
        walls: list[float] = []
        cpus: list[float] = []
        out = Output()
        for _ in range(runs):
            out, wall, cpu = timed(run, v)
            walls.append(wall)
            cpus.append(cpu)
        entry: dict[str, Any] = {
            "median_ms": 1e3 * statistics.median(walls),
            "min_ms": 1e3 * min(walls),
            "max_ms": 1e3 * max(walls),
            "cpu_over_wall": sum(cpus) / sum(walls),
            "runs": runs,
            "boxes_or_meshes": max(len(out.boxes), len(out.landmarks)),
        }
        if kind == "unshear" and out.unshear_faces:
            entry["k_measured"] = [float(f.k_measured) for f in out.unshear_faces]
        reads = [shear_from_landmarks(lm) for lm in out.landmarks if lm is not None]
        entry["shear_read"] = reads
        results[name] = entry
        print(f"  frame {name}: {entry['median_ms']:.1f} ms", file=sys.stderr)
    frame_info = {
        "size": [int(bgr.shape[1]), int(bgr.shape[0])],
        "made_from": str(EXAMPLE.relative_to(REPO)),
        "how": "enlarged bicubically to 1080 rows, pasted centred on a 128-grey canvas",
        "true_k": 0.30,
    }
    return results, frame_info


# ---------------------------------------------------------------------------------------------
# Environment


def git(*args: str) -> str:
    try:
        return subprocess.run(
            ["git", *args], cwd=REPO, capture_output=True, text=True, check=True
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def read_text(path: str) -> str | None:
    try:
        return Path(path).read_text().strip()
    except OSError:
        return None


def load_mediapipe() -> tuple[Any, str | None, dict[str, bool]]:
    """The mediapipe module (or ``None``), why not, and which bundled models are present."""
    try:
        import mediapipe as mp  # type: ignore[import-untyped,import-not-found,unused-ignore]
    except ImportError as e:
        return None, f"mediapipe not importable: {e}", {}
    root = Path(mp.__file__).parent / "modules"
    models = {
        name: (root / rel).is_file()
        for name, rel in {
            "face_detection_short_range": "face_detection/face_detection_short_range.tflite",
            "face_detection_full_range_sparse": (
                "face_detection/face_detection_full_range_sparse.tflite"
            ),
            "face_landmark": "face_landmark/face_landmark.tflite",
        }.items()
    }
    if not hasattr(mp, "solutions"):
        return None, f"mediapipe {mp.__version__} has no mp.solutions (removed in 0.10.30)", models
    return mp, None, models


# ---------------------------------------------------------------------------------------------
# The table


def pct(x: float | None) -> str:
    return "" if x is None else f"{100 * x:.1f}%"


def num(x: float | None, fmt: str = ".2f") -> str:
    return "" if x is None else format(x, fmt)


def markdown(result: dict[str, Any]) -> str:
    shears: list[float] = result["settings"]["shears"]
    heads = [f"found k={k:+.1f}" for k in shears]
    heads += [f"ms/photo k={k:+.1f}" for k in shears]
    lines = [
        "| method | " + " | ".join(heads) + " | tracking slope | 1920x1080 frame |",
        "|---|" + "---:|" * (len(heads) + 2),
    ]
    frame = result["frame"]["times"]
    for name, s in result["photos"]["methods"].items():
        cells = []
        for k in shears:
            e = s["per_shear"][f"{k:+.2f}"]
            cells.append(f"{pct(e['found_share'])} ({e['found']}/{e['faces']})")
        for k in shears:
            cells.append(num(s["per_shear"][f"{k:+.2f}"]["median_ms_per_photo"], ".1f"))
        slope = num(s["tracking_slope_landmarks"], ".3f")
        if s["tracking_slope_estimate"] is not None:
            slope = f"estimate {num(s['tracking_slope_estimate'], '.3f')}; landmarks {slope}"
        f = frame.get(name)
        ft = "" if f is None else f"{f['median_ms']:.1f} ms (CPU/wall {f['cpu_over_wall']:.2f})"
        lines.append(f"| {name} | " + " | ".join(cells) + f" | {slope} | {ft} |")
    for name, f in frame.items():
        if name not in result["photos"]["methods"]:
            blank = " | ".join([""] * (len(heads) + 1))
            ft = f"{f['median_ms']:.1f} ms (CPU/wall {f['cpu_over_wall']:.2f})"
            lines.append(f"| {name} | {blank} | {ft} |")
    u = result["photos"]["methods"].get("unshear")
    extra = []
    if u is not None:
        extra = [
            "",
            "| unshear's estimates (`k_measured`) | median abs k error | within 0.05 | accepted |",
            "|---|---:|---:|---:|",
        ]
        for k in shears:
            e = u["per_shear"][f"{k:+.2f}"]
            if "median_abs_k_error" in e:
                extra.append(
                    f"| k={k:+.1f} | {e['median_abs_k_error']:.3f} | {pct(e['within_0_05'])} "
                    f"| {e['accepted']} of {e['estimates']} |"
                )
    return "\n".join(lines + extra)


def main() -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared/data/caltech-webfaces")
    ap.add_argument("--limit", type=int, default=200, help="photos (0: all)")
    ap.add_argument("--min-eye-distance", type=float, default=40.0)
    ap.add_argument("--shears", type=float, nargs="+", default=[0.0, 0.4, -0.4])
    ap.add_argument("--frame-runs", type=int, default=15, help="timed runs on the frame (>= 10)")
    ap.add_argument("--out", type=Path, help="write the JSON here")
    args = ap.parse_args()
    if args.frame_runs < 10:
        ap.error("--frame-runs must be at least 10")
    shears = [float(k) for k in args.shears]
    if 0.0 not in shears:
        shears.insert(0, 0.0)

    started = datetime.datetime.now(datetime.timezone.utc)
    load_start = os.getloadavg()
    default_threads = cv2.getNumThreads()

    clf = cv2.CascadeClassifier(str(CASCADE))
    if clf.empty():
        raise SystemExit(f"cannot load {CASCADE}")
    model = unshear.Unshear()

    # name -> (kind for read_face, runner, note)
    methods: dict[str, tuple[str, Runner, str]] = {
        "opencv-cascade 1 thread": (
            "box",
            cascade_runner(clf, 1),
            "CascadeClassifier(alt2).detectMultiScale(gray, 1.1, 3), cv2.setNumThreads(1)",
        ),
        f"opencv-cascade {default_threads} threads": (
            "box",
            cascade_runner(clf, default_threads),
            f"the same, cv2.setNumThreads({default_threads}) (OpenCV's default here)",
        ),
    }
    skipped: dict[str, str] = {}
    mp, why, mp_models = load_mediapipe()
    closers: list[Any] = []
    if mp is None:
        skipped["mediapipe"] = why or "unavailable"
    else:
        for sel, name, model_name in (
            (0, "mediapipe-short", "face_detection_short_range"),
            (1, "mediapipe-full", "face_detection_full_range_sparse"),
        ):
            if not mp_models.get(model_name):
                skipped[name] = f"{model_name}.tflite is not inside the installed mediapipe"
                continue
            det = mp.solutions.face_detection.FaceDetection(
                model_selection=sel, min_detection_confidence=0.5
            )
            closers.append(det)
            methods[name] = (
                "box",
                mediapipe_detector_runner(det),
                (
                    f"mp.solutions.face_detection model_selection={sel} ({model_name}.tflite), "
                    "confidence 0.5; shear read from its 4 keypoints"
                ),
            )
        if mp_models.get("face_landmark") and mp_models.get("face_detection_short_range"):
            mesh = mp.solutions.face_mesh.FaceMesh(
                static_image_mode=True, max_num_faces=10, refine_landmarks=False
            )
            closers.append(mesh)
            methods["mediapipe-facemesh"] = (
                "mesh",
                facemesh_runner(mesh),
                "mp.solutions.face_mesh.FaceMesh(static_image_mode=True, max_num_faces=10)",
            )
        else:
            skipped["mediapipe-facemesh"] = "face_landmark.tflite is not inside mediapipe"
    methods["unshear"] = (
        "unshear",
        unshear_runner(model, None),
        "unshear.Unshear().estimate(rgb), default threads",
    )

    photos = load_photos(args.data, args.min_eye_distance, args.limit)
    n_faces = sum(len(p.faces) for p in photos)
    print(f"{len(photos)} photos, {n_faces} faces", file=sys.stderr)

    recs = {name: Method(name, note) for name, (_, _, note) in methods.items()}
    truth = Method("annotations", "the annotated points through the same formula (check: 1)")
    # Warm-up: one photo through every method, untimed.
    if photos:
        bgr0 = cv2.imread(str(photos[0].path), cv2.IMREAD_COLOR)
        if bgr0 is not None:
            for _, run, _ in methods.values():
                run(views_of(np.asarray(bgr0, dtype=np.uint8)))
    for pi, photo in enumerate(photos):
        bgr = cv2.imread(str(photo.path), cv2.IMREAD_COLOR)
        if bgr is None:
            print(f"warning: cannot read {photo.path}", file=sys.stderr)
            continue
        for k in shears:
            img, pivot, shift = shear_image(np.asarray(bgr, dtype=np.uint8), k)
            v = views_of(img)
            faces = [f.sheared(k, pivot, shift) for f in photo.faces]
            for fi, f in enumerate(faces):
                truth.record(
                    (pi, fi),
                    k,
                    Reading(True, shear_from_landmarks(Landmarks(*f.points()))),
                )
            for name, (kind, run, _) in methods.items():
                out, wall, _cpu = timed(run, v)
                recs[name].times.setdefault(k, []).append(wall)
                for fi, f in enumerate(faces):
                    recs[name].record((pi, fi), k, read_face(kind, out, f))
        if (pi + 1) % 20 == 0:
            print(f"  {pi + 1}/{len(photos)} photos", file=sys.stderr)
    cv2.setNumThreads(default_threads)

    frame_runners: dict[str, tuple[str, Runner]] = {
        name: (kind, run) for name, (kind, run, _) in methods.items()
    }
    frame_runners["unshear 1 thread"] = ("unshear", unshear_runner(model, 1))
    frame_times, frame_info = time_frame(frame_runners, args.frame_runs)
    cv2.setNumThreads(default_threads)
    for c in closers:
        c.close()

    summaries = {name: summarise(m, shears, n_faces) for name, m in recs.items()}
    summaries["annotations"] = summarise(truth, shears, n_faces)
    result: dict[str, Any] = {
        "command": " ".join([Path(sys.executable).name, *sys.argv]),
        "date": started.isoformat(timespec="seconds"),
        "finished": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "machine": {
            "cpu_model": cpu_model(),
            "logical_cpus": os.cpu_count(),
            "loadavg_start": load_start,
            "loadavg_end": os.getloadavg(),
            "platform": platform.platform(),
            "sched_autogroup_enabled": read_text("/proc/sys/kernel/sched_autogroup_enabled"),
            "autogroup": read_text("/proc/self/autogroup"),
            "nice": os.nice(0),
        },
        "versions": {
            "python": platform.python_version(),
            "opencv": cv2.__version__,
            "mediapipe": None if mp is None else mp.__version__,
            "mediapipe_bundled_models": mp_models,
            "numpy": np.__version__,
            "unshear": unshear.__version__,
            "unshear_commit": git("rev-parse", "--short", "HEAD"),
            "worktree_changes": git("status", "--porcelain").splitlines(),
        },
        "settings": {
            "data": str(args.data),
            "photos": len(photos),
            "faces": n_faces,
            "min_eye_distance": args.min_eye_distance,
            "shears": shears,
            "shear": "x' = x + k (y - H/2), canvas widened by ceil(|k| H), bilinear, "
            "BORDER_REPLICATE (cv2.warpAffine)",
            "threads": {
                "opencv_default": default_threads,
                "opencv_runs": [1, default_threads],
                "mediapipe": "its own default (not settable through mp.solutions)",
                "unshear": "rayon's default pool (one thread per core); the frame also with "
                "estimate_many(threads=1)",
            },
            "frame_runs": args.frame_runs,
            "mesh_match_eye_distances": MESH_MATCH,
        },
        "skipped": skipped,
        "photos": {"methods": summaries},
        "frame": {**frame_info, "times": frame_times},
    }
    table = markdown(result)
    result["markdown"] = table
    print(table)
    for name, why_skipped in skipped.items():
        print(f"\nskipped {name}: {why_skipped}")
    print(
        f"\n{len(photos)} photos, {n_faces} faces; OpenCV {cv2.__version__}, MediaPipe "
        f"{result['versions']['mediapipe']}, numpy {np.__version__}, unshear "
        f"{unshear.__version__} ({result['versions']['unshear_commit']}); "
        f"{result['machine']['cpu_model']}; {result['date']}"
    )
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(result, indent=1) + "\n")
        print(f"wrote {args.out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())

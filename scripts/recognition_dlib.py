#!/usr/bin/env python3
"""The paper's Table I with a real recogniser: dlib's ResNet face embeddings (issue 61).

Per identity the first 3 images by file name are the gallery, the rest probes (the protocol of
`unshear eval recognition`). Each probe's rows within 1.5 face heights of its face (`frame_rows`)
are sheared by `k` and cut to the rectangle a camera delivers (`unshear.distort(...,
canvas="crop")`), then recognised four ways: undistorted (the
baseline), sheared as it is (*raw*), corrected by `unshear` (`Unshear.estimate` then `correct`;
a probe the tool gives no `k` goes to the recogniser as it is, as a pipeline would pass it on),
and corrected with the true `k` (the ceiling). With `--camera` each probe is also made as a
panning camera would (see `camera_like`): a pan speeding up during the readout, a small vertical
stretch, motion blur along the rows, sensor noise and JPEG; corrected with and without
`blur="auto"` (`correct --deblur`), and with the nominal `k` as the ceiling.

The recogniser: dlib's frontal HOG detector (upsampled once; the face nearest the image's
centre), its 5-point shape predictor and the ResNet embedding (`face-recognition-models`),
classified by the nearest gallery embedding (Euclidean). A probe without a detected face is a
miss. On LFW only identities the networks are never trained on are probes (odd positions of the
sorted names, `unshear::dev::dataset::lfw_trained_identity`); every identity enrols.

    python -m venv /tmp/dlibv && /tmp/dlibv/bin/pip install -r scripts/requirements-dlib.txt ./python
    /tmp/dlibv/bin/python scripts/recognition_dlib.py ../shared/data --camera --json out.json
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from collections import defaultdict
from dataclasses import dataclass, field
from multiprocessing import get_context
from pathlib import Path
from typing import Any, Callable

import numpy as np
import numpy.typing as npt

Image = npt.NDArray[Any]
SHEARS = (0.14, 0.20, 0.33, 0.40)
GALLERY = 3


@dataclass(frozen=True)
class Labelled:
    identity: str
    path: Path


def identity_list(root: Path) -> list[Labelled]:
    """`root/identity.txt` lines `<file> <identity>`, images in `root/images/`."""
    out = []
    for line in (root / "identity.txt").read_text().splitlines():
        parts = line.split()
        if len(parts) == 2:
            out.append(Labelled(parts[1], root / "images" / parts[0]))
    return out


def yale(root: Path) -> list[Labelled]:
    """`root/images/subjectNN.condition[.jpeg]`: identity is the part before the first dot."""
    return [
        Labelled(p.name.split(".", 1)[0], p) for p in (root / "images").iterdir() if "." in p.name
    ]


def split(items: list[Labelled]) -> tuple[list[Labelled], list[Labelled]]:
    """The first `GALLERY` images by file name of each identity enrol, the rest are probes."""
    items = sorted(items, key=lambda i: (i.identity, i.path.name))
    seen: dict[str, int] = defaultdict(int)
    gallery: list[Labelled] = []
    probes: list[Labelled] = []
    for item in items:
        seen[item.identity] += 1
        (gallery if seen[item.identity] <= GALLERY else probes).append(item)
    return gallery, probes


def lfw_untrained(items: list[Labelled]) -> set[str]:
    """LFW identities the networks never train on: odd positions of the sorted names."""
    names = sorted({i.identity for i in items})
    return {n for i, n in enumerate(names) if i % 2 == 1}


def box_blur_rows(img: Image, length: float) -> Image:
    """A horizontal box of `length` pixels (fractional ends weighted), edges replicated."""
    if length <= 1.0:
        return img
    half = length / 2.0
    n = int(np.ceil(half))
    taps = np.ones(2 * n + 1)
    taps[0] = taps[-1] = half - (n - 1) - 0.5 if n >= 1 else 1.0
    taps = np.clip(taps, 0.0, 1.0)
    taps /= taps.sum()
    f = img.astype(np.float64)
    pad = [(0, 0), (n, n)] + [(0, 0)] * (img.ndim - 2)
    p = np.pad(f, pad, mode="edge")
    out = np.zeros_like(f)
    for i, t in enumerate(taps):
        out += t * p[:, i : i + f.shape[1]]
    return out


def shift_rows(img: Image, offsets: npt.NDArray[np.float64], scale_y: float) -> Image:
    """Row `y` of the output is the input's row `c + (y - c) / scale_y` moved right by
    `offsets[y]` (linear interpolation), cut to the columns every row covers."""
    f = img.astype(np.float64)
    h, w = f.shape[:2]
    c = h / 2.0
    src_y = np.clip(c + (np.arange(h) + 0.5 - c) / scale_y - 0.5, 0, h - 1)
    y0 = np.floor(src_y).astype(int)
    y1 = np.minimum(y0 + 1, h - 1)
    wy = (src_y - y0).reshape((h,) + (1,) * (f.ndim - 1))
    f = f[y0] * (1 - wy) + f[y1] * wy
    lo = int(np.ceil(offsets.max()))
    hi = int(np.floor(w + offsets.min()))
    if hi <= lo:
        raise ValueError("no column is covered by every row")
    xs = np.arange(lo, hi, dtype=np.float64)
    out = np.empty((h, len(xs)) + f.shape[2:])
    for y in range(h):
        src = xs - offsets[y]
        if f.ndim == 2:
            out[y] = np.interp(src, np.arange(w), f[y])
        else:
            for ch in range(f.shape[2]):
                out[y, :, ch] = np.interp(src, np.arange(w), f[y, :, ch])
    return out


def camera_like(img: Image, k: float, seed: int) -> Image:
    """What a panning rolling-shutter camera makes of `img`: the readout takes `RHO = 0.8` of
    the frame interval; the pan's speed at the middle row gives the shear `k` and grows by half
    over one frame interval (so the rows' offsets bend: the local shear is `k (1 + 0.4 (y - c)
    / H)`); a vertical drift stretches the rows by 2%; the 0.12-frame exposure (1/250 s at 30
    frames/s) blurs along the rows by `0.12 |v|` px (`v = k H / RHO`: 15 px at k = 0.4 in a
    250-row photo); sensor noise of 2 grey levels; JPEG at quality 85."""
    rho, accel, exposure = 0.8, 0.5, 0.12
    h = img.shape[0]
    s = rho * (np.arange(h) + 0.5 - h / 2.0) / h
    v0 = k * h / rho
    offsets = v0 * (s + accel * s * s / 2.0)
    blurred = box_blur_rows(img, abs(v0) * exposure)
    out = shift_rows(blurred, offsets, 1.02)
    rng = np.random.default_rng(seed)
    out = out + rng.normal(0.0, 2.0, out.shape)
    return jpeg(np.clip(np.rint(out), 0, 255).astype(np.uint8), 85)


def jpeg(img: Image, quality: int) -> Image:
    import unshear

    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "probe.jpg"
        unshear.write(path, img, jpeg_quality=quality)
        return np.asarray(unshear.read(path))


class Recogniser:
    """dlib's detector, 5-point shape predictor and ResNet embedding."""

    def __init__(self) -> None:
        import dlib
        import face_recognition_models as models

        self.detector = dlib.get_frontal_face_detector()
        self.shape = dlib.shape_predictor(models.pose_predictor_five_point_model_location())
        self.net = dlib.face_recognition_model_v1(models.face_recognition_model_location())

    def embed(self, img: Image) -> npt.NDArray[np.float64] | None:
        rgb = np.ascontiguousarray(to_rgb8(img))
        faces = self.detector(rgb, 1)
        if len(faces) == 0:
            return None
        h, w = rgb.shape[:2]

        def off_centre(r: Any) -> float:
            return float(
                ((r.left() + r.right()) / 2 - w / 2) ** 2
                + ((r.top() + r.bottom()) / 2 - h / 2) ** 2
            )

        face = min(faces, key=off_centre)
        return np.asarray(self.net.compute_face_descriptor(rgb, self.shape(rgb, face)))


def frame_rows(rec: Recogniser, img: Image) -> Image:
    """The rows a camera framing the face would read: within 1.5 face-box heights of the box's
    centre (three boxes high, as `eval shear --context 3`), the whole photo when dlib finds no
    face. Yale's and LFW's photos are about that high already; CelebA's tall portraits would
    otherwise lose most of their width to the shear's cut (`|k|` times the rows read)."""
    rgb = np.ascontiguousarray(to_rgb8(img))
    faces = rec.detector(rgb, 1)
    if len(faces) == 0:
        return img
    h, w = rgb.shape[:2]
    f = min(
        faces,
        key=lambda r: (
            ((r.left() + r.right()) / 2 - w / 2) ** 2 + ((r.top() + r.bottom()) / 2 - h / 2) ** 2
        ),
    )
    centre, half = (f.top() + f.bottom()) / 2, 1.5 * (f.bottom() - f.top())
    y0, y1 = max(0, int(centre - half)), min(h, int(np.ceil(centre + half)))
    return img[y0:y1]


def to_rgb8(img: Image) -> Image:
    a = np.asarray(img)
    if a.dtype != np.uint8:
        a = np.clip(np.rint(a), 0, 255).astype(np.uint8)
    if a.ndim == 2:
        a = np.stack([a] * 3, axis=-1)
    elif a.shape[2] == 1:
        a = np.concatenate([a] * 3, axis=-1)
    elif a.shape[2] == 4:
        a = a[:, :, :3]
    return a


_WORKER: dict[str, Any] = {}


def init_worker() -> None:
    import unshear

    _WORKER["rec"] = Recogniser()
    _WORKER["unshear"] = unshear.Unshear()


def correct(probe: Image, blur: str | None = None) -> tuple[Image, float | None, str]:
    """The tool's correction of `probe` (as it is when no `k` is found), the `k`, and why none."""
    tool = _WORKER["unshear"]
    report = tool.estimate(probe)
    if report.k is None:
        reasons = [f.refused for f in report.faces if getattr(f, "refused", None)]
        why = "no_face" if not report.faces else (reasons[0] if reasons else "no_k")
        return probe, None, str(why)
    return tool.correct(probe, report=report, blur=blur), report.k, ""


@dataclass
class ProbeResult:
    identity: str
    file: str
    embeddings: dict[str, list[float] | None] = field(default_factory=dict)
    k: dict[str, float | None] = field(default_factory=dict)
    refused: dict[str, str] = field(default_factory=dict)


def run_probe(args: tuple[Labelled, tuple[float, ...], bool, int]) -> ProbeResult:
    import unshear

    item, shears, camera, seed = args
    rec: Recogniser = _WORKER["rec"]
    img = np.asarray(unshear.read(item.path))
    out = ProbeResult(item.identity, item.path.name)

    def put(name: str, im: Image) -> None:
        e = rec.embed(im)
        out.embeddings[name] = None if e is None else e.tolist()

    def variants(k: float, make: Callable[[float], Image], names: tuple[str, str, str]) -> None:
        """The probe `make(k)` gives, recognised raw, corrected by unshear and corrected with `k`
        (no frame when no column is covered by every row: nothing to recognise)."""
        raw, corrected, nominal = (f"{n}@{k}" for n in names)
        try:
            probe = make(k)
        except ValueError:
            out.refused[corrected] = "no_frame"
            return
        put(raw, probe)
        fixed, out.k[corrected], out.refused[corrected] = correct(probe)
        put(corrected, fixed)
        put(nominal, unshear.distort(probe, -k))
        if names[0].startswith("camera"):
            fixed, out.k[f"camera-deblurred@{k}"], _ = correct(probe, blur="auto")
            put(f"camera-deblurred@{k}", fixed)

    put("undistorted", img)
    img = frame_rows(rec, img)
    for k in shears:
        variants(k, lambda k: unshear.distort(img, k, canvas="crop"), ("raw", "corrected", "true"))
        if camera:
            names = ("camera-raw", "camera-corrected", "camera-nominal")
            variants(k, lambda k: camera_like(img, k, seed), names)
    return out


def run_gallery(item: Labelled) -> tuple[str, list[float] | None]:
    import unshear

    e = _WORKER["rec"].embed(np.asarray(unshear.read(item.path)))
    return item.identity, None if e is None else e.tolist()


def rank1(
    results: list[ProbeResult], gallery: list[tuple[str, list[float] | None]], name: str
) -> float:
    ids = [i for i, e in gallery if e is not None]
    g = np.array([e for _, e in gallery if e is not None])
    hits = 0
    for r in results:
        e = r.embeddings.get(name)
        if e is None:
            continue
        d = np.linalg.norm(g - np.asarray(e), axis=1)
        hits += ids[int(np.argmin(d))] == r.identity
    return 100.0 * hits / max(len(results), 1)


def evaluate(
    name: str,
    items: list[Labelled],
    probe_ids: set[str] | None,
    shears: tuple[float, ...],
    camera: bool,
    max_probes: int,
    jobs: int,
) -> dict[str, Any]:
    gallery_items, probes = split(items)
    if probe_ids is not None:
        probes = [p for p in probes if p.identity in probe_ids]
    if max_probes > 0:
        kept: dict[str, int] = defaultdict(int)
        capped = []
        for p in probes:
            kept[p.identity] += 1
            if kept[p.identity] <= max_probes:
                capped.append(p)
        probes = capped
    start = time.time()
    with get_context("spawn").Pool(jobs, initializer=init_worker) as pool:
        gallery = pool.map(run_gallery, gallery_items, chunksize=4)
        work = [(p, shears, camera, i) for i, p in enumerate(probes)]
        results = []
        for i, r in enumerate(pool.imap(run_probe, work, chunksize=2)):
            results.append(r)
            if (i + 1) % 50 == 0:
                print(f"  {name}: {i + 1}/{len(probes)} probes", file=sys.stderr)
    table: dict[str, Any] = {
        "set": name,
        "identities": len({i.identity for i in items}),
        "gallery": sum(e is not None for _, e in gallery),
        "gallery_images": len(gallery_items),
        "probes": len(results),
        "seconds": round(time.time() - start, 1),
        "baseline": rank1(results, gallery, "undistorted"),
        "baseline_found": found(results, "undistorted"),
        "shears": [],
    }
    kinds = ["raw", "corrected", "true"]
    if camera:
        kinds += ["camera-raw", "camera-corrected", "camera-deblurred", "camera-nominal"]
    for k in shears:
        row: dict[str, Any] = {"k": k}
        for kind in kinds:
            key = f"{kind}@{k}"
            row[kind] = rank1(results, gallery, key)
            row[f"{kind}_found"] = found(results, key)
        for kind in ("corrected", "camera-corrected"):
            key = f"{kind}@{k}"
            ks = [v for r in results if (v := r.k.get(key)) is not None]
            if not ks and kind != "corrected":
                continue
            row[f"{kind}_median_k"] = float(np.median(ks)) if ks else None
            row[f"{kind}_within_0.05"] = 100.0 * sum(abs(x - k) <= 0.05 for x in ks) / len(results)
            reasons: dict[str, int] = defaultdict(int)
            for r in results:
                if r.k.get(key) is None:
                    reasons[r.refused.get(key, "") or "none"] += 1
            row[f"{kind}_not_corrected"] = dict(reasons)
        table["shears"].append(row)
    return table


def found(results: list[ProbeResult], key: str) -> float:
    return 100.0 * sum(r.embeddings.get(key) is not None for r in results) / max(len(results), 1)


def markdown(t: dict[str, Any], camera: bool) -> str:
    ks = [r["k"] for r in t["shears"]]
    head = "| " + t["set"] + " | " + " | ".join(f"k = {k:.2f}" for k in ks) + " |"
    lines = [head, "|---" + "|---:" * len(ks) + "|"]

    def row(label: str, fmt: Any) -> None:
        lines.append(f"| {label} | " + " | ".join(fmt(r) for r in t["shears"]) + " |")

    def pct(key: str) -> Any:
        return lambda r: f"{r[key]:.1f}%"

    row("median estimated k", lambda r: f"{r['corrected_median_k']:.3f}")
    row("estimate within 0.05", pct("corrected_within_0.05"))
    row("rank-1, raw sheared", pct("raw"))
    row("rank-1, corrected", pct("corrected"))
    row("rank-1, corrected with the true k", pct("true"))
    if camera:
        row("camera-like: rank-1 raw", pct("camera-raw"))
        row("camera-like: corrected", pct("camera-corrected"))
        row('camera-like: corrected, `blur="auto"`', pct("camera-deblurred"))
        row("camera-like: corrected with the nominal k", pct("camera-nominal"))
    lines.append(
        f"\n{t['set']}: {t['identities']} identities, {t['probes']} probes, baseline "
        f"(undistorted) {t['baseline']:.1f}%, face found {t['baseline_found']:.1f}%; "
        f"{t['seconds']} s"
    )
    return "\n".join(lines)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("data", type=Path, help="the development data folder (../shared/data)")
    ap.add_argument("--sets", default="yale,lfw,celeba", help="comma-separated: yale,lfw,celeba")
    ap.add_argument("--shears", default=",".join(map(str, SHEARS)))
    ap.add_argument("--camera", action="store_true", help="also camera-like probes")
    ap.add_argument("--max-probes", type=int, default=0, help="probes per identity (0: all)")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--json", type=Path, help="write the tables as JSON")
    a = ap.parse_args()
    shears = tuple(float(s) for s in a.shears.split(","))

    def lfw() -> tuple[list[Labelled], set[str] | None]:
        items = identity_list(a.data / "lfw-subset")
        return items, lfw_untrained(items)

    def celeba() -> tuple[list[Labelled], set[str] | None]:
        return identity_list(a.data / "celeba-subset"), None

    def yale_set() -> tuple[list[Labelled], set[str] | None]:
        return yale(a.data / "yale-faces"), None

    loaders = {"yale": yale_set, "lfw": lfw, "celeba": celeba}
    tables = []
    for name in a.sets.split(","):
        if name not in loaders:
            print(f"error: unknown set {name!r} (yale, lfw, celeba)", file=sys.stderr)
            return 2
        try:
            items, probe_ids = loaders[name]()
        except OSError as e:
            print(f"error: cannot read the {name} set: {e}", file=sys.stderr)
            return 1
        t = evaluate(name, items, probe_ids, shears, a.camera, a.max_probes, a.jobs)
        tables.append(t)
        print(markdown(t, a.camera), flush=True)
        print(flush=True)
    if a.json:
        a.json.write_text(json.dumps(tables, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

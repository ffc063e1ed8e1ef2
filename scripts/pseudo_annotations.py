#!/usr/bin/env python3
"""Writes the faces of an `unshear estimate --json` run as a ground-truth file in the Caltech
Web Faces format, so that `unshear eval shear --data DIR` can shear photos that carry no
annotations (the CelebA subset) and measure how the estimates follow the shear.

Each reported face, accepted or refused, becomes one line: the file name, then its right eye,
left eye, nose and mouth (the nostrils' midpoint for either when the locator gave none),
1-based as the Caltech file is. The true shear of every
face is then what the eval applies, the photo itself taken as unsheared; the faces are those
the pipeline found unsheared, so "found" in that eval counts how many stay found under shear,
not how many the photos hold.

Usage (docs/accuracy.md#other-photos-celeba):
    unshear estimate ../shared/data/celeba-subset/images --json > target/celeba-k0.jsonl
    python3 scripts/pseudo_annotations.py target/celeba-k0.jsonl > target/celeba/ground_truth.txt

The landmark network's shear-only training faces (models/README.md, `landmarks.bin`) keep only
the faces the pipeline accepted with a confident reading and eyes far enough apart, name the
photos relative to the data set's image folder (ORL's photos are `sN/M.pgm`), and, for the LFW
photos (centred on the person the identity list names), only the face whose box holds the
photo's centre:
    python3 scripts/pseudo_annotations.py lfw-k0.jsonl --accepted-only --min-confidence 0.5 \
        --min-eye 15 --relative-to ../shared/data/lfw-subset/images --centre 124.5,124.5
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from pathlib import PurePath
from typing import Any

# dev::dataset::CALTECH_PIXEL_ORIGIN: the Caltech file counts pixels from 1.
PIXEL_ORIGIN = 1.0

Point = list[float]


def midpoint(a: Point, b: Point) -> Point:
    return [(a[0] + b[0]) / 2.0, (a[1] + b[1]) / 2.0]


def face_line(name: str, face: dict[str, Any]) -> str:
    """One ground-truth line for `face` of the photo `name`."""
    nostrils = midpoint(face["right_nostril"], face["left_nostril"])
    nose = face.get("nose") or nostrils
    mouth = face.get("mouth") or nostrils
    points = [face["right_eye"], face["left_eye"], nose, mouth]
    coords = " ".join(f"{p[0] + PIXEL_ORIGIN:.4f} {p[1] + PIXEL_ORIGIN:.4f}" for p in points)
    return f"{name} {coords}"


def keep(face: dict[str, Any], args: argparse.Namespace) -> bool:
    """Whether `face` passes the filters the options ask for."""
    if args.accepted_only and face.get("refused") is not None:
        return False
    if face.get("confidence", 0.0) < args.min_confidence:
        return False
    return math.dist(face["right_eye"], face["left_eye"]) >= args.min_eye


def holds(face: dict[str, Any], point: tuple[float, float]) -> bool:
    """Whether the face's box `[x, y, width, height]` holds `point`."""
    x, y, w, h = face["box"]
    return x <= point[0] <= x + w and y <= point[1] <= y + h


def central(faces: list[dict[str, Any]], point: tuple[float, float]) -> list[dict[str, Any]]:
    """The face whose box holds `point`, nearest by its eyes' midpoint when several do."""
    inside = [f for f in faces if holds(f, point)]

    def distance(f: dict[str, Any]) -> float:
        mid = midpoint(f["right_eye"], f["left_eye"])
        return math.dist(mid, point)

    return sorted(inside, key=distance)[:1]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("estimates", help="JSON lines from `unshear estimate --json`")
    parser.add_argument(
        "--accepted-only", action="store_true", help="leave out the refused estimates' faces"
    )
    parser.add_argument(
        "--min-confidence", type=float, default=0.0, help="leave out faces below this confidence"
    )
    parser.add_argument(
        "--min-eye", type=float, default=0.0, help="leave out faces with eyes closer (pixels)"
    )
    parser.add_argument(
        "--relative-to",
        metavar="DIR",
        help="name each photo by its path relative to DIR (default: its file name)",
    )
    parser.add_argument(
        "--centre",
        metavar="X,Y",
        help="keep only the face whose box holds this point (0-based pixels) of each photo",
    )
    args = parser.parse_args()
    centre = tuple(float(v) for v in args.centre.split(",")) if args.centre else None
    faces = 0
    with open(args.estimates, encoding="utf-8") as f:
        for line in f:
            if not line.strip():
                continue
            report = json.loads(line)
            if args.relative_to:
                name = os.path.relpath(report["file"], args.relative_to)
            else:
                name = PurePath(report["file"]).name
            found = report.get("faces") or []
            if centre is not None:
                found = central(found, centre)
            for face in found:
                if keep(face, args):
                    print(face_line(name, face))
                    faces += 1
    print(f"{faces} faces", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())

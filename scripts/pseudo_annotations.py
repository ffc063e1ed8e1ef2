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
"""

from __future__ import annotations

import argparse
import json
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


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("estimates", help="JSON lines from `unshear estimate --json`")
    args = parser.parse_args()
    faces = 0
    with open(args.estimates, encoding="utf-8") as f:
        for line in f:
            if not line.strip():
                continue
            report = json.loads(line)
            name = PurePath(report["file"]).name
            for face in report.get("faces") or []:
                print(face_line(name, face))
                faces += 1
    print(f"{faces} faces", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())

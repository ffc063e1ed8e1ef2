#!/usr/bin/env python3
"""How alt2's face boxes compare with haarcascade_frontalface_default's for the same faces: the
source of `DEFAULT_CASCADE_BOX_SCALE` (src/pipeline.rs), which maps the fallback cascade's boxes
onto alt2's.

For the first 400 Caltech development images that no accuracy table measures (no annotated face
with eyes 40 px or more apart), both cascades run with OpenCV's
detectMultiScale(gray, 1.1, 3); each alt2 box is paired with the default box of highest IoU
(> 0.5), and the median of (x offset / width, y offset / height, alt2 width / default width)
is printed with its quartiles.

Usage: python3 scripts/cascade_box_scale.py [../shared/data/caltech-webfaces]
Needs python3 with numpy and OpenCV (`pip install opencv-python-headless`).
"""
import glob
import os
import sys

import cv2
import numpy as np


def cascade(name):
    path = f"/usr/share/opencv4/haarcascades/{name}"
    if not os.path.exists(path):
        path = os.path.join(cv2.data.haarcascades, name)
    return cv2.CascadeClassifier(path)


def main():
    data = sys.argv[1] if len(sys.argv) > 1 else "../shared/data/caltech-webfaces"
    alt2 = cascade("haarcascade_frontalface_alt2.xml")
    default = cascade("haarcascade_frontalface_default.xml")
    widest = {}
    with open(os.path.join(data, "ground_truth.txt")) as f:
        for line in f:
            name, *xy = line.split()
            if len(xy) >= 4:
                eyes = float(xy[0]) - float(xy[2]), float(xy[1]) - float(xy[3])
                widest[name] = max(widest.get(name, 0.0), float(np.hypot(*eyes)))
    images = sorted(glob.glob(os.path.join(data, "images", "*.jpg")))
    rel = []
    for f in [f for f in images if widest.get(os.path.basename(f), 0.0) < 40.0][:400]:
        g = cv2.cvtColor(cv2.imread(f), cv2.COLOR_BGR2GRAY)
        others = default.detectMultiScale(g, 1.1, 3)
        for (x, y, w, h) in alt2.detectMultiScale(g, 1.1, 3):
            best = None
            for (X, Y, W, H) in others:
                ix = max(0, min(x + w, X + W) - max(x, X))
                iy = max(0, min(y + h, Y + H) - max(y, Y))
                iou = ix * iy / (w * h + W * H - ix * iy)
                if iou > 0.5 and (best is None or iou > best[0]):
                    best = (iou, X, Y, W, H)
            if best:
                _, X, Y, W, H = best
                rel.append(((x - X) / W, (y - Y) / H, w / W))
    rel = np.array(rel)
    print(f"{len(rel)} faces found by both")
    print("median dx/W, dy/H, scale:", np.median(rel, axis=0))
    print("quartiles:", np.percentile(rel, 25, axis=0), np.percentile(rel, 75, axis=0))


if __name__ == "__main__":
    main()

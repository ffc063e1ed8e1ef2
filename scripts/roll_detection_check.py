#!/usr/bin/env python3
"""Side check for future work: would roll hypotheses find the faces the detector misses?

For every face that `unshear eval shear` reports as not detected, rotate its image by
+-10, 20 and 30 degrees (canvas enlarged) and ask OpenCV's alt2 cascade (the one unshear
reproduces) for a box holding both annotated eyes (smallest box 60 px, as `eval shear` uses).

Usage:
  cargo run --release -- eval shear --limit 300 --k 0 --csv /tmp/k0.csv
  python3 scripts/roll_detection_check.py /tmp/k0.csv [../shared/data/caltech-webfaces]

Needs python3 with numpy and OpenCV (`pip install opencv-python-headless`), and the cascade
in /usr/share/opencv4/haarcascades (Debian's opencv-data) or cv2.data.
"""
import csv
import math
import os
import sys

import cv2
import numpy as np


def main():
    samples = sys.argv[1]
    data = sys.argv[2] if len(sys.argv) > 2 else "../shared/data/caltech-webfaces"
    xml = "/usr/share/opencv4/haarcascades/haarcascade_frontalface_alt2.xml"
    if not os.path.exists(xml):
        xml = os.path.join(cv2.data.haarcascades, "haarcascade_frontalface_alt2.xml")
    cascade = cv2.CascadeClassifier(xml)
    truth = {}
    for line in open(os.path.join(data, "ground_truth.txt")):
        p = line.split()
        truth.setdefault(p[0], []).append([float(v) for v in p[1:]])
    missed = [r for r in csv.DictReader(open(samples)) if r["detected"] == "false"]
    found = 0
    for r in missed:
        name = os.path.basename(r["image"])
        a = truth[name][int(r["face"])]
        eyes = [np.array(a[0:2]), np.array(a[2:4])]
        img = cv2.imread(os.path.join(data, "images", name), cv2.IMREAD_GRAYSCALE)
        h, w = img.shape
        roll = math.degrees(math.atan2(eyes[1][1] - eyes[0][1], eyes[1][0] - eyes[0][0]))
        hit = None
        for angle in [-10, 10, -20, 20, -30, 30]:
            m = cv2.getRotationMatrix2D((w / 2, h / 2), angle, 1.0)
            c, s = abs(m[0, 0]), abs(m[0, 1])
            nw, nh = int(h * s + w * c), int(h * c + w * s)
            m[0, 2] += nw / 2 - w / 2
            m[1, 2] += nh / 2 - h / 2
            view = cv2.warpAffine(img, m, (nw, nh))
            moved = [m @ np.array([e[0], e[1], 1.0]) for e in eyes]
            for (x, y, bw, bh) in cascade.detectMultiScale(view, 1.1, 3, minSize=(60, 60)):
                if all(x <= e[0] <= x + bw and y <= e[1] <= y + bh for e in moved):
                    hit = angle
                    break
            if hit is not None:
                break
        found += hit is not None
        print(f"{name} face {r['face']} k {r['true_k']}: roll {roll:.0f} deg, found at {hit}")
    print(f"{found} of {len(missed)} missed faces found in a rotated view")


if __name__ == "__main__":
    main()

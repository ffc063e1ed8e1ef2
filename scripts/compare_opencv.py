#!/usr/bin/env python3
"""Run OpenCV's Haar cascade detector on images and write the boxes as JSON.

This is the reference side of the OpenCV-agreement check (tests/opencv_agreement.rs):

    python3 scripts/compare_opencv.py --cascade models/haarcascade_frontalface_alt2.xml \
        --out /tmp/cv.json [--gray-dir /tmp/gray] [--limit N] IMAGE_OR_DIR...

For every image it loads BGR with cv2.imread, converts with cvtColor(BGR2GRAY) (the same
fixed-point formula as unshear::detect::to_gray_opencv) and runs
detectMultiScale(gray, scaleFactor, minNeighbors). With --gray-dir it also writes that grey
image as PNG so the Rust side can run on byte-identical input (this separates detector
differences from JPEG-decoder differences).

Output JSON: {"opencv_version": ..., "cascade": ..., "scale_factor": ..., "min_neighbors": ...,
"images": [{"path": ..., "gray": <png or null>, "width": w, "height": h,
"boxes": [[x, y, w, h], ...]}, ...]}

Exit status 3 when OpenCV (with CascadeClassifier: OpenCV 5 dropped it from the main module)
is not available, so callers can skip.
"""
import argparse
import json
import os
import sys

EXTS = (".jpg", ".jpeg", ".png", ".bmp", ".pgm", ".ppm", ".tif", ".tiff", ".webp")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("inputs", nargs="+", help="image files or folders")
    ap.add_argument("--cascade", required=True)
    ap.add_argument("--out", required=True, help="JSON output file")
    ap.add_argument("--gray-dir", help="also write the grey input images here as PNG")
    ap.add_argument("--scale-factor", type=float, default=1.1)
    ap.add_argument("--min-neighbors", type=int, default=3)
    ap.add_argument("--limit", type=int, default=0, help="at most N images per folder (sorted)")
    args = ap.parse_args()

    try:
        import cv2  # noqa: F401
    except ImportError:
        print("skipped: python module cv2 not found", file=sys.stderr)
        return 3
    if not hasattr(cv2, "CascadeClassifier"):
        print(f"skipped: cv2 {cv2.__version__} has no CascadeClassifier (need OpenCV 4)",
              file=sys.stderr)
        return 3

    clf = cv2.CascadeClassifier(args.cascade)
    if clf.empty():
        print(f"cannot load cascade {args.cascade}", file=sys.stderr)
        return 2
    # Single-threaded so the run is deterministic and comparable with our timing.
    cv2.setNumThreads(1)

    files = []
    for inp in args.inputs:
        if os.path.isdir(inp):
            names = sorted(n for n in os.listdir(inp) if n.lower().endswith(EXTS))
            if args.limit > 0:
                names = names[: args.limit]
            files += [os.path.join(inp, n) for n in names]
        else:
            files.append(inp)

    if args.gray_dir:
        os.makedirs(args.gray_dir, exist_ok=True)
    images = []
    for i, path in enumerate(files):
        bgr = cv2.imread(path, cv2.IMREAD_COLOR)
        if bgr is None:
            print(f"warning: cannot read {path}", file=sys.stderr)
            continue
        gray = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)
        gray_path = None
        if args.gray_dir:
            gray_path = os.path.join(args.gray_dir, f"{i:05d}.png")
            cv2.imwrite(gray_path, gray)
        boxes = clf.detectMultiScale(gray, args.scale_factor, args.min_neighbors)
        images.append({
            "path": os.path.abspath(path),
            "gray": os.path.abspath(gray_path) if gray_path else None,
            "width": int(gray.shape[1]),
            "height": int(gray.shape[0]),
            "boxes": [[int(v) for v in b] for b in boxes],
        })
    with open(args.out, "w") as f:
        json.dump({
            "opencv_version": cv2.__version__,
            "cascade": os.path.abspath(args.cascade),
            "scale_factor": args.scale_factor,
            "min_neighbors": args.min_neighbors,
            "images": images,
        }, f)
    print(f"{len(images)} images, {sum(len(im['boxes']) for im in images)} boxes -> {args.out}",
          file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())

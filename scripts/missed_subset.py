#!/usr/bin/env python3
"""Build a small Caltech-layout data set from the photos whose faces an `unshear eval shear` run
missed at one or more shears, to try detection changes on quickly.

    python3 scripts/missed_subset.py target/fullV4/samples.csv [more samples.csv ...] \
        --data ../shared/data/caltech-webfaces --out target/missed

Writes OUT/ground_truth.txt (every annotation row of those photos, in the data set's order) and
OUT/images/ (symbolic links to the photos), which `unshear eval shear --data OUT` reads. Only the
standard library is used.
"""

import argparse
import csv
import os
import sys


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("samples", nargs="+", help="samples.csv files of eval shear runs")
    parser.add_argument("--data", default="../shared/data/caltech-webfaces")
    parser.add_argument("--out", required=True)
    args = parser.parse_args()

    missed = set()
    for path in args.samples:
        with open(path, newline="") as f:
            for row in csv.DictReader(f):
                # Faces the camera's frame cut (`cut`, missing in older runs) were not missed.
                if row["detected"] != "true" and row.get("cut", "false") != "true":
                    missed.add(os.path.basename(row["image"]))
    if not missed:
        print("no missed faces in", args.samples, file=sys.stderr)
        return 1

    images = os.path.join(args.out, "images")
    os.makedirs(images, exist_ok=True)
    rows = []
    with open(os.path.join(args.data, "ground_truth.txt")) as f:
        for line in f:
            fields = line.split()
            if fields and fields[0] in missed:
                rows.append(line if line.endswith("\n") else line + "\n")
    with open(os.path.join(args.out, "ground_truth.txt"), "w") as f:
        f.writelines(rows)
    source = os.path.abspath(os.path.join(args.data, "images"))
    for name in sorted(missed):
        link = os.path.join(images, name)
        if not os.path.lexists(link):
            os.symlink(os.path.join(source, name), link)
    print(f"{len(missed)} photos, {len(rows)} annotated faces -> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

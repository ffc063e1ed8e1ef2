#!/usr/bin/env python3
"""Measures the yaw extrapolation factor of `estimate::YAW_EXTRAPOLATION` on located points.

For each beta, recomputes every sample's estimate as `k_mouth + beta (k_mouth - k_nose_tip)`
(the mouth alone when the nose tip is missing, the measured k when both are) from an
`unshear eval shear --out DIR` run and prints the share of faces within 0.05 of the truth per k
(of all faces at that k) and the median absolute error, next to the run's own `measured` k.

Usage (the figures in `estimate.rs` and the README):
    cargo run --release -- eval shear --limit 300 --k=0,0.4,-0.4 --out target/fit300
    cargo run --release -- eval shear --k=0,0.4,-0.4 --out target/all
    python3 scripts/yaw_factor.py target/fit300                  # choose beta on 300 faces
    python3 scripts/yaw_factor.py target/all --skip target/fit300  # check on the other 628

The figures were measured on runs of the build before the nose-tip model (UMACE filters, the
nostrils' axis with 0.5 as `measured`); `k_mouth` and `k_nose_tip` do not depend on beta, so a
run of a later build gives close figures, with its own model as `measured`. No packages needed.
"""
import json
import statistics
import sys

BETAS = (0.0, 0.1, 0.2, 0.3, 0.4, 0.5)


def estimate(s, beta):
    if s["k_mouth"] is not None and s["k_nose_tip"] is not None:
        return s["k_mouth"] + beta * (s["k_mouth"] - s["k_nose_tip"])
    if s["k_mouth"] is not None:
        return s["k_mouth"]
    return s["measured"]


def main():
    args = sys.argv[1:]
    if len(args) not in (1, 3) or args[0] in ("-h", "--help"):
        print(__doc__)
        return
    with open(args[0] + "/samples.json") as f:
        samples = json.load(f)
    if len(args) == 3 and args[1] == "--skip":
        with open(args[2] + "/samples.json") as f:
            skip = {(s["image"], s["face"]) for s in json.load(f)}
        samples = [s for s in samples if (s["image"], s["face"]) not in skip]
    shears = sorted({s["true_k"] for s in samples})
    print(f"{len({(s['image'], s['face']) for s in samples})} faces; within 0.05 at k = {shears}")
    rules = [("measured", lambda s: s["measured"])] + [
        (f"beta {b:.1f}", lambda s, b=b: estimate(s, b)) for b in BETAS
    ]
    for name, rule in rules:
        shares, errors = [], []
        for k in shears:
            at = [s for s in samples if s["true_k"] == k]
            err = [abs(rule(s) - k) for s in at if s["measured"] is not None]
            errors += err
            shares.append(100.0 * sum(e <= 0.05 for e in err) / len(at))
        cells = " / ".join(f"{v:.1f}%" for v in shares)
        print(f"{name:>9}: {cells}; median abs err {statistics.median(errors):.3f}")


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""Chooses the filters' yaw factors (`estimate::YAW_EXTRAPOLATION` and `_NOSTRILS`).

For each beta, recomputes every sample's estimate as `k_mouth + beta (k_mouth - k_nose)` from
`unshear eval shear --out DIR` runs, with the nose tip's axis (`k_nose_tip`, the nose filter's
point: `YAW_EXTRAPOLATION`) or the nostrils' axis (`k_nose`, used when the nose filter did not
run: `YAW_EXTRAPOLATION_NOSTRILS`), and prints per run the share of faces within 0.05 of the
truth per k (of all faces at that k) and the median absolute error, then the mean share over
all runs and shears. Samples without both axes keep the run's own estimate (`measured`).

The committed factors are chosen on the faces no accuracy table measures, with the runs that
fit the filters' confidence models (`scripts/regenerate-models --only confidence` leaves them in
target/regenerate/fit-{umace,asef,mosse}):

    python3 scripts/yaw_factor.py target/regenerate/fit-{umace,asef,mosse}
    python3 scripts/yaw_factor.py --axis nostrils target/regenerate/fit-{umace,asef,mosse}

No packages needed.
"""

from __future__ import annotations

import argparse
import json
import statistics

BETAS = (0.0, 0.1, 0.2, 0.3, 0.4, 0.5)
AXES = {"nose-tip": "k_nose_tip", "nostrils": "k_nose"}


def estimate(sample: dict, axis: str, beta: float) -> float | None:
    """The sample's estimate with factor `beta` on `axis`, or its own when an axis is missing."""
    mouth, nose = sample["k_mouth"], sample[axis]
    if mouth is not None and nose is not None:
        return mouth + beta * (mouth - nose)
    return sample["measured"]


def shares(samples: list[dict], axis: str, beta: float | None) -> tuple[list[float], float]:
    """Per true k, the share (%) of faces within 0.05; and the median absolute error."""
    shears = sorted({s["true_k"] for s in samples})
    per_shear, errors = [], []
    for k in shears:
        at = [s for s in samples if s["true_k"] == k]
        values = [s["measured"] if beta is None else estimate(s, axis, beta) for s in at]
        err = [
            abs(v - k) for v, s in zip(values, at) if v is not None and s["measured"] is not None
        ]
        errors += err
        per_shear.append(100.0 * sum(e <= 0.05 for e in err) / len(at))
    return per_shear, statistics.median(errors) if errors else float("nan")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", help="eval shear --out folders")
    parser.add_argument("--axis", choices=sorted(AXES), default="nose-tip")
    args = parser.parse_args()
    axis = AXES[args.axis]
    rules: list[tuple[str, float | None]] = [("measured", None)] + [
        (f"beta {b:.1f}", b) for b in BETAS
    ]
    means: dict[str, list[float]] = {name: [] for name, _ in rules}
    for run in args.runs:
        with open(f"{run}/samples.json") as f:
            samples = json.load(f)
        faces = len({(s["image"], s["face"]) for s in samples})
        both = sum(s["k_mouth"] is not None and s[axis] is not None for s in samples)
        shears = sorted({s["true_k"] for s in samples})
        print(f"{run}: {faces} faces, {both} samples with both axes; within 0.05 at k = {shears}")
        for name, beta in rules:
            per_shear, median = shares(samples, axis, beta)
            means[name] += per_shear
            cells = " / ".join(f"{v:.1f}%" for v in per_shear)
            print(f"{name:>9}: {cells}; median abs err {median:.3f}")
    print("mean share within 0.05 over all runs and shears:")
    for name, values in means.items():
        print(f"{name:>9}: {statistics.mean(values):.2f}%")


if __name__ == "__main__":
    main()

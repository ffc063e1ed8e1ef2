#!/usr/bin/env python3
"""Fits the confidence model of `pipeline::confidence` to an `unshear eval shear --out DIR` run.

The model is a logistic regression of "the measured k is within 0.10 of the true k" on the
features listed in FEATURES (the same, in the same order, as `pipeline::confidence` computes).
It prints the weights and intercept in Rust syntax, the two-fold cross-validated AUC (folds by
image, so that a face's shears never sit on both sides) and what several thresholds keep.

Usage (the figures in the README and in `pipeline.rs`):
    cargo run --release -- eval shear --limit 300 --k=0,0.4,-0.4 --out target/conf-fit
    python3 scripts/fit_confidence.py target/conf-fit [--check OTHER_RUN]

`--check` scores another run (for example the faces after the first 300) with the weights fitted
on the first, without refitting. Needs only numpy.
"""
import json
import math
import sys

import numpy as np

# pipeline::EYE_DISTANCE_PER_BOX_WIDTH
EYE_DISTANCE_PER_BOX_WIDTH = 0.381
GOOD = 0.10


def ln(v):
    return math.log(max(v, 0.1))


def features(s):
    psr = s["psr"]
    disagreement = (
        abs(s["k_nose_tip"] - s["k_mouth"])
        if s["k_nose_tip"] is not None and s["k_mouth"] is not None
        else 0.5
    )
    return [
        ln(min(psr[0], psr[1])),
        ln(min(psr[2], psr[3])),
        ln(psr[4]),
        ln(s["nose_tip_psr"] or 0.0),
        disagreement,
        abs(s["roll_degrees"]) / 10.0,
        abs(s["eye_box_ratio"] - EYE_DISTANCE_PER_BOX_WIDTH) * 10.0,
    ]


FEATURES = [
    "ln weaker eye PSR",
    "ln weaker nostril PSR",
    "ln mouth PSR",
    "ln nose-tip PSR",
    "|k_nose_tip - k_mouth|",
    "|roll| / 10 degrees",
    "|eye distance / box width - 0.381| * 10",
]


def load(run):
    with open(run + "/samples.json") as f:
        samples = json.load(f)
    rows = [s for s in samples if s["measured"] is not None]
    x = np.array([features(s) for s in rows])
    y = np.array([abs(s["measured"] - s["true_k"]) <= GOOD for s in rows], dtype=float)
    images = [s["image"] for s in rows]
    return x, y, images


def fit(x, y, ridge=1e-3):
    """Logistic regression by Newton's method (a small ridge keeps it finite if separable)."""
    a = np.hstack([x, np.ones((len(x), 1))])
    w = np.zeros(a.shape[1])
    for _ in range(50):
        p = 1.0 / (1.0 + np.exp(-a @ w))
        grad = a.T @ (p - y) + ridge * w
        hess = a.T @ (a * (p * (1 - p))[:, None]) + ridge * np.eye(len(w))
        step = np.linalg.solve(hess, grad)
        w -= step
        if np.abs(step).max() < 1e-10:
            break
    return w[:-1], w[-1]


def predict(x, weights, intercept):
    return 1.0 / (1.0 + np.exp(-(x @ weights + intercept)))


def auc(score, y):
    """Probability that a good estimate scores above a bad one (ties count half)."""
    order = np.argsort(score)
    ranks = np.empty(len(score))
    ranks[order] = np.arange(1, len(score) + 1)
    # Average ranks over ties.
    for v in np.unique(score):
        tied = score == v
        ranks[tied] = ranks[tied].mean()
    pos = y == 1
    n_pos, n_neg = pos.sum(), (~pos).sum()
    return (ranks[pos].sum() - n_pos * (n_pos + 1) / 2) / (n_pos * n_neg)


def report(name, x, y, weights, intercept):
    c = predict(x, weights, intercept)
    print(f"{name}: {len(y)} estimates, {100 * y.mean():.1f}% within {GOOD}; AUC {auc(c, y):.3f}")
    for t in (0.15, 0.2, 0.25, 0.3, 0.4, 0.5):
        kept = c >= t
        good = y[kept].mean() if kept.any() else float("nan")
        print(
            f"  threshold {t:.2f}: keeps {100 * kept.mean():.1f}%, of them {100 * good:.1f}% "
            f"within {GOOD}; refuses {int((~kept & (y == 1)).sum())} good, "
            f"keeps {int((kept & (y == 0)).sum())} bad"
        )


def main():
    args = sys.argv[1:]
    if not args or args[0] in ("-h", "--help"):
        print(__doc__)
        return
    x, y, images = load(args[0])
    # Two folds by image.
    names = sorted(set(images))
    fold = {n: i % 2 for i, n in enumerate(names)}
    f = np.array([fold[i] for i in images])
    for k in (0, 1):
        w, b = fit(x[f != k], y[f != k])
        print(f"fold {k}: held-out AUC {auc(predict(x[f == k], w, b), y[f == k]):.3f}")
    weights, intercept = fit(x, y)
    for name, w in zip(FEATURES, weights):
        print(f"  {w:+.3f}  {name}")
    print("const CONFIDENCE_WEIGHTS: [f64; %d] = [%s];" % (len(weights), ", ".join(f"{w:.3f}" for w in weights)))
    print(f"const CONFIDENCE_INTERCEPT: f64 = {intercept:.3f};")
    report(args[0], x, y, weights, intercept)
    if len(args) >= 3 and args[1] == "--check":
        xc, yc, _ = load(args[2])
        report(args[2], xc, yc, weights, intercept)


if __name__ == "__main__":
    main()

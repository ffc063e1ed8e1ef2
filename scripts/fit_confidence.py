#!/usr/bin/env python3
"""Fits the confidence model of `pipeline::confidence` (the filters' estimates) or, with
`--locator network`, of `pipeline::network_confidence` (the landmark network's) to an
`unshear eval shear --out DIR` run.

The model is a logistic regression of "the measured k is within 0.10 of the true k" on the
features listed in FEATURES (the same, in the same order, as `pipeline::confidence` computes).
It prints the weights and intercept in Rust syntax, the two-fold cross-validated AUC (folds by
image, so that a face's shears never sit on both sides) and what several thresholds keep.

Usage (the figures in the README and in `pipeline.rs`):
    cargo run --release -- eval shear --limit 300 --k=0,0.4,-0.4 --out target/fit300
    cargo run --release -- eval shear --k=0,0.4,-0.4 --out target/all
    python3 scripts/fit_confidence.py target/fit300 --check target/all      # UMACE's model
    python3 scripts/fit_confidence.py target/all --fit-first 300            # MOSSE's, ASEF's

`--check OTHER_RUN` fits on the first run and scores the faces of OTHER_RUN that are not in it
(`--limit 300` takes the first 300 faces of the ground-truth file). `--fit-first N` splits one
run instead: it fits on the first N faces in the run's own order (images sorted by path, which
is not the ground-truth file's order) and scores the others. Add `--filter-type T` to both
`eval` commands for type T. Needs only numpy.
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


def network_features(s):
    spread = s["spread"]
    k_points = s["k_points"]
    return [
        max(spread[0], spread[1]),
        spread[2],
        spread[3],
        abs(s["k_network"] - k_points) if k_points is not None else 0.5,
        abs(s["k_nose_tip"] - s["k_mouth"])
        if s["k_nose_tip"] is not None and s["k_mouth"] is not None
        else 0.5,
        abs(s["roll_degrees"]) / 10.0,
        abs(s["eye_box_ratio"] - EYE_DISTANCE_PER_BOX_WIDTH) * 10.0,
    ]


NETWORK_FEATURES = [
    "wider eye heatmap spread (eye distances)",
    "nose heatmap spread",
    "mouth heatmap spread",
    "|k_network - k_points|",
    "|k_nose - k_mouth| (network axes)",
    "|roll| / 10 degrees",
    "|eye distance / box width - 0.381| * 10",
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


def load_samples(run):
    with open(run + "/samples.json") as f:
        return json.load(f)


def face_key(s):
    return (s["image"], s["face"])


def arrays(samples):
    rows = [s for s in samples if s["measured"] is not None]
    x = np.array([FEATURE_FN(s) for s in rows])
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


FEATURE_FN = features


def main():
    global FEATURE_FN, FEATURES
    args = sys.argv[1:]
    if "--locator" in args:
        i = args.index("--locator")
        if args[i + 1] == "network":
            FEATURE_FN, FEATURES = network_features, NETWORK_FEATURES
        del args[i : i + 2]
    if not args or args[0] in ("-h", "--help") or len(args) not in (1, 3):
        print(__doc__)
        return
    fit_samples = load_samples(args[0])
    check = None
    if len(args) == 3 and args[1] == "--check":
        fitted = {face_key(s) for s in fit_samples}
        check = [s for s in load_samples(args[2]) if face_key(s) not in fitted]
    elif len(args) == 3 and args[1] == "--fit-first":
        order = list(dict.fromkeys(face_key(s) for s in fit_samples))
        first = set(order[: int(args[2])])
        check = [s for s in fit_samples if face_key(s) not in first]
        fit_samples = [s for s in fit_samples if face_key(s) in first]
    x, y, images = arrays(fit_samples)
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
    print(
        ("ConfidenceModel::NETWORK = ConfidenceModel" if FEATURE_FN is network_features else "ConfidenceModel")
        + " { weights: [%s], intercept: %.3f }"
        % (", ".join(f"{w:.3f}" for w in weights), intercept)
    )
    report("fitted", x, y, weights, intercept)
    if check is not None:
        faces = len({face_key(s) for s in check})
        xc, yc, _ = arrays(check)
        report(f"checked ({faces} other faces)", xc, yc, weights, intercept)


if __name__ == "__main__":
    main()

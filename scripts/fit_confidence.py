#!/usr/bin/env python3
"""Fits a confidence model (`pipeline::confidence`) to an `unshear eval shear --out DIR` run:
the filters' model of one filter type (`--model umace|asef|mosse`, the features of
`confidence`) or the landmark network's (`--model network`, the features of
`network_confidence`), and with `--write-rust` writes it into `src/fitted.rs`.

The model is a logistic regression of "the measured k is within 0.10 of the true k" on the
features listed in FEATURES or NETWORK_FEATURES (the same, in the same order, as the Rust
functions compute), over the estimates that no rule refused (a rule's refusal does not depend on
the confidence). It prints the weights and intercept, the two-fold cross-validated AUC (folds by
image, so that a face's shears never sit on both sides) and what several thresholds keep.

The models are fitted on faces that no accuracy table measures and the landmark network was
never trained on (`eval shear --faces unseen`: in the development photos whose faces all have
eyes under 40 px apart, those held out of the network's training or smaller than it trains on),
and may be checked on the faces the tables measure.

Usage (`scripts/regenerate-models --only confidence` runs these for every model):
    cargo run --release -- eval shear --faces unseen --min-eye-distance 12 --k=0,0.2,-0.2,0.4,-0.4 --locator filters --filter-type mosse --out target/fit-mosse
    python3 scripts/fit_confidence.py target/fit-mosse --model mosse --write-rust src/fitted.rs
    cargo run --release -- eval shear --faces unseen --min-eye-distance 12 --k=0,0.2,-0.2,0.4,-0.4 --min-confidence 0 --out target/fit-network
    python3 scripts/fit_confidence.py target/fit-network --model network --write-rust src/fitted.rs

`--check OTHER_RUN` also scores the faces of OTHER_RUN that are not in the fitted run (for
example the measured faces, `eval shear --min-confidence 0 --out OTHER_RUN`); `--fit-first N`
instead fits on the first N faces in the run's own order (images sorted by path, which is not
the ground-truth file's order) and scores the others. `--fitted-on TEXT` names the command that
made the run in the generated comment. Needs only numpy.
"""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Callable
from typing import Any

import numpy as np
from fitted_rust import Block, fit_doc, replace_block

# detect::boxes::EYE_DISTANCE_PER_BOX_WIDTH
EYE_DISTANCE_PER_BOX_WIDTH = 0.381
GOOD = 0.10

Sample = dict[str, Any]


def ln(v: float) -> float:
    """The natural logarithm, with values below 0.1 taken as 0.1 (as the Rust code does)."""
    return math.log(max(v, 0.1))


def features(s: Sample) -> list[float]:
    """The features of `pipeline::confidence::confidence` (the filters)."""
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


def network_features(s: Sample) -> list[float]:
    """The features of `pipeline::confidence::network_confidence` (the landmark network)."""
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

# Each model's features, as a function and as names.
MODELS: dict[str, tuple[Callable[[Sample], list[float]], list[str]]] = {
    "umace": (features, FEATURES),
    "asef": (features, FEATURES),
    "mosse": (features, FEATURES),
    "network": (network_features, NETWORK_FEATURES),
}


def load_samples(run: str) -> list[Sample]:
    """The samples of an `eval shear --out` run."""
    with open(run + "/samples.json", encoding="utf-8") as f:
        samples: list[Sample] = json.load(f)
    return samples


def face_key(s: Sample) -> tuple[str, int]:
    """What identifies a face across its shears."""
    return (s["image"], s["face"])


def refused_by_rule(s: Sample) -> bool:
    """Whether a rule (not the confidence) refused the estimate."""
    return s.get("refused") not in (None, "low_confidence")


def load_false_faces(run: str) -> list[Sample]:
    """The faces reported on the run's photos with their annotated faces painted over
    (`eval shear --face-free`; none without it): false faces, or real faces the annotations
    leave out, whose estimates count as bad."""
    try:
        with open(run + "/face_free.json", encoding="utf-8") as f:
            photos: list[dict[str, Any]] = json.load(f)
    except FileNotFoundError:
        return []
    return [{**face, "false_face": True} for p in photos for face in p["found"]]


def arrays(
    samples: list[Sample], feature_fn: Callable[[Sample], list[float]]
) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """The features, the labels (within GOOD or not; a false face never is) and the images of
    the measured samples."""
    rows = [s for s in samples if s["measured"] is not None and not refused_by_rule(s)]
    x = np.array([feature_fn(s) for s in rows])
    y = np.array(
        [not s.get("false_face") and abs(s["measured"] - s["true_k"]) <= GOOD for s in rows],
        dtype=float,
    )
    images = [s["image"] for s in rows]
    return x, y, images


def fit(x: np.ndarray, y: np.ndarray, ridge: float = 1e-3) -> tuple[np.ndarray, float]:
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
    return w[:-1], float(w[-1])


def predict(x: np.ndarray, weights: np.ndarray, intercept: float) -> np.ndarray:
    """The model's probabilities."""
    return 1.0 / (1.0 + np.exp(-(x @ weights + intercept)))


def auc(score: np.ndarray, y: np.ndarray) -> float:
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
    return float((ranks[pos].sum() - n_pos * (n_pos + 1) / 2) / (n_pos * n_neg))


def report(name: str, x: np.ndarray, y: np.ndarray, weights: np.ndarray, intercept: float) -> None:
    """Prints the AUC and what several thresholds keep."""
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


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("run", help="folder of an `eval shear --out` run")
    parser.add_argument("--model", required=True, choices=list(MODELS))
    split = parser.add_mutually_exclusive_group()
    split.add_argument("--fit-first", type=int, metavar="N", help="fit on the run's first N faces")
    split.add_argument("--check", metavar="OTHER_RUN", help="score the faces of another run")
    parser.add_argument("--write-rust", metavar="FILE", help="write the model here (src/fitted.rs)")
    parser.add_argument(
        "--fitted-on",
        metavar="TEXT",
        help="what made the run, for the generated comment (default: the run's path)",
    )
    args = parser.parse_args()
    feature_fn, names = MODELS[args.model]

    fit_samples = load_samples(args.run)
    check = None
    if args.check is not None:
        fitted = {face_key(s) for s in fit_samples}
        check = [s for s in load_samples(args.check) if face_key(s) not in fitted]
        check += load_false_faces(args.check)
    elif args.fit_first is not None:
        order = list(dict.fromkeys(face_key(s) for s in fit_samples))
        first = set(order[: args.fit_first])
        check = [s for s in fit_samples if face_key(s) not in first]
        fit_samples = [s for s in fit_samples if face_key(s) in first]
    false_faces = load_false_faces(args.run)
    fit_samples += false_faces
    x, y, images = arrays(fit_samples, feature_fn)
    # Two folds by image.
    image_names = sorted(set(images))
    fold = {n: i % 2 for i, n in enumerate(image_names)}
    f = np.array([fold[i] for i in images])
    for k in (0, 1):
        w, b = fit(x[f != k], y[f != k])
        print(f"fold {k}: held-out AUC {auc(predict(x[f == k], w, b), y[f == k]):.3f}")
    weights, intercept = fit(x, y)
    for name, w in zip(names, weights):
        print(f"  {w:+.3f}  {name}")
    print(f"  {intercept:+.3f}  intercept")
    report("fitted", x, y, weights, intercept)
    fit_faces = len({face_key(s) for s in fit_samples if not s.get("false_face")})
    summary = f"fitted on {len(y)} estimates of {fit_faces} faces"
    if false_faces:
        used = sum(1 for f in false_faces if f["measured"] is not None and not refused_by_rule(f))
        summary += f" and of {used} faces found with the annotated faces painted over"
    if check is not None:
        faces = len({face_key(s) for s in check})
        xc, yc, _ = arrays(check, feature_fn)
        report(f"checked ({faces} other faces)", xc, yc, weights, intercept)
        checked_auc = auc(predict(xc, weights, intercept), yc)
        summary += (
            f", checked on {len(yc)} estimates of {faces} other faces (AUC {checked_auc:.3f})"
        )
    else:
        summary += f" (AUC {auc(predict(x, weights, intercept), y):.3f} on them)"
    if args.write_rust:
        command = f"python3 scripts/fit_confidence.py {args.run} --model {args.model}"
        if args.fit_first is not None:
            command += f" --fit-first {args.fit_first}"
        if args.check is not None:
            command += f" --check {args.check}"
        name = f"CONFIDENCE_{args.model.upper()}"
        fitted_on = args.fitted_on or f"`{args.run}`"
        doc = fit_doc(name, command, fitted_on, summary)
        block = Block(name, doc, names, [float(v) for v in weights], intercept)
        replace_block(args.write_rust, block)
        print(f"wrote {name} into {args.write_rust}")


if __name__ == "__main__":
    main()

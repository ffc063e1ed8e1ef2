#!/usr/bin/env python3
"""Fits the eye-pair score (`locate::filters::EYE_PAIR_WEIGHTS`) to the output of the
`eye_pair_features` example and, with `--write-rust`, writes the weights into `src/fitted.rs`.

The score is linear in the pair's features and the highest-scoring pair wins, so the weights are
fitted as a conditional logit (McFadden's choice model): for each face, a softmax over its
candidate pairs, fitted by Newton's method to choose the pair closest to the annotated eyes.
Faces where no pair has both eyes within GOOD of the annotation are left out (no weights can
choose right there). A small ridge keeps the weights finite when features separate perfectly.

It prints the weights, and for the fitted weights and the hand-set score they replaced
(HAND_SET) the share of samples (a face at one shear) whose chosen pair has both eyes within
0.05 and 0.10 of the annotation, in-sample and two-fold cross-validated (folds by sample).

Usage (`scripts/regenerate-models --only eye-pairs` runs these):
    cargo run --release --example eye_pair_features > target/eye_pairs.csv
    python3 scripts/fit_eye_pairs.py target/eye_pairs.csv --write-rust src/fitted.rs
Add `--drop NAME[,NAME..]` to fit without some features (their weights are 0), and
`--fitted-on TEXT` to name the command that made the CSV in the generated comment. Needs numpy.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np
from fitted_rust import Block, fit_doc, replace_block

GOOD = 0.10
RIDGE = 1e-3
# The score before the fit: peak heights, the pair's scale and its mirror symmetry.
HAND_SET = {"right_height": 1.0, "left_height": 1.0, "scale_error_sq": -5.0, "symmetry": 0.5}


def load(path: str) -> tuple[list[str], np.ndarray, np.ndarray, np.ndarray]:
    """The feature names, each row's sample, each row's error and the features."""
    with open(path, encoding="utf-8") as f:
        header = f.readline().strip().split(",")
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    names = header[8:]
    samples = data[:, 0].astype(int)
    return names, samples, data[:, 3], data[:, 8:]


def groups(samples: np.ndarray) -> list[np.ndarray]:
    """Index arrays of the rows of each sample, in order."""
    cuts = np.flatnonzero(np.diff(samples)) + 1
    return np.split(np.arange(len(samples)), cuts)


def chosen_errors(
    weights: np.ndarray, x: np.ndarray, error: np.ndarray, idx: list[np.ndarray]
) -> np.ndarray:
    """The error of the highest-scoring pair of each sample."""
    score = x @ weights
    return np.array([error[g][np.argmax(score[g])] for g in idx])


def fit(x: np.ndarray, error: np.ndarray, idx: list[np.ndarray], mask: np.ndarray) -> np.ndarray:
    """Newton's method on the conditional logit's ridge-penalised log-likelihood."""
    scale = x.std(axis=0)
    scale[scale == 0] = 1.0
    z = x / scale
    usable = [g for g in idx if error[g].min() <= GOOD]
    if not usable:
        sys.exit("no sample has a pair within GOOD of the annotation")
    targets = [g[np.argmin(error[g])] for g in usable]
    w = np.zeros(x.shape[1])
    for _ in range(50):
        grad = -RIDGE * w
        hess = -RIDGE * np.eye(len(w))
        for g, t in zip(usable, targets):
            zg = z[g]
            s = zg @ w
            p = np.exp(s - s.max())
            p /= p.sum()
            mean = p @ zg
            grad += z[t] - mean
            hess -= (zg * p[:, None]).T @ zg - np.outer(mean, mean)
        # Features left out keep weight 0.
        free = np.flatnonzero(mask)
        step = np.zeros_like(w)
        step[free] = np.linalg.solve(hess[np.ix_(free, free)], grad[free])
        w -= step
        if np.abs(step).max() < 1e-8:
            break
    return w / scale


def shares(errors: np.ndarray) -> str:
    """The shares of `errors` within 0.05 and within GOOD, as percentages."""
    return f"{np.mean(errors <= 0.05) * 100:5.1f}% / {np.mean(errors <= GOOD) * 100:5.1f}%"


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("csv", help="output of the eye_pair_features example")
    parser.add_argument("--drop", default="", help="features to leave out, comma-separated")
    parser.add_argument(
        "--write-rust", metavar="FILE", help="write the weights here (src/fitted.rs)"
    )
    parser.add_argument(
        "--fitted-on",
        metavar="TEXT",
        help="what made the CSV, for the generated comment (default: the CSV's path)",
    )
    args = parser.parse_args()
    drop = [d for d in args.drop.split(",") if d]
    names, samples, error, x = load(args.csv)
    unknown = [d for d in drop if d not in names]
    if unknown:
        sys.exit(f"unknown features: {unknown}")
    mask = np.array([n not in drop for n in names])
    idx = groups(samples)
    hand_set = np.array([HAND_SET.get(n, 0.0) for n in names])
    w = fit(x, error, idx, mask)
    # Two folds by face.
    rng = np.random.default_rng(0)
    fold = rng.integers(0, 2, len(idx))
    cv = np.empty(len(idx))
    for f in (0, 1):
        train = [g for g, h in zip(idx, fold) if h != f]
        test = np.flatnonzero(fold == f)
        rows = np.concatenate(train)
        remap = np.full(len(samples), -1)
        remap[rows] = np.arange(len(rows))
        wf = fit(x[rows], error[rows], [remap[g] for g in train], mask)
        cv[test] = chosen_errors(wf, x, error, [idx[i] for i in test])
    oracle = np.array([error[g].min() for g in idx])
    print(f"{len(idx)} samples (face x shear); both eyes within 0.05 / 0.10 (of all samples):")
    print(f"  best pair (oracle):      {shares(oracle)}")
    print(f"  highest peaks:           {shares(np.array([error[g][0] for g in idx]))}")
    print(f"  hand-set score:          {shares(chosen_errors(hand_set, x, error, idx))}")
    print(f"  fitted, in sample:       {shares(chosen_errors(w, x, error, idx))}")
    print(f"  fitted, 2-fold CV:       {shares(cv)}")
    print("weights:")
    for n, v in zip(names, w):
        print(f"  {v:+9.3g}  {n}")
    if args.write_rust:
        command = f"python3 scripts/fit_eye_pairs.py {args.csv}"
        if drop:
            command += f" --drop {','.join(drop)}"
        summary = (
            f"{len(idx)} samples (a face at one shear); both eyes within {GOOD:.2f} of the eye "
            f"distance for {np.mean(cv <= GOOD) * 100:.1f}% of them, two-fold cross-validated"
        )
        name = "EYE_PAIR_WEIGHTS"
        fitted_on = args.fitted_on or f"`{args.csv}`"
        doc = fit_doc(name, command, fitted_on, summary)
        replace_block(args.write_rust, Block(name, doc, names, [float(v) for v in w], None))
        print(f"wrote {name} into {args.write_rust}")


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""Fits the eye-pair score (`features::EYE_PAIR_WEIGHTS`) to the output of the
`eye_pair_features` example.

The score is linear in the pair's features and the highest-scoring pair wins, so the weights are
fitted as a conditional logit (McFadden's choice model): for each face, a softmax over its
candidate pairs, fitted by Newton's method to choose the pair closest to the annotated eyes.
Faces where no pair has both eyes within GOOD of the annotation are left out (no weights can
choose right there). A small ridge keeps the weights finite when features separate perfectly.

It prints the weights in Rust syntax, and for the fitted weights and the hand-set score they
replaced (HAND_SET) the share of samples (a face at one shear) whose chosen pair
has both eyes within 0.05 and 0.10 of the annotation, in-sample and two-fold cross-validated
(folds by sample).

Usage (the figures in the README and in `features.rs`):
    cargo run --release --example eye_pair_features > target/eye_pairs.csv
    python3 scripts/fit_eye_pairs.py target/eye_pairs.csv
Add `--drop NAME[,NAME..]` to fit without some features (their weights are 0). Needs numpy.
Paste the printed weights into `EYE_PAIR_WEIGHTS`.
"""
import sys

import numpy as np

GOOD = 0.10
RIDGE = 1e-3
# The score before the fit: peak heights, the pair's scale and its mirror symmetry.
HAND_SET = {"right_height": 1.0, "left_height": 1.0, "scale_error_sq": -5.0, "symmetry": 0.5}


def load(path):
    with open(path) as f:
        header = f.readline().strip().split(",")
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    names = header[8:]
    samples = data[:, 0].astype(int)
    return names, samples, data[:, 3], data[:, 8:]


def groups(samples):
    """Index arrays of the rows of each sample, in order."""
    cuts = np.flatnonzero(np.diff(samples)) + 1
    return np.split(np.arange(len(samples)), cuts)


def chosen_errors(weights, x, error, idx):
    """The error of the highest-scoring pair of each sample."""
    score = x @ weights
    return np.array([error[g][np.argmax(score[g])] for g in idx])


def fit(x, error, idx, mask):
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


def shares(errors):
    return f"{np.mean(errors <= 0.05) * 100:5.1f}% / {np.mean(errors <= GOOD) * 100:5.1f}%"


def main():
    args = sys.argv[1:]
    drop = []
    if "--drop" in args:
        i = args.index("--drop")
        drop = args[i + 1].split(",")
        del args[i : i + 2]
    names, samples, error, x = load(args[0])
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
    print("pub const EYE_PAIR_WEIGHTS: [f64; EYE_PAIR_FEATURES.len()] = [")
    for n, v in zip(names, w):
        print(f"    {v:.3},  // {n}")
    print("];")


if __name__ == "__main__":
    main()

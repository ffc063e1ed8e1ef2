"""Per-call overhead of the Python binding against the Rust library, on one 640 x 480 photo.

    cargo build --release --example time_estimate
    python python/bench/overhead.py [--rounds 5] [--runs 20]

Alternates rounds of the Rust example (``Unshear::estimate`` and ``correct`` by k = 0.2 on the
decoded image) with the same calls from Python on the same pixels (``unshear.read``), both
after one warm-up call, for the default (thorough) search and the quick one. Each round keeps
the fastest of its runs (the least disturbed by other work on the machine); the overhead is
that of the medians of the rounds' fastest. The Python call includes what the binding adds:
checking and copying the array, releasing the GIL, building the result.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import time
from pathlib import Path

from common import ROOT, photo_640x480

import unshear

# Corrections per estimate in a round (a correction by k is a fraction of a millisecond).
CORRECT_RUNS = 20


def python_times(u: unshear.Unshear, path: Path, runs: int) -> tuple[float, float]:
    img = unshear.read(path)
    report = u.estimate(img)
    estimate, correct = [], []
    for _ in range(runs):
        t = time.perf_counter()
        u.estimate(img)
        estimate.append((time.perf_counter() - t) * 1e3)
    for _ in range(runs * CORRECT_RUNS):
        t = time.perf_counter()
        u.correct(img, 0.2, report=report)
        correct.append((time.perf_counter() - t) * 1e3)
    return min(estimate), min(correct)


def rust_times(binary: Path, path: Path, runs: int, quick: bool) -> tuple[float, float]:
    args = [str(binary), str(path), str(runs), *(["--quick"] if quick else [])]
    line = json.loads(subprocess.run(args, check=True, capture_output=True, text=True).stdout)
    return float(line["estimate_ms"]), float(line["correct_ms"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--runs", type=int, default=10, help="estimates per round")
    parser.add_argument(
        "--rust-bin",
        type=Path,
        default=ROOT / "target" / "release" / "examples" / "time_estimate",
    )
    a = parser.parse_args()
    path = photo_640x480()
    print(f"image: {path} {unshear.read(path).shape}")
    for search in ("thorough", "quick"):
        u = unshear.Unshear(search=search)
        rows = []
        for _ in range(a.rounds):
            rust = rust_times(a.rust_bin, path, a.runs, search == "quick")
            py = python_times(u, path, a.runs)
            rows.append((rust, py))
            print(
                f"  {search:8} estimate: Rust {rust[0]:8.3f} ms  Python {py[0]:8.3f} ms   "
                f"correct: Rust {rust[1]:6.3f} ms  Python {py[1]:6.3f} ms"
            )
        for i, what in enumerate(("estimate", "correct")):
            r = statistics.median(row[0][i] for row in rows)
            p = statistics.median(row[1][i] for row in rows)
            print(
                f"{search} {what}: Rust {r:.3f} ms, Python {p:.3f} ms, "
                f"overhead {p - r:+.3f} ms ({(p - r) / r * 100:+.1f}%)"
            )


if __name__ == "__main__":
    main()

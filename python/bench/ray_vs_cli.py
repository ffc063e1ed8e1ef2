"""Throughput of the Ray example against the plain CLI over the same folder of photos.

    cargo build --release
    python python/bench/ray_vs_cli.py [--images 50]

Times ``unshear correct FOLDER --out-dir ...`` (one process, both cores) and
``examples/ray_batch.py`` on a local Ray of 2 CPUs with 2 actors of 1 thread and 1 actor of 2
threads, each writing its corrected images; Ray's figures with and without its start.
"""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
import time

from common import OUT, ROOT, folder_of


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--images", type=int, default=50)
    parser.add_argument("--cli", default=str(ROOT / "target" / "release" / "unshear"))
    a = parser.parse_args()
    folder = folder_of(a.images)
    n = len(list(folder.iterdir()))
    print(f"{n} images in {folder}")
    out = OUT / "ray-vs-cli"
    shutil.rmtree(out, ignore_errors=True)
    t = time.perf_counter()
    subprocess.run(
        [a.cli, "correct", str(folder), "--out-dir", str(out / "cli"), "--json"],
        check=True,
        capture_output=True,
    )
    seconds = time.perf_counter() - t
    print(f"CLI (unshear correct)            {seconds:6.1f} s  {n / seconds:5.2f} images/s")
    for actors, threads in [(2, 1), (1, 2)]:
        target = out / f"ray-{actors}x{threads}"
        run = subprocess.run(
            [
                sys.executable,
                str(ROOT / "examples" / "ray_batch.py"),
                str(folder),
                str(target),
                "--num-cpus",
                "2",
                "--actors",
                str(actors),
                "--threads",
                str(threads),
            ],
            check=True,
            capture_output=True,
            text=True,
        )
        m = re.search(r"in ([\d.]+) s \(([\d.]+) images/s; ([\d.]+) s with", run.stdout)
        if m is None:
            raise RuntimeError(run.stdout + run.stderr[-2000:])
        run_s, rate, total = float(m[1]), float(m[2]), float(m[3])
        print(
            f"Ray, {actors} actor(s) x {threads} thread(s) {run_s:6.1f} s  {rate:5.2f} images/s  "
            f"({total:.1f} s, {n / total:.2f} images/s with Ray's start)"
        )


if __name__ == "__main__":
    main()

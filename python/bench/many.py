"""estimate_many on 1 and 2 threads, and estimate from 2 Python threads, over the same photos.

python python/bench/many.py [--images 24] [--rounds 3]
"""

from __future__ import annotations

import argparse
import resource
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

from common import folder_of

import unshear


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--images", type=int, default=24)
    parser.add_argument("--rounds", type=int, default=3)
    a = parser.parse_args()
    folder = folder_of(a.images)
    images = [unshear.read(p) for p in sorted(folder.iterdir())]
    u = unshear.Unshear()
    u.estimate_many(images[:2])
    print(f"{len(images)} images from {folder}")

    def cpu() -> float:
        r = resource.getrusage(resource.RUSAGE_SELF)
        return r.ru_utime + r.ru_stime

    def best(run: Callable[[], object]) -> tuple[float, float]:
        """The fastest round's wall time, and the cores busy during it."""
        rounds = []
        for _ in range(a.rounds):
            c, t = cpu(), time.perf_counter()
            run()
            wall = time.perf_counter() - t
            rounds.append((wall, (cpu() - c) / wall))
        return min(rounds)

    one = best(lambda: u.estimate_many(images, threads=1))
    two = best(lambda: u.estimate_many(images, threads=2))
    with ThreadPoolExecutor(max_workers=2) as pool:
        threads = best(lambda: list(pool.map(u.estimate, images)))
    for name, (seconds, cores) in [
        ("estimate_many(threads=1)", one),
        ("estimate_many(threads=2)", two),
        ("estimate from 2 Python threads", threads),
    ]:
        print(
            f"{name:32} {seconds:6.2f} s  {len(images) / seconds:5.2f} images/s  "
            f"x{one[0] / seconds:.2f}  {cores:.2f} cores busy"
        )


if __name__ == "__main__":
    main()

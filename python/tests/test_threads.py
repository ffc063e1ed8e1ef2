"""Threads: the GIL is released in Rust, one corrector serves many threads, estimate_many."""

from __future__ import annotations

import os
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest

import unshear


@pytest.fixture(scope="module")
def batch(faces: list[np.ndarray]) -> list[np.ndarray]:
    return [unshear.distort(f, k, canvas="expand") for f in faces for k in (-0.3, 0.0, 0.3)]


def test_the_gil_is_released_while_rust_works(batch: list[np.ndarray]) -> None:
    """A pure-Python thread keeps running during a long call: it could not if the GIL were held.
    The thorough Viola-Jones search makes the call long enough to measure."""
    corrector = unshear.Unshear(search="thorough")
    stop = threading.Event()
    ticks = [0]

    def count() -> None:
        while not stop.is_set():
            ticks[0] += 1

    thread = threading.Thread(target=count)
    thread.start()
    try:
        time.sleep(0.05)
        before = ticks[0]
        start = time.perf_counter()
        corrector.estimate_many(batch[:4], threads=1)
        seconds = time.perf_counter() - start
        during = ticks[0] - before
    finally:
        stop.set()
        thread.join()
    assert seconds > 0.2, seconds
    # Held, the counter would advance only between images (a few switches): thousands of
    # increments per image at the least when it is free.
    assert during > 10_000, (during, seconds)


def test_one_corrector_from_many_threads(
    corrector: unshear.Unshear, batch: list[np.ndarray]
) -> None:
    expected = [r.to_dict() for r in corrector.estimate_many(batch)]
    with ThreadPoolExecutor(max_workers=4) as pool:
        futures = [pool.submit(corrector.estimate, img) for img in batch for _ in range(2)]
        got = [f.result().to_dict() for f in futures]
    assert got == [e for e in expected for _ in range(2)]
    with ThreadPoolExecutor(max_workers=3) as pool:
        fixed = list(pool.map(lambda img: corrector.correct(img, 0.3), batch))
    assert all(np.array_equal(a, corrector.correct(b, 0.3)) for a, b in zip(fixed, batch))


def test_estimate_many_matches_estimate(quick: unshear.Unshear, batch: list[np.ndarray]) -> None:
    one_by_one = [quick.estimate(img).to_dict() for img in batch]
    for threads in (None, 1, 2, 5):
        got = [r.to_dict() for r in quick.estimate_many(batch, threads=threads)]
        assert got == one_by_one, threads
    assert [r.to_dict() for r in quick.estimate_many(iter(batch))] == one_by_one
    assert quick.estimate_many([]) == []
    # A 4-D batch (N x H x W x C, as Ray Data hands over same-sized images) is N images.
    stacked = np.stack([batch[1], batch[1]])
    assert [r.to_dict() for r in quick.estimate_many(stacked)] == [one_by_one[1]] * 2
    with pytest.raises(ValueError, match="threads must be 1 to 65535, got 0"):
        quick.estimate_many(batch, threads=0)
    with pytest.raises(ValueError, match="uint8 or uint16"):
        quick.estimate_many([batch[0], batch[1].astype(np.float32)])
    with pytest.raises(TypeError):
        quick.estimate_many(5)  # type: ignore[arg-type]
    # One image is not a batch of its rows.
    with pytest.raises(TypeError, match="use estimate for one image"):
        quick.estimate_many(batch[1])


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="needs Linux's /proc")
def test_estimate_many_with_new_sizes_keeps_one_pool(
    quick: unshear.Unshear, batch: list[np.ndarray]
) -> None:
    def threads() -> int:
        return len(os.listdir("/proc/self/task"))

    quick.estimate_many(batch[:1], threads=2)
    before = threads()
    for n in range(3, 12):
        quick.estimate_many(batch[:1], threads=n)
    # The last pool (11 threads) replaced the first (2); the others end (rayon's threads
    # leave on their own once their pool is dropped: wait up to 5 s for them).
    limit = before + 11 - 2
    deadline = time.monotonic() + 5
    while threads() > limit and time.monotonic() < deadline:
        time.sleep(0.05)
    assert threads() <= limit, (threads(), before)


def test_video_correctors_in_threads(faces: list[np.ndarray]) -> None:
    frames = [unshear.distort(faces[0], 0.2) for _ in range(4)]

    def run(_: int) -> list[float]:
        video = unshear.VideoCorrector(smoothing_lag=0)
        return [out.k for f in frames for out in video.push(f)]

    with ThreadPoolExecutor(max_workers=3) as pool:
        results = list(pool.map(run, range(3)))
    assert results[0] == results[1] == results[2] and len(results[0]) == 4

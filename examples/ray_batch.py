"""Correct a folder or bucket of photos on Ray Data: one `unshear.Unshear` per actor.

    python examples/ray_batch.py INPUT OUTPUT [--actors N] [--threads T] [--quick]

INPUT is a local folder or a bucket URI (``s3://bucket/photos``, ``gs://...``); it is read with
``ray.data.read_images`` (recursively; JPEG, PNG, TIFF, BMP). Each batch goes to an actor of a
pool (``map_batches`` with a class), which builds its corrector once and then, per batch, runs
``estimate_many`` and corrects every image with a face. OUTPUT (a folder or URI) receives:

* ``images/<path below INPUT>`` with ``.unshear`` before the extension: the corrected images
  (none for an image without a face, as the CLI), written by the actors through
  ``pyarrow.fs``, so that they stream out and keep their names;
* ``results/*.json``: one JSON line per input with the CLI's ``--json`` keys (``file``, ``k``,
  ``faces``) and ``output``, written with ``Dataset.write_json``.

On a cluster, start Ray there and pass ``--address auto``; without it a local Ray is started
with ``--num-cpus`` CPUs. Needs ``pip install "ray[data]" pillow`` beside ``unshear``.
"""

from __future__ import annotations

import argparse
import io
import posixpath
import time
from typing import Any

import numpy as np
import pyarrow.fs  # type: ignore[import-untyped]
import ray
from PIL import Image

import unshear


def relative_name(path: str, root: str) -> str:
    """``path`` below ``root`` (both as ``pyarrow.fs`` names them), for the output's name."""
    root = root.rstrip("/")
    if path.startswith(root + "/"):
        return path[len(root) + 1 :]
    return posixpath.basename(path)


def output_name(relative: str) -> str:
    """``a/b.jpg`` -> ``a/b.unshear.jpg`` (the CLI's naming); PNG for formats PIL cannot write."""
    stem, ext = posixpath.splitext(relative)
    if ext.lower() not in (".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff"):
        ext = ".png"
    return f"{stem}.unshear{ext}"


def encode(image: np.ndarray, name: str) -> bytes:
    """The image in the format its name says (JPEG at quality 95, as the CLI writes)."""
    buffer = io.BytesIO()
    fmt = {".jpg": "JPEG", ".jpeg": "JPEG", ".bmp": "BMP", ".tif": "TIFF", ".tiff": "TIFF"}
    kind = fmt.get(posixpath.splitext(name)[1].lower(), "PNG")
    options = {"quality": 95} if kind == "JPEG" else {}
    Image.fromarray(image).save(buffer, format=kind, **options)
    return buffer.getvalue()


class Corrector:
    """One actor: builds its corrector once, then estimates and corrects batch after batch."""

    def __init__(self, input_root: str, output: str, threads: int, config: dict[str, Any]):
        self.unshear = unshear.Unshear(**config)
        self.threads = threads
        self.input_root = input_root
        self.fs, self.images = pyarrow.fs.FileSystem.from_uri(output)
        self.images = self.images.rstrip("/") + "/images"

    def __call__(self, batch: dict[str, np.ndarray]) -> dict[str, list[Any]]:
        images = list(batch["image"])
        paths = [str(p) for p in batch["path"]]
        reports = self.unshear.estimate_many(images, threads=self.threads)
        outputs: list[str | None] = []
        for image, path, report in zip(images, paths, reports):
            if report.k is None:
                outputs.append(None)
                continue
            fixed = self.unshear.correct(image, report=report)
            name = f"{self.images}/{output_name(relative_name(path, self.input_root))}"
            self.fs.create_dir(posixpath.dirname(name), recursive=True)
            with self.fs.open_output_stream(name) as stream:
                stream.write(encode(fixed, name))
            outputs.append(name)
        return {
            "file": paths,
            "k": [r.k for r in reports],
            "faces": [r.to_dict()["faces"] for r in reports],
            "output": outputs,
        }


def run(
    input_uri: str,
    output_uri: str,
    *,
    actors: int = 2,
    threads: int = 1,
    batch_size: int = 4,
    config: dict[str, Any] | None = None,
) -> int:
    """Corrects every image under ``input_uri`` into ``output_uri`` on the running Ray;
    returns the number of images read."""
    _, input_root = pyarrow.fs.FileSystem.from_uri(input_uri)
    # Reading (decoding) and writing the table are light next to the faces: they reserve no
    # CPU, so that the actors can hold every CPU and still be fed (with a CPU each, the read
    # tasks would wait for CPUs the actors never give back).
    images = ray.data.read_images(input_uri, mode="RGB", include_paths=True, num_cpus=0)
    results = images.map_batches(
        Corrector,
        fn_constructor_args=(input_root, output_uri, threads, config or {}),
        batch_size=batch_size,
        batch_format="numpy",
        concurrency=actors,
        num_cpus=threads,
    )
    results.write_json(output_uri.rstrip("/") + "/results", ray_remote_args={"num_cpus": 0})
    return len(images.input_files())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("input", help="a folder or bucket URI of images")
    parser.add_argument("output", help="a folder or bucket URI for images/ and results/")
    parser.add_argument("--actors", type=int, default=2, help="actors, each with a corrector")
    parser.add_argument("--threads", type=int, default=1, help="threads per actor")
    parser.add_argument("--batch-size", type=int, default=4, help="images per batch")
    parser.add_argument("--quick", action="store_true", help="the quick face search")
    parser.add_argument("--address", help="a running Ray cluster (e.g. auto)")
    parser.add_argument("--num-cpus", type=int, help="CPUs of the local Ray (no --address)")
    a = parser.parse_args()
    start = time.perf_counter()
    if a.address:
        ray.init(address=a.address)
    else:
        ray.init(num_cpus=a.num_cpus)
    started = time.perf_counter()
    config = {"search": "quick"} if a.quick else {}
    n = run(
        a.input,
        a.output,
        actors=a.actors,
        threads=a.threads,
        batch_size=a.batch_size,
        config=config,
    )
    done = time.perf_counter()
    print(
        f"{n} images in {done - started:.1f} s ({n / (done - started):.2f} images/s; "
        f"{done - start:.1f} s with Ray's start)"
    )
    ray.shutdown()


if __name__ == "__main__":
    main()

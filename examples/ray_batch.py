"""Correct a folder or bucket of photos on Ray Data, as ``unshear correct --out-dir`` does.

    python examples/ray_batch.py INPUT OUTPUT [--address auto | --num-cpus N]
                                 [--actors N] [--threads T] [--batch-size B] [--quick]

INPUT and OUTPUT are folders (relative, ``~/...``, ``file:///...``) or bucket URIs
(``s3://bucket/photos``, ``gs://...``: whatever ``pyarrow.fs`` opens). INPUT is listed once, on
the driver, recursively and in name order, for the CLI's image extensions (JPEG, PNG, PNM, BMP,
TIFF, WebP), skipping ``*.unshear.*`` files and OUTPUT. Only the names travel through Ray: each
batch of names goes to an actor of a pool (``map_batches`` with a class), which builds its
corrector once and corrects every file with ``Unshear.correct_file``, the CLI's own reader and
writer (EXIF orientation, colour profile and EXIF block kept). OUTPUT receives:

* ``images/<path below INPUT>``: the corrected images, named as ``correct --out-dir`` names
  them (none for an image without a face, as the CLI);
* ``results.jsonl``: one JSON line per input with the CLI's ``--json`` keys (``file``, ``k``,
  ``faces``, ..., ``error`` for an input that failed) and ``output``, written by the driver.

A progress line (images done, images/s) goes to stderr, a summary to stdout; the exit code is 1
when an input failed (the others are still corrected), as the CLI's. On a cluster, start Ray
there and pass ``--address auto``; without it a local Ray is started with ``--num-cpus`` CPUs
(default: every core). By default each actor has as many threads as a node has CPUs, one actor
per node. Needs ``pip install "ray[data]"`` beside ``unshear``.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import os
import posixpath
import sys
import tempfile
import time
from dataclasses import dataclass, field
from typing import Any, TextIO

import numpy as np
import pyarrow.fs  # type: ignore[import-untyped]
import ray

import unshear

# The extensions `unshear correct` picks up in a folder, and those it writes.
IMAGE_EXTENSIONS: tuple[str, ...] = (".jpg", ".jpeg", ".png", ".pgm", ".ppm", ".pnm", ".pbm")
IMAGE_EXTENSIONS += (".bmp", ".tif", ".tiff", ".webp")
WRITTEN = frozenset(IMAGE_EXTENSIONS) - {".pbm"}


class UserError(Exception):
    """A mistake in what was asked (a missing folder, an unwritable output): one line, exit 1."""


@dataclass(frozen=True)
class Location:
    """A folder or bucket prefix: its file system, its path there, and its name as given."""

    fs: Any
    path: str
    shown: str

    @property
    def local(self) -> bool:
        return isinstance(self.fs, pyarrow.fs.LocalFileSystem)

    def join(self, name: str) -> str:
        return f"{self.path}/{name}" if self.path else name


def locate(where: str) -> Location:
    """``where`` (a folder, relative or ``~/...``, or a URI) as a ``Location``."""
    shown = where.rstrip("/") or where
    if "://" not in where:
        path = os.path.abspath(os.path.expanduser(where))
        return Location(pyarrow.fs.LocalFileSystem(), path, os.path.expanduser(shown))
    try:
        fs, path = pyarrow.fs.FileSystem.from_uri(where)
    except (OSError, ValueError, pyarrow.ArrowException) as e:
        raise UserError(f"{where}: cannot open: {e}") from None
    return Location(fs, str(path).rstrip("/"), shown)


def output_name(name: str) -> str:
    """The corrected image's name, as ``correct --out-dir`` names it: the input's, with PNG
    for an extension that is only read (``.pbm``) or none at all."""
    stem, ext = posixpath.splitext(name)
    if ext.lower() in WRITTEN:
        return name
    if ext.lower() in IMAGE_EXTENSIONS:
        return f"{stem}.png"
    return f"{name}.png"


def list_images(source: Location, skip: Location) -> tuple[Location, list[str]]:
    """The images under ``source`` (or ``source`` itself, a file), as names below the folder
    returned, sorted; ``skip`` (the output) is left out wherever it lies below."""
    try:
        info = source.fs.get_file_info(source.path)
    except (OSError, pyarrow.ArrowException) as e:
        raise UserError(f"{source.shown}: cannot read: {e}") from None
    if info.type == pyarrow.fs.FileType.NotFound:
        raise UserError(f"{source.shown}: no such folder or file")
    if info.type == pyarrow.fs.FileType.File:
        folder = Location(
            source.fs, posixpath.dirname(source.path), posixpath.dirname(source.shown)
        )
        return folder, [posixpath.basename(source.path)]
    try:
        found = source.fs.get_file_info(pyarrow.fs.FileSelector(source.path, recursive=True))
    except (OSError, pyarrow.ArrowException) as e:
        raise UserError(f"{source.shown}: cannot list: {e}") from None
    prefix = source.path + "/" if source.path else ""
    skipped = skip.join("images") + "/" if type(skip.fs) is type(source.fs) else None
    names = []
    for f in found:
        if f.type != pyarrow.fs.FileType.File or not f.path.startswith(prefix):
            continue
        if skipped is not None and f.path.startswith(skipped):
            continue
        stem, ext = posixpath.splitext(f.base_name)
        if ext.lower() in IMAGE_EXTENSIONS and not stem.endswith(".unshear"):
            names.append(f.path[len(prefix) :])
    if not names:
        raise UserError(f"{source.shown}: no image found ({', '.join(IMAGE_EXTENSIONS)})")
    return source, sorted(names)


class Corrector:
    """One actor: builds its corrector once, then corrects batch after batch of file names, as
    many batches at once as it has threads (one ``Unshear`` serves them all: every call
    releases the GIL)."""

    def __init__(self, source: Location, target: Location, config: dict[str, Any]) -> None:
        self.unshear = unshear.Unshear(**config)
        self.source = source
        self.target = target
        self.images = target.join("images")
        self.made: set[str] = set()

    def __call__(self, batch: dict[str, np.ndarray]) -> dict[str, list[str]]:
        return {"row": [json.dumps(self.one(str(name))) for name in batch["name"]]}

    def one(self, name: str) -> dict[str, Any]:
        """Corrects the input ``name``; its result line (errors included: the job goes on)."""
        row: dict[str, Any] = {"file": f"{self.source.shown}/{name}"}
        written = output_name(name)
        try:
            report = self.correct(name, f"{self.images}/{written}")
            row |= report.to_dict()
            row["output"] = f"{self.target.shown}/images/{written}"
        except unshear.NoFaceError as e:
            row |= e.report.to_dict() if e.report is not None else {"k": None, "faces": []}
            row["output"] = None
        except Exception as e:  # noqa: BLE001 - an input that fails is reported in its row
            row |= {"k": None, "faces": [], "error": str(e) or type(e).__name__, "output": None}
        return row

    def correct(self, name: str, dst: str) -> unshear.Report:
        self.make_folder(posixpath.dirname(dst))
        if self.source.local and self.target.local:
            return self.unshear.correct_file(self.source.join(name), dst, overwrite=True)
        # A bucket: the file is copied to local disk and back (the reader and writer keep the
        # EXIF block and colour profile, and detect the format from the content).
        with tempfile.TemporaryDirectory(prefix="unshear-") as tmp:
            src = os.path.join(tmp, "in" + posixpath.splitext(name)[1])
            out = os.path.join(tmp, "out" + posixpath.splitext(dst)[1])
            with self.source.fs.open_input_stream(self.source.join(name)) as stream:
                data = stream.read()
            with open(src, "wb") as f:
                f.write(data)
            report = self.unshear.correct_file(src, out)
            with open(out, "rb") as f, self.target.fs.open_output_stream(dst) as stream:
                stream.write(f.read())
            return report

    def make_folder(self, folder: str) -> None:
        if folder not in self.made:  # a race between threads only makes it twice
            self.target.fs.create_dir(folder, recursive=True)
            self.made.add(folder)


@dataclass
class Summary:
    """What happened to the inputs, counted as their rows come back."""

    read: int = 0
    corrected: int = 0
    no_face: int = 0
    failed: list[tuple[str, str]] = field(default_factory=list)

    def add(self, row: dict[str, Any]) -> None:
        self.read += 1
        if row.get("error"):
            self.failed.append((row["file"], row["error"]))
        elif row["output"] is not None:
            self.corrected += 1
        else:
            self.no_face += 1

    def lines(self) -> list[str]:
        counts = f"{self.corrected} corrected, {self.no_face} without a face (nothing written)"
        out = [f"{self.read} images read: {counts}, {len(self.failed)} failed"]
        out += [f"  failed: {error}" for _, error in self.failed[:20]]
        if len(self.failed) > 20:
            out.append(f"  ... and {len(self.failed) - 20} more (see results.jsonl)")
        return out


class Progress:
    """``done/total images, rate images/s`` on stderr: redrawn on a terminal, else a line every
    ``every`` seconds."""

    def __init__(self, total: int, stream: TextIO = sys.stderr, every: float = 10.0) -> None:
        self.total = total
        self.stream = stream
        self.tty = stream.isatty()
        self.every = 0.5 if self.tty else every
        self.start = time.perf_counter()
        self.shown = self.start

    def update(self, done: int, final: bool = False) -> None:
        now = time.perf_counter()
        if not final and now - self.shown < self.every:
            return
        self.shown = now
        rate = done / max(now - self.start, 1e-9)
        line = f"{done}/{self.total} images, {rate:.1f} images/s"
        end = "\n" if final or not self.tty else ""
        self.stream.write(("\r" if self.tty else "") + line + end)
        self.stream.flush()


def run(
    source: Location,
    target: Location,
    names: list[str],
    results: Any,
    *,
    actors: int,
    threads: int,
    batch_size: int,
    config: dict[str, Any],
    progress: Progress | None = None,
) -> Summary:
    """Corrects ``names`` (below ``source``) into ``target`` on the running Ray, writing each
    result line to the binary stream ``results`` as it comes back."""
    items = [{"name": n} for n in names]
    # One block per batch: nothing but the names is read, so there are no read tasks; the
    # actors (each holding `threads` CPUs) are the only workers.
    dataset = ray.data.from_items(items, override_num_blocks=math.ceil(len(items) / batch_size))
    # Each actor holds `threads` CPUs and runs that many batches at once, in threads of its
    # own: a batch is never split between threads, so none waits for another's last image.
    pool = ray.data.ActorPoolStrategy(
        size=actors,
        max_concurrent_calls_per_actor=threads,
        max_tasks_in_flight_per_actor=2 * threads,
        enable_true_multi_threading=True,
    )
    rows = dataset.map_batches(
        Corrector,
        fn_constructor_args=(source, target, config),
        batch_size=batch_size,
        batch_format="numpy",
        compute=pool,
        num_cpus=threads,
    )
    summary = Summary()
    for item in rows.iter_rows():
        line = str(item["row"])
        results.write(line.encode() + b"\n")
        summary.add(json.loads(line))
        if progress is not None:
            progress.update(summary.read)
    if progress is not None:
        progress.update(summary.read, final=True)
    return summary


def node_cpus() -> int:
    """The CPUs of the smallest node with CPUs (each actor's threads by default)."""
    nodes = ray.nodes()  # type: ignore[no-untyped-call]
    cpus = [n["Resources"].get("CPU", 0) for n in nodes if n.get("Alive")]
    return max(1, int(min((c for c in cpus if c > 0), default=1)))


def main() -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("input", help="a folder or bucket URI of images")
    parser.add_argument("output", help="a folder or bucket URI for images/ and results.jsonl")
    parser.add_argument("--actors", type=int, help="actors (default: CPUs / threads)")
    parser.add_argument("--threads", type=int, help="threads per actor (default: a node's CPUs)")
    parser.add_argument("--batch-size", type=int, default=16, help="images per batch (16)")
    parser.add_argument("--quick", action="store_true", help="the quick face search")
    parser.add_argument("--address", help="a running Ray cluster (e.g. auto)")
    parser.add_argument("--num-cpus", type=int, help="CPUs of the local Ray (no --address)")
    a = parser.parse_args()
    for flag in ("actors", "threads", "batch_size", "num_cpus"):
        value = getattr(a, flag)
        if value is not None and value < 1:
            parser.error(f"--{flag.replace('_', '-')} must be at least 1")

    # Everything that can be wrong with the paths is found before Ray starts.
    target = locate(a.output)
    source, names = list_images(locate(a.input), target)
    try:
        target.fs.create_dir(target.join("images"), recursive=True)
        results = target.fs.open_output_stream(target.join("results.jsonl"))
    except (OSError, pyarrow.ArrowException) as e:
        raise UserError(f"{target.shown}: cannot write: {e}") from None

    start = time.perf_counter()
    if a.address:
        ray.init(address=a.address, logging_level=logging.WARNING)
    else:
        ray.init(num_cpus=a.num_cpus, include_dashboard=False, logging_level=logging.WARNING)
    context = ray.data.DataContext.get_current()
    context.enable_progress_bars = False
    context.print_on_execution_start = False
    started = time.perf_counter()
    threads = a.threads or node_cpus()
    cpus = int(ray.cluster_resources().get("CPU", 1))  # type: ignore[no-untyped-call]
    actors = a.actors or max(1, cpus // threads)
    print(
        f"{len(names)} images in {source.shown}; {actors} actor(s) x {threads} thread(s), "
        f"batches of {a.batch_size}",
        file=sys.stderr,
    )
    config = {"search": "quick"} if a.quick else {}
    with results:
        summary = run(
            source,
            target,
            names,
            results,
            actors=actors,
            threads=threads,
            batch_size=a.batch_size,
            config=config,
            progress=Progress(len(names)),
        )
    done = time.perf_counter()
    ray.shutdown()
    print("\n".join(summary.lines()))
    print(
        f"run {done - started:.1f} s ({summary.read / (done - started):.2f} images/s) after "
        f"Ray's start of {started - start:.1f} s; results in {target.shown}/results.jsonl"
    )
    return 1 if summary.failed else 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except UserError as e:
        print(f"ray_batch: {e}", file=sys.stderr)
        sys.exit(1)
    except KeyboardInterrupt:
        print("ray_batch: interrupted", file=sys.stderr)
        sys.exit(130)

"""Throughput of the Ray example against the plain CLI over the same folder of photos.

    cargo build --release -p unshear-cli
    python python/bench/ray_vs_cli.py [--images 600] [--rounds 2] [--layouts default,2x1]

The first ``--images`` Caltech web photos (sorted by name; sheared fixture faces without
``../shared``), copied under ``target/bench``. Each round times ``unshear correct FOLDER
--out-dir ...`` (one process, every core) and then ``examples/ray_batch.py`` on a local Ray of
``--num-cpus`` CPUs (each ``--layouts`` entry: ``default``, or ``AxT`` for A actors of T
threads), every corrected image written. Ray's run is its own report (from its first batch
scheduled to its last result, excluding Ray's start), and Ray's start is reported apart; the
Ray worker processes are counted from ``/proc`` while it runs. Every round checks that Ray's
results are the CLI's: one line per input, the same corrected files, ``k`` within 0.001.
``--shards N`` also times the array-job path: ``correct --shard I/N`` for every ``I``, one
after another with every core, and all ``N`` at once with ``--jobs CPUS/N`` each.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import resource
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

from common import OUT, ROOT, folder_of


def descendants(pid: int) -> list[int]:
    """Every process below ``pid`` (from ``/proc``'s parent links)."""
    children: dict[int, list[int]] = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            stat = Path(f"/proc/{entry}/stat").read_text()
        except OSError:
            continue
        parent = int(stat.rsplit(")", 1)[1].split()[1])
        children.setdefault(parent, []).append(int(entry))
    found, todo = [], [pid]
    while todo:
        for child in children.get(todo.pop(), []):
            found.append(child)
            todo.append(child)
    return found


def name(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")[0].decode()[:40]
    except OSError:
        return "?"


def is_worker(pid: int) -> bool:
    """A Ray worker process, one that runs tasks or actors (``ray::IDLE``, ``ray::MapWorker``,
    Ray Data's ``ray::_StatsActor``, ...); not the raylet, the GCS, the driver, nor the node's
    two agents (``ray::DashboardAgent``, ``ray::RuntimeEnvAgent``), which every Ray node runs."""
    try:
        args = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
    except OSError:
        return False
    if args[0].startswith((b"ray::DashboardAgent", b"ray::RuntimeEnvAgent")):
        return False
    # A worker names itself `ray::...` once started; before, it is Python running
    # setup_worker.py or default_worker.py (the raylet's own arguments name them too).
    starting = not args[0].endswith(b"raylet") and any(
        a.endswith((b"setup_worker.py", b"default_worker.py")) for a in args[1:3]
    )
    return args[0].startswith(b"ray::") or starting


def cpu_seconds(pid: int) -> float:
    """The CPU time (user and system) of the process ``pid`` itself, 0 once it is gone."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


class Watch(threading.Thread):
    """The most Ray worker processes seen below ``pid`` while Ray starts and (their names)
    once ``running`` is set, and the CPU time of ``pid`` and every process below it, sampled
    every half second (missing at most each one's last half second)."""

    def __init__(self, pid: int) -> None:
        super().__init__(daemon=True)
        self.pid = pid
        self.most_starting = 0
        self.names: list[str] = []
        self.counts: list[int] = []
        self.running = threading.Event()
        self.cpu: dict[int, float] = {}
        self.stop = threading.Event()

    def run(self) -> None:
        while not self.stop.wait(0.5):
            below = descendants(self.pid)
            workers = [p for p in below if is_worker(p)]
            if not self.running.is_set():
                self.most_starting = max(self.most_starting, len(workers))
            else:
                self.counts.append(len(workers))
                if len(workers) > len(self.names):
                    self.names = sorted(map(name, workers))
            for p in [self.pid, *below]:
                self.cpu[p] = max(self.cpu.get(p, 0.0), cpu_seconds(p))

    def total(self) -> float:
        return sum(self.cpu.values())


def cli_results(lines: str, folder: Path) -> dict[str, float | None]:
    rows = [json.loads(line) for line in lines.splitlines() if line.startswith("{")]
    return {str(Path(r["file"]).relative_to(folder)): r["k"] for r in rows}


def corrected(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_file()}


def children_cpu() -> float:
    """CPU seconds of the children waited for so far (and theirs, as each waited for its own)."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def time_cli(cli: str, folder: Path, out: Path, *extra: str) -> tuple[float, float, str]:
    """The wall time, the CPU time and the JSON lines of ``unshear correct``."""
    shutil.rmtree(out, ignore_errors=True)
    cpu = children_cpu()
    t = time.perf_counter()
    run = subprocess.run(
        [cli, "correct", str(folder), "--out-dir", str(out), "--json", *extra],
        capture_output=True,
        text=True,
        check=False,
    )
    seconds = time.perf_counter() - t
    if run.returncode not in (0, 1):
        raise RuntimeError(run.stderr[-2000:])
    return seconds, children_cpu() - cpu, run.stdout


def time_ray(
    folder: Path, out: Path, cpus: int, layout: str
) -> tuple[float, float, float, float, int, list[str], int, dict[str, float | None], set[str]]:
    """Ray's run and start (its own report), the wall time, the CPU time of the run (every
    process of the local Ray, after its start), the most worker processes while Ray starts,
    those of the run at its most and their median count, and the results: ``k`` by file and
    the corrected files."""
    shutil.rmtree(out, ignore_errors=True)
    args = [sys.executable, str(ROOT / "examples" / "ray_batch.py"), str(folder), str(out)]
    args += ["--num-cpus", str(cpus)]
    if layout != "default":
        actors, threads = layout.split("x")
        args += ["--actors", actors, "--threads", threads]
    t = time.perf_counter()
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    count = Watch(proc.pid)
    count.start()
    # The CPU time spent starting Ray: up to the line the example prints once Ray is up.
    assert proc.stderr is not None and proc.stdout is not None
    lines, at_start = [], 0.0
    for line in proc.stderr:
        lines.append(line)
        if "actor(s) x" in line:
            at_start = count.total()
            count.running.set()
    stdout = proc.stdout.read()
    proc.wait()
    stderr = "".join(lines)
    wall = time.perf_counter() - t
    count.stop.set()
    count.join()
    m = re.search(r"run ([\d.]+) s .* Ray's start of ([\d.]+) s", stdout)
    if m is None or proc.returncode not in (0, 1):
        raise RuntimeError(stdout + stderr[-2000:])
    rows = [json.loads(line) for line in (out / "results.jsonl").read_text().splitlines()]
    ks = {str(Path(r["file"]).relative_to(folder)): r["k"] for r in rows}
    if len(ks) != len(rows):
        raise RuntimeError("an input has more than one result line")
    cpu = count.total() - at_start
    typical = sorted(count.counts)[len(count.counts) // 2] if count.counts else 0
    return (
        float(m[1]),
        float(m[2]),
        wall,
        cpu,
        count.most_starting,
        count.names,
        typical,
        ks,
        corrected(out / "images"),
    )


def compare(cli: dict[str, float | None], ray: dict[str, float | None]) -> str:
    """Where Ray's results differ from the CLI's (empty when they agree)."""
    if set(cli) != set(ray):
        return f"inputs differ: {sorted(set(cli) ^ set(ray))[:5]}"
    for name, k in cli.items():
        other = ray[name]
        if (k is None) != (other is None) or (k is not None and abs(k - other) > 0.001):  # type: ignore[operator]
            return f"{name}: k {k} (CLI) against {other} (Ray)"
    return ""


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--images", type=int, default=600)
    parser.add_argument("--folder", help="a folder of images instead of --images")
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--num-cpus", type=int, default=os.cpu_count() or 2)
    parser.add_argument("--layouts", default="default", help="default and/or AxT, by commas")
    parser.add_argument("--shards", type=int, default=0, help="also time --shard I/N")
    parser.add_argument("--cli", default=str(ROOT / "target" / "release" / "unshear"))
    a = parser.parse_args()
    folder = Path(a.folder).resolve() if a.folder else folder_of(a.images)
    n = len(list(folder.iterdir()))
    print(f"{n} images in {folder}; {a.num_cpus} CPUs; {time.strftime('%Y-%m-%d %H:%M %Z')}")
    out = OUT / "ray-vs-cli"
    for r in range(1, a.rounds + 1):
        seconds, cpu, lines = time_cli(a.cli, folder, out / "cli")
        reference, cli_files = cli_results(lines, folder), corrected(out / "cli")
        print(
            f"round {r}: CLI (unshear correct)  {seconds:6.1f} s  {n / seconds:5.2f} images/s; "
            f"CPU {cpu:.1f} s ({cpu / seconds:.2f} cores busy)"
        )
        for layout in a.layouts.split(","):
            run_s, start_s, wall, cpu, starting, workers, typical, ks, files = time_ray(
                folder, out / "ray", a.num_cpus, layout
            )
            differs = compare(reference, ks) or (
                "" if files == cli_files else f"corrected files differ: {files ^ cli_files}"
            )
            print(
                f"round {r}: Ray, {layout:8}         {run_s:6.1f} s  {n / run_s:5.2f} images/s  "
                f"{run_s / seconds:.3f} x the CLI; start {start_s:.1f} s, wall {wall:.1f} s, "
                f"CPU {cpu:.1f} s ({cpu / run_s:.2f} cores busy); "
                f"worker processes: {typical} in most of the run, at most {len(workers)} "
                f"({', '.join(workers)}), "
                f"{starting} while Ray started; "
                + (f"DIFFERS: {differs}" if differs else f"same results ({len(files)} corrected)")
            )
    if a.shards:
        total = 0.0
        for i in range(a.shards):
            seconds, _, _ = time_cli(a.cli, folder, out / f"shard{i}", "--shard", f"{i}/{a.shards}")
            total += seconds
            print(f"--shard {i}/{a.shards}, every core  {seconds:6.1f} s")
        print(f"the {a.shards} shards one after another  {total:6.1f} s  {n / total:5.2f} images/s")
        jobs = str(max(1, a.num_cpus // a.shards))
        t = time.perf_counter()
        procs = [
            subprocess.Popen(
                [a.cli, "correct", str(folder), "--out-dir", str(out / "shards"), "--json"]
                + ["--force", "--shard", f"{i}/{a.shards}", "--jobs", jobs],
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
            )
            for i in range(a.shards)
        ]
        for p in procs:
            p.wait()
        seconds = time.perf_counter() - t
        print(
            f"the {a.shards} shards at once, --jobs {jobs}  {seconds:6.1f} s  "
            f"{n / seconds:5.2f} images/s"
        )


if __name__ == "__main__":
    main()

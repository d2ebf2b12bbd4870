"""Scaling of the Dask executor on a CPU-bound toy grid, and peak memory per worker.

Writes a toy pipeline (one notebook, a grid over ``seed``, a fixed amount of
pure-Python work per point) into a temporary folder, runs it with each
``--workers`` value (1 = the in-process path), and reports the wall time,
the speed-up over 1 worker and the peak resident memory of each worker
process and of each notebook kernel (sampled every 0.2 s with psutil).

    .venv/bin/python benchmarks/bench_executor.py                       # 8 points at 1, 2, 4 workers
    .venv/bin/python benchmarks/bench_executor.py --points 16 --workers 1 2 4 8 --figure scaling.png

``make main`` itself (serial against 2 workers, from a fresh clone) is timed
with the shell: ``time make main RUN_ARGS="--workers 1"`` and ``time make main RUN_ARGS="--workers 2"``.
"""

from __future__ import annotations

import argparse
import tempfile
import threading
import time
from pathlib import Path

import nbformat
import psutil
import yaml

from fnnbook import load_spec, run

PARAMS = 'profile = "toy"\nout_dir = "."\nseed = 0\nwork = 1\n'
BODY = """\
import json, pathlib, random
rng = random.Random(seed)
total = 0.0
for _ in range(work):            # CPU-bound, single-threaded
    total += rng.random()
pathlib.Path(out_dir, "result.json").write_text(json.dumps({"seed": seed, "total": total}))
"""


def _write_pipeline(root: Path, points: int, work: int) -> Path:
    nb = nbformat.v4.new_notebook()
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    nb.cells = [nbformat.v4.new_code_cell(PARAMS, metadata={"tags": ["parameters"]}),
                nbformat.v4.new_code_cell(BODY)]
    (root / "notebooks").mkdir(parents=True)
    nbformat.write(nb, root / "notebooks" / "toy.ipynb")
    (root / "claims.yaml").write_text("groups: []\n")
    doc = {"claims_file": "claims.yaml", "output_root": "outputs",
           "parts": [{"title": "Toy", "tasks": ["toy"]}],
           "tasks": {"toy": {"title": "Toy", "notebook": "notebooks/toy.ipynb", "products": ["result.json"],
                             "grid": {"seed": list(range(points))}, "parameters": {"toy": {"work": work}}}}}
    path = root / "pipeline.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


class _PeakMemory:
    """Peak RSS of every descendant process of this one, sampled in a thread."""

    def __init__(self) -> None:
        self.peak: dict[int, tuple[str, int]] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._sample, daemon=True)

    def _sample(self) -> None:
        me = psutil.Process()
        while not self._stop.is_set():
            for proc in me.children(recursive=True):
                try:
                    rss = proc.memory_info().rss
                    cmd = " ".join(proc.cmdline())
                except psutil.Error:
                    continue
                kind = "kernel" if "ipykernel" in cmd else "worker" if "multiprocessing" in cmd else ""
                if not kind:  # e.g. a fork about to exec a kernel
                    continue
                if rss > self.peak.get(proc.pid, ("", 0))[1]:
                    self.peak[proc.pid] = (kind, rss)
            time.sleep(0.2)

    def __enter__(self) -> _PeakMemory:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()

    def max_mib(self, kind: str) -> float:
        values = [rss for k, rss in self.peak.values() if k == kind]
        return max(values, default=0) / 2**20


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=8, help="grid points (tasks)")
    parser.add_argument("--work", type=int, default=6_000_000, help="random draws per point (about 1 s / 6e6)")
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2, 4])
    parser.add_argument("--figure", type=Path, help="save the scaling figure here (PNG)")
    args = parser.parse_args()

    rows = []
    with tempfile.TemporaryDirectory(prefix="bench-executor-") as tmp:
        pipeline = _write_pipeline(Path(tmp), args.points, args.work)
        for k in args.workers:
            spec = load_spec(pipeline).with_paths(output_root=Path(tmp) / f"out-{k}")
            with _PeakMemory() as memory:
                start = time.perf_counter()
                report = run(spec, "toy", workers=k, progress_bar=False, echo=lambda _: None)
                wall = time.perf_counter() - start
            if not report.ok:
                raise SystemExit(f"the toy grid failed with {k} workers: {report}")
            rows.append((k, wall, memory.max_mib("worker"), memory.max_mib("kernel")))
    base = rows[0][1]
    print(f"{args.points} points x {args.work:.2g} draws; {psutil.cpu_count()} cores")
    print(f"{'workers':>7} {'wall s':>8} {'speed-up':>8} {'peak worker MiB':>16} {'peak kernel MiB':>16}")
    for k, wall, worker, kernel in rows:
        print(f"{k:>7} {wall:>8.1f} {base / wall:>8.2f} {worker:>16.0f} {kernel:>16.0f}")
    print("(workers = 1 is the in-process path: no worker process; its kernel is the one measured)")
    if args.figure is not None:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(4, 3))
        ks = [r[0] for r in rows]
        ax.plot(ks, [base / r[1] for r in rows], "o-", label="measured")
        ax.plot(ks, [min(k, psutil.cpu_count()) for k in ks], "k--", label="ideal (cores)")
        ax.set_xlabel("workers")
        ax.set_ylabel("speed-up over 1 worker")
        ax.set_xticks(ks)
        ax.legend()
        fig.tight_layout()
        fig.savefig(args.figure, dpi=120)
        print(f"figure: {args.figure}")


if __name__ == "__main__":
    main()

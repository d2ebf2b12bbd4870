"""What a K-worker cluster would take for a profile, from the task times a run measured.

Reads each task's seconds from ``<output_root>/<profile>/_status.json`` (``seconds``) or, for a run made
before those were recorded, from the last line of its log (``--- ok after S s ---``), and replays the
executor's rule on them: a free worker takes the ready task with the longest remaining path
(:func:`fnnbook.executor.longest_remaining`). Prints, per K, the makespan of that list schedule, the lower
bound max(critical path, total / K), and the utilisation total / (K x makespan). Fixed costs (the cluster,
kernel start-up) are in the measured task times only as far as each task's own kernel start is.

    .venv/bin/python benchmarks/plan_workers.py outputs/paper [--workers 1 2 3 4 8]
    .venv/bin/python benchmarks/plan_workers.py outputs/why    # the why tasks (the paper tasks it skipped are done)
"""

from __future__ import annotations

import argparse
import heapq
import json
import re
from pathlib import Path

from fnnbook.executor import longest_remaining
from fnnbook.spec import load_spec

ROOT = Path(__file__).resolve().parents[1]
_OK = re.compile(r"--- ok after ([0-9.]+) s ---")


def measured(profile_dir: Path, tasks: list[str]) -> dict[str, float]:
    """Task -> measured seconds (status file first, then the log); tasks with neither are left out."""
    try:
        status = json.loads((profile_dir / "_status.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        status = {}
    seconds: dict[str, float] = {}
    for task in tasks:
        entry = status.get(task)
        if isinstance(entry, dict) and entry.get("status") == "skipped":
            continue  # up to date before the run (the why profile's paper tasks): not part of its work
        if isinstance(entry, dict) and isinstance(entry.get("seconds"), (int, float)):
            seconds[task] = float(entry["seconds"])
        elif (log := profile_dir / "_logs" / f"{task}.log").is_file() and (
                found := _OK.findall(log.read_text(encoding="utf-8", errors="replace"))):
            seconds[task] = float(found[-1])
    return seconds


def list_schedule(upstream: dict[str, list[str]], seconds: dict[str, float], workers: int) -> float:
    """Makespan of the longest-remaining-path list schedule on ``workers`` identical workers."""
    priority = longest_remaining(upstream, seconds)
    waiting = {t: set(ups) & set(upstream) for t, ups in upstream.items()}
    ready = [(-priority[t], t) for t, ups in waiting.items() if not ups]
    heapq.heapify(ready)
    running: list[tuple[float, str]] = []  # (finish time, task)
    now = 0.0
    while ready or running:
        while ready and len(running) < workers:
            _, task = heapq.heappop(ready)
            heapq.heappush(running, (now + seconds[task], task))
        now, done = heapq.heappop(running)
        for task, ups in waiting.items():
            if done in ups:
                ups.discard(done)
                if not ups:
                    heapq.heappush(ready, (-priority[task], task))
    return now


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("profile_dir", type=Path, help="<output_root>/<profile> of a finished run")
    parser.add_argument("--pipeline", type=Path, default=ROOT / "pipeline.yaml")
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2, 3, 4, 6, 8])
    args = parser.parse_args()
    spec = load_spec(args.pipeline)
    profile = args.profile_dir.name  # the tasks this profile runs (a why run: its own, after the paper's)
    names = spec.closure(spec.declares(profile)) if profile in spec.profiles else list(spec.tasks)
    every = {n: list(spec.tasks[n].upstream) for n in names}  # grids as their points
    seconds = measured(args.profile_dir, list(every))
    if missing := sorted(set(every) - set(seconds)):
        print(f"no measured time (left out): {', '.join(missing)}")
    upstream = {t: [u for u in ups if u in seconds] for t, ups in every.items() if t in seconds}
    total, critical = sum(seconds.values()), max(longest_remaining(upstream, seconds).values())
    print(f"{len(seconds)} tasks, {total:.0f} s of task time, critical path {critical:.0f} s")
    for k in args.workers:
        span = list_schedule(upstream, seconds, k)
        print(f"K={k}: {span:6.0f} s  (bound {max(critical, total / k):6.0f} s, utilisation {total / (k * span):.0%})")


if __name__ == "__main__":
    main()

"""A pytest plugin: the CPU seconds each test costs, its own and its children's, written as JSON lines.

Wall times (``--durations``) say where a 2-core run waits; CPU seconds say what each test costs whatever runs
beside it, which is what a suite on 2 workers has to divide. A child process counts once it has been waited for
(a notebook's kernel, a pytest of nbval, a pipeline command).

usage: PYTHONPATH=benchmarks python -m pytest -p pytest_cpu [pytest args]   (writes $PYTEST_CPU_OUT or
       pytest_cpu.jsonl; with xdist each worker appends its own lines), then
       python benchmarks/pytest_cpu.py pytest_cpu.jsonl   (totals by group and the 30 costliest tests)
"""

from __future__ import annotations

import collections
import json
import os
import resource
import sys
import time
from pathlib import Path

import pytest

OUT = Path(os.environ.get("PYTEST_CPU_OUT", "pytest_cpu.jsonl"))


def _cpu() -> float:
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None):
    cpu, wall, start = _cpu(), time.perf_counter(), time.time()
    yield
    line = {"test": item.nodeid, "cpu_s": round(_cpu() - cpu, 3), "wall_s": round(time.perf_counter() - wall, 3),
            "worker": os.environ.get("PYTEST_XDIST_WORKER", "main"), "start": round(start, 3)}
    with OUT.open("a", encoding="utf-8") as f:
        f.write(json.dumps(line) + "\n")


def _group(nodeid: str) -> str:
    path, _, name = nodeid.partition("::")
    if path.endswith("test_nbval.py") and name.startswith("test_executed"):
        return "nbval reruns"
    if path.endswith("test_notebooks.py"):
        return "smoke tasks"
    return path.rsplit("/", 1)[0] if path.count("/") > 1 else path


def summary(path: Path) -> None:
    rows = [json.loads(line) for line in path.read_text(encoding="utf-8").splitlines() if line.strip()]
    groups: collections.Counter[str] = collections.Counter()
    for r in rows:
        groups[_group(r["test"])] += r["cpu_s"]
    print(f"{len(rows)} tests, {sum(r['cpu_s'] for r in rows):.0f} CPU s, {sum(r['wall_s'] for r in rows):.0f} test-wall s")
    for name, cpu in groups.most_common():
        print(f"{cpu:8.1f}  {name}")
    print()
    for r in sorted(rows, key=lambda r: -r["cpu_s"])[:30]:
        print(f"{r['cpu_s']:8.1f} cpu {r['wall_s']:7.1f} wall  {r['test']}")
    if all("start" in r for r in rows):
        _timeline(rows)


def _timeline(rows: list[dict]) -> None:
    """When each worker started its first test and ended its last, and the tests of 5 s or more in time order:
    the suite's tail, and which long test ran beside which."""
    t0 = min(r["start"] for r in rows)
    print(f"\ntimeline (s from the first test's start)")
    for worker in sorted({r["worker"] for r in rows}):
        mine = [r for r in rows if r["worker"] == worker]
        end = max(r["start"] + r["wall_s"] for r in mine)
        print(f"  {worker}: first test at {min(r['start'] for r in mine) - t0:6.1f}, last ends at {end - t0:6.1f}")
    for r in sorted((r for r in rows if r["wall_s"] >= 5), key=lambda r: r["start"]):
        start = r["start"] - t0
        print(f"  {start:6.1f} - {start + r['wall_s']:6.1f}  {r['worker']}  {r['test']}")


if __name__ == "__main__":
    summary(Path(sys.argv[1]))

"""The Dask executor on tiny notebooks: overlap, order, grids, faults, a real cluster, Ctrl-C.

Each test starts a LocalCluster of 2 single-threaded worker processes (or a
scheduler and two workers with the ``dask`` command line) on 127.0.0.1.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import psutil
import pytest
import yaml

from fnnbook import PipelineSpec, load_spec, run
from fnnbook.cli import main
from fnnbook.execution import deferring_interrupts
from fnnbook.executor import longest_remaining, run_on_dask
from fnnbook.kernel import stop_kernels, task_kernel
from fnnbook.layout import RUN_KEY, STATUS_FILE, read_status, staging_of, write_status
from fnnbook.outcome import RunReport, Status, TaskOutcome
from fnnbook.runner import check, decide

from .nbfactory import CHILD_BODY, CHILD_PARAMS, LEAF_BODY, LEAF_PARAMS, MakePipeline, child_task, leaf_task, write_notebook

# A leaf that records when it ran (wall clock) and sleeps `nap` seconds in between. With `meet_within` > 0 it
# also waits (that long at most) until another timed task of the run has started: two tasks that run at the
# same time always overlap, however slowly a loaded machine starts their kernels. The tasks meet in
# <output_root>/<profile>/started (out_dir is the run's staging folder <profile>/.staging/<run>/<task>).
TIMED_PARAMS = LEAF_PARAMS + "nap = 0.0\nmeet_within = 0.0\n"
TIMED_BODY = """\
import json, pathlib, time
start = time.time()
meet = pathlib.Path(out_dir).parents[2] / "started"
meet.mkdir(exist_ok=True)
(meet / pathlib.Path(out_dir).name).write_text("x")
while time.time() - start < meet_within and len(list(meet.iterdir())) < 2:
    time.sleep(0.05)
time.sleep(nap)
""" + LEAF_BODY + """\
(out / "times.json").write_text(json.dumps([start, time.time()]))
"""
CHILD_TIMED_BODY = "import json, time\nstart = time.time()\n" + CHILD_BODY + """\
(pathlib.Path(out_dir) / "times.json").write_text(json.dumps([start, time.time()]))
"""
# The aggregate step of a grid: sums value.txt over every point it is given.
AGG_BODY = """\
import pathlib
total = sum(float((pathlib.Path(d) / "value.txt").read_text()) for d in upstream_dirs.values())
(pathlib.Path(out_dir) / "total.txt").write_text(f"{len(upstream_dirs)} {total}")
"""
# Kills the worker process that runs it (the kernel's parent) on the first attempt; `always` on every one.
KILLER_BODY = """\
import os, pathlib, signal
marker = pathlib.Path(out_dir).parent.parent / "attempted"
if always or not marker.exists():
    marker.write_text("x")
    os.kill(os.getppid(), signal.SIGKILL)
(pathlib.Path(out_dir) / "value.txt").write_text("done")
"""


def _tasks(tmp_path: Path) -> dict[str, Any]:
    write_notebook(tmp_path / "notebooks" / "timed.ipynb", TIMED_PARAMS, TIMED_BODY)
    write_notebook(tmp_path / "notebooks" / "child.ipynb", CHILD_PARAMS, CHILD_TIMED_BODY)
    write_notebook(tmp_path / "notebooks" / "agg.ipynb", CHILD_PARAMS, AGG_BODY)
    def timed(**extra: Any) -> dict[str, Any]:
        return {**leaf_task(nap=1.5), "notebook": "notebooks/timed.ipynb", "products": ["results.json", "times.json"],
                **extra}

    return {
        "leaf": timed(),
        "other": timed(claims=[]),
        "child": {**child_task(), "products": ["double.txt", "times.json"]},
        "pt": timed(claims=[], parameters={"smoke": {}, "paper": {}}, grid={"value": [1, 2]}),
        "agg": {"title": "Aggregate", "notebook": "notebooks/agg.ipynb", "upstream": ["pt"],
                "products": ["total.txt"], "parameters": {"smoke": {}}},
    }


def _times(spec: PipelineSpec, task: str) -> tuple[float, float]:
    start, end = json.loads((spec.output_dir("smoke", task) / "times.json").read_text())
    return start, end


def test_parallel_overlaps_independent_tasks_respects_order_and_matches_serial(
        make_pipeline: MakePipeline, tmp_path: Path) -> None:
    tasks = _tasks(tmp_path)
    del tasks["other"]
    for name in ("leaf", "pt"):  # each independent task waits (up to 60 s) for another to start beside it
        tasks[name]["parameters"]["smoke"]["meet_within"] = 60.0
    spec = load_spec(make_pipeline(tasks, parts=[{"title": "P", "tasks": list(tasks)}]))
    assert spec.grids == {"pt": ("pt__value_1", "pt__value_2")}
    lines: list[str] = []
    report = run(spec, "smoke", workers=2, progress_bar=False, echo=lines.append)
    assert report.ok, lines
    assert {o.status for o in report.outcomes} == {"ok"}
    assert lines[0].startswith("running on a local Dask cluster: 2 worker(s), ")
    assert lines[1].startswith("dashboard: http://127.0.0.1:"), lines[1]  # bokeh is in the lock: a live dashboard
    # the utilisation: the task seconds over 2 workers' wall time, printed and recorded
    assert report.workers == 2 and report.wall > 0
    assert report.busy == pytest.approx(sum(o.seconds for o in report.outcomes))
    assert report.utilisation == pytest.approx(report.busy / (2 * report.wall))
    assert 0 < report.utilisation <= 1
    assert lines[-2] == f"utilisation {100 * report.utilisation:.0f}% (task time {report.busy:.1f} s / " \
                        f"(2 worker(s) x {report.wall:.1f} s wall))"
    status = read_status(spec, "smoke")
    assert status[RUN_KEY]["workers"] == 2
    assert status[RUN_KEY]["utilisation"] == pytest.approx(report.utilisation, abs=1e-4)
    assert status["leaf"]["seconds"] == pytest.approx(report.outcome("leaf").seconds, abs=0.01)

    leaf, child = _times(spec, "leaf"), _times(spec, "child")
    assert child[0] >= leaf[1]  # after its upstream task
    # two workers: some pair of independent tasks ran at the same time
    spans = [_times(spec, t) for t in ("leaf", "pt__value_1", "pt__value_2")]
    assert any(a[0] < b[1] and b[0] < a[1] for i, a in enumerate(spans) for b in spans[i + 1:])

    # the grid: one output folder and fingerprint per point; the aggregate read both
    fp = [json.loads((spec.output_dir("smoke", p) / ".fingerprint.json").read_text())["fingerprint"]
          for p in spec.grids["pt"]]
    assert fp[0] != fp[1]
    assert (spec.output_dir("smoke", "agg") / "total.txt").read_text() == "2 3.0"
    assert max(_times(spec, p)[1] for p in spec.grids["pt"]) <= (
        spec.output_dir("smoke", "agg") / "total.txt").stat().st_mtime

    # the serial path gives the same results.json
    serial = spec.with_paths(output_root=tmp_path / "serial")
    met = serial.output_root / "smoke" / "started"  # alone on purpose: nothing to wait for
    met.mkdir(parents=True)
    for name in ("a", "b"):
        (met / name).write_text("x")
    assert run(serial, "smoke", ["leaf"], workers=1, progress_bar=False, echo=lambda _: None).ok
    start, end = json.loads((serial.output_dir("smoke", "leaf") / "times.json").read_text())
    assert end - start < 30.0  # it found the meeting place full and did not wait out its 60 s
    for task in ("leaf",):
        assert (serial.output_dir("smoke", task) / "results.json").read_bytes() == (
            spec.output_dir("smoke", task) / "results.json").read_bytes()

    # nothing changed: everything skipped (no cluster work)
    report = run(spec, "smoke", workers=2, progress_bar=False, echo=lambda _: None)
    assert {o.status for o in report.outcomes} == {"skipped"}
    assert read_status(spec, "smoke")["leaf"]["seconds"] == status["leaf"]["seconds"]  # kept: the next estimate


def test_longest_remaining_path_puts_the_long_chain_first() -> None:
    # the paper's shape: a three-task chain beside short independent tasks, and a join
    upstream = {"spiral": [], "bottle": [], "q_learn": [], "q_mpc": ["q_learn"],
                "tuned": ["q_mpc", "spiral", "up_to_date"]}  # up_to_date does not run: not in the graph
    seconds = {"spiral": 100.0, "bottle": 150.0, "q_learn": 200.0, "q_mpc": 250.0, "tuned": 40.0}
    path = longest_remaining(upstream, seconds)
    assert path == {"tuned": 40.0, "q_mpc": 290.0, "q_learn": 490.0, "spiral": 140.0, "bottle": 150.0}
    assert sorted(path, key=path.get, reverse=True)[:2] == ["q_learn", "q_mpc"]
    # the estimate alone does not decide: a short task heading a long chain beats a longer lone task
    assert longest_remaining({"a": [], "b": ["a"], "lone": []}, {"a": 1.0, "b": 9.0, "lone": 5.0}) == {
        "b": 9.0, "a": 10.0, "lone": 5.0}


def test_one_worker_takes_the_long_chain_first(make_pipeline: MakePipeline, tmp_path: Path) -> None:
    # submitted in plan order (other, leaf, child); the last run's seconds make leaf -> child the long path
    tasks = _tasks(tmp_path)
    tasks = {t: tasks[t] for t in ("other", "leaf", "child")}
    tasks["leaf"]["parameters"]["smoke"]["nap"] = 0.0
    spec = load_spec(make_pipeline(tasks, parts=[{"title": "P", "tasks": ["other", "leaf", "child"]}]))
    (spec.output_root / "smoke").mkdir(parents=True)
    (spec.output_root / "smoke" / STATUS_FILE).write_text(json.dumps(
        {"other": {"status": "ok", "message": "", "seconds": 5.0}, "leaf": {"status": "ok", "message": "", "seconds": 3.0},
         "child": {"status": "ok", "message": "", "seconds": 3.0}}))
    plan = check(spec, "smoke")
    assert plan.order == ("other", "leaf", "child")
    with staging_of(spec, "smoke", plan.run):
        outcomes = run_on_dask(spec, plan, decide(spec, plan), workers=1, scheduler=None, threads=1,
                               echo=lambda _: None, progress_bar=False)
    assert {o.status for o in outcomes.values()} == {Status.OK}
    started = sorted(("other", "leaf", "child"), key=lambda t: _times(spec, t)[0])
    assert started == ["leaf", "other", "child"]  # 6 s of chain ahead of leaf, then other's 5 s, then child's 3 s


def test_utilisation_is_task_time_over_workers_times_wall(make_pipeline: MakePipeline, tmp_path: Path) -> None:
    def outcome(task: str, status: Status, seconds: float) -> TaskOutcome:
        return TaskOutcome(task, status, seconds, tmp_path / task)

    ran = (outcome("a", Status.OK, 30.0), outcome("b", Status.FAILED, 10.0), outcome("c", Status.SKIPPED, 0.0))
    report = RunReport("smoke", ran, workers=2, wall=25.0)
    assert report.busy == 40.0 and report.utilisation == pytest.approx(0.8)
    assert RunReport("smoke", ran[2:], workers=2, wall=1.0).utilisation is None  # nothing ran
    spec = load_spec(make_pipeline())
    write_status(spec, report)
    status = read_status(spec, "smoke")
    assert status[RUN_KEY] == {"workers": 2, "wall_seconds": 25.0, "task_seconds": 40.0, "utilisation": 0.8}
    assert status["a"]["seconds"] == 30.0 and "seconds" not in status["b"]  # a failed run is no estimate
    write_status(spec, RunReport("smoke", (outcome("a", Status.SKIPPED, 0.0),), workers=1, wall=0.5))
    assert read_status(spec, "smoke")["a"] == {"status": "skipped", "message": "", "seconds": 30.0}
    assert read_status(spec, "smoke")[RUN_KEY]["workers"] == 2  # a run where nothing ran leaves the last one


def test_a_failing_task_is_isolated(make_pipeline: MakePipeline, tmp_path: Path) -> None:
    tasks = _tasks(tmp_path)
    del tasks["pt"], tasks["agg"]
    pipeline = make_pipeline(tasks, parts=[{"title": "P", "tasks": ["leaf", "other", "child"]}])
    spec = load_spec(pipeline)
    assert run(spec, "smoke", ["leaf"], workers=1, progress_bar=False, echo=lambda _: None).ok
    before = {p.name: p.read_bytes() for p in spec.output_dir("smoke", "leaf").iterdir()}

    doc = yaml.safe_load(pipeline.read_text())
    doc["tasks"]["leaf"]["parameters"]["smoke"]["fail"] = True
    pipeline.write_text(yaml.safe_dump(doc))
    lines: list[str] = []
    report = run(load_spec(pipeline), "smoke", workers=2, progress_bar=False, echo=lines.append)
    assert not report.ok
    assert [report.outcome(t).status for t in ("leaf", "other", "child")] == ["failed", "ok", "not run"]
    assert report.outcome("child").message == "upstream leaf failed"
    assert {p.name: p.read_bytes() for p in spec.output_dir("smoke", "leaf").iterdir()} == before
    assert lines[-1].splitlines() == ["profile smoke: 1 ok, 1 failed, 1 not run",
                          f"  FAILED leaf: log {spec.output_root / 'smoke' / '_logs' / 'leaf.log'}",
                          "  NOT RUN child: upstream leaf failed"]


@pytest.mark.parametrize("always", [False, True])
def test_a_killed_worker_is_retried_once_then_reported(make_pipeline: MakePipeline, tmp_path: Path,
                                                       always: bool) -> None:
    write_notebook(tmp_path / "notebooks" / "killer.ipynb", 'profile = ""\nout_dir = ""\nalways = False\n',
                   KILLER_BODY)
    spec = load_spec(make_pipeline({"killer": {
        "title": "Killer", "notebook": "notebooks/killer.ipynb", "products": ["value.txt"],
        "parameters": {"smoke": {"always": always}}}}))
    report = run(spec, "smoke", workers=2, progress_bar=False, echo=lambda _: None)
    out = spec.output_dir("smoke", "killer")
    staging = spec.output_root / "smoke" / ".staging" / "killer"
    if always:
        assert report.outcome("killer").status == "failed"
        assert "worker process running it died" in report.outcome("killer").message
        assert not out.exists()
        assert "--- FAILED: the worker process running it died" in (
            spec.output_root / "smoke" / "_logs" / "killer.log").read_text()
    else:
        assert report.ok and (out / "value.txt").read_text() == "done"
        assert "--- FAILED: the process running this attempt was killed" in (
            spec.output_root / "smoke" / "_logs" / "killer.previous.log").read_text()
    assert not staging.exists()  # no half-written outputs


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _wait_for_workers(address: str, n: int, timeout: float = 60.0) -> None:
    from distributed import Client

    with Client(address, timeout="30s") as client:
        client.wait_for_workers(n, timeout=timeout)


def test_runs_on_a_running_cluster(make_pipeline: MakePipeline, tmp_path: Path,
                                   capsys: pytest.CaptureFixture[str]) -> None:
    tasks = _tasks(tmp_path)
    del tasks["pt"], tasks["agg"]
    for name in ("leaf", "other"):
        tasks[name]["parameters"]["smoke"]["nap"] = 0.0  # nothing here times them
    pipeline = make_pipeline(tasks, parts=[{"title": "P", "tasks": ["leaf", "other", "child"]}])
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    dask = [str(Path(sys.executable).parent / "dask")]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(Path(__file__).parents[2]),
                                                                      os.environ.get("PYTHONPATH")]))}
    procs = [subprocess.Popen([*dask, "scheduler", "--host", "127.0.0.1", "--port", str(port),
                               "--no-dashboard"], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        for _ in range(2):
            procs.append(subprocess.Popen([*dask, "worker", address, "--nthreads", "1", "--nworkers", "1",
                                           "--no-dashboard", "--host", "127.0.0.1"], env=env,
                                          stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        _wait_for_workers(address, 2)
        assert main(["run", "--profile", "smoke", "--pipeline", str(pipeline), "--no-progress",
                     "--scheduler", address]) == 0
        out = capsys.readouterr().out
        assert f"running on Dask scheduler {address}: 2 worker(s)" in out
        assert "profile smoke: 3 ok" in out
    finally:
        # the workers first, then the scheduler: a worker whose scheduler is gone tries to reconnect for ~8 s
        # before it exits; with its scheduler still there it leaves at once
        for group in (procs[1:], procs[:1]):
            for p in group:
                p.send_signal(signal.SIGTERM)
            for p in group:
                try:
                    p.wait(timeout=20)
                except subprocess.TimeoutExpired:
                    p.kill()
                    p.wait()
    assert all(p.poll() is not None for p in procs)


def _processes_in(folder: Path) -> list[str]:
    """Command lines of the processes whose working directory is inside ``folder``."""
    found = []
    for p in psutil.process_iter():
        with contextlib.suppress(psutil.Error):
            if Path(p.cwd()).is_relative_to(folder):
                found.append(" ".join(p.cmdline()))
    return found


def test_a_kernel_still_starting_at_the_stop_is_killed_as_it_appears() -> None:
    """A Ctrl-C can come while papermill starts a task's kernel: no child process yet. The stop outwaits the
    task and kills the kernel as it appears, so it cannot outlive its worker (and hold the run's terminal)."""
    registered, codes = threading.Event(), []

    def task() -> None:
        with task_kernel():
            registered.set()
            time.sleep(0.3)  # the stop comes meanwhile; then the stand-in kernel appears
            proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)", "ipykernel"])
            codes.append(proc.wait(timeout=30))

    thread = threading.Thread(target=task)
    thread.start()
    registered.wait(10)
    assert asyncio.run(stop_kernels(patience=30)) == 1
    thread.join(10)
    assert codes == [-signal.SIGKILL]
    assert asyncio.run(stop_kernels(patience=30)) == 0  # no task running: nothing to outwait


def test_a_ctrl_c_while_deferred_arrives_when_the_block_ends() -> None:
    reached = []
    before = signal.signal(signal.SIGINT, signal.default_int_handler)  # as in a terminal (whatever this worker has)
    try:
        with pytest.raises(KeyboardInterrupt):
            with deferring_interrupts():
                os.kill(os.getpid(), signal.SIGINT)
                time.sleep(0.05)
                reached.append("the block ran to its end")
        assert reached
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # put back
    finally:
        signal.signal(signal.SIGINT, before)


def test_ctrl_c_cancels_and_leaves_no_processes(make_pipeline: MakePipeline, tmp_path: Path) -> None:
    write_notebook(tmp_path / "notebooks" / "timed.ipynb", TIMED_PARAMS, TIMED_BODY)
    timed = {**leaf_task(nap=120.0), "notebook": "notebooks/timed.ipynb"}
    pipeline = make_pipeline({"leaf": timed, "other": {**timed, "claims": [], "parameters": {"smoke": {"nap": 120.0}}}},
                             parts=[{"title": "P", "tasks": ["leaf", "other"]}])
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(Path(__file__).parents[2]),
                                                                      os.environ.get("PYTHONPATH")]))}
    proc = subprocess.Popen([sys.executable, "-m", "fnnbook", "run", "--profile", "smoke", "--pipeline",
                             str(pipeline), "--no-progress", "--workers", "2"], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True,
                            # Ctrl-C as a terminal's foreground job gets it, whatever this test process ignores
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    logs = tmp_path / "outputs" / "smoke" / "_logs"
    started = tmp_path / "outputs" / "smoke" / "started"  # each kernel marks its start there, then naps
    deadline = time.time() + 90
    while time.time() < deadline and not all((started / t).exists() for t in ("leaf", "other")):
        time.sleep(0.2)
    time.sleep(0.5)  # past the marks, the kernels napping (test_a_kernel_still_starting_at_the_stop_is_killed: before)
    family = psutil.Process(proc.pid).children(recursive=True)
    assert len(family) >= 4  # two workers (with their nanny/spawn helpers) and two kernels
    os.killpg(proc.pid, signal.SIGINT)  # Ctrl-C reaches the terminal's whole foreground process group
    out, _ = proc.communicate(timeout=60)  # until the run and all that holds its output (a kernel too) are gone
    assert proc.returncode == 130, out
    assert "interrupted" in out
    assert "Task exception was never retrieved" not in out
    assert "Traceback" not in out, out  # no worker took the Ctrl-C itself (its KeyboardInterrupt)
    gone, alive = psutil.wait_procs(family, timeout=15)
    assert not alive, [p.cmdline() for p in alive]
    assert not _processes_in(tmp_path), "a process of the run (a kernel: cwd is the pipeline's root) outlived it"
    assert not (tmp_path / "outputs" / "smoke" / "leaf").exists()
    assert "\n--- FAILED" in (logs / "leaf.log").read_text()  # by the task itself or, if it was gone, the runner


# A stand-in for fnnbook.cli whose import is cut short by a Ctrl-C: the press arrives while its code runs.
SLOW_IMPORT = '''\
import importlib.abc, importlib.util, sys
BODY = """
import os, signal
try:
    os.kill(os.getpid(), signal.SIGINT)
    for _ in range(10 ** 7):
        pass
except KeyboardInterrupt:
    print("a KeyboardInterrupt reached the imported code", flush=True)
    raise
print("the import went on after the Ctrl-C", flush=True)
"""
class SlowCli(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    def find_spec(self, name, path, target=None):
        return importlib.util.spec_from_loader(name, self) if name == "fnnbook.cli" else None
    def create_module(self, spec):
        return None
    def exec_module(self, module):
        exec(BODY, {})
sys.meta_path.insert(0, SlowCli())
from fnnbook.entry import main
sys.exit(main([]))
'''


def test_ctrl_c_during_the_imports_never_raises_inside_them(tmp_path: Path) -> None:
    """A KeyboardInterrupt raised inside the imports is not safe to catch: raised in torch's C++ bindings it
    aborted the command (SIGABRT), raised in code run through exec (dataclasses, numpy) CPython killed the process
    with SIGINT at exit (status -2, after it had printed "interrupted"). So the press ends the command at once:
    the imported code never sees a KeyboardInterrupt, never goes on, and the status is 130."""
    script = tmp_path / "slow_import.py"
    script.write_text(SLOW_IMPORT)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(Path(__file__).parents[2]),
                                                                      os.environ.get("PYTHONPATH")]))}
    proc = subprocess.run([sys.executable, str(script)], env=env, capture_output=True, text=True, timeout=120,
                          preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    assert (proc.returncode, proc.stdout, proc.stderr) == (130, "", "interrupted\n")


@pytest.mark.parametrize("when", ["imports", "spawn", "spawn+0.5s"])
def test_ctrl_c_at_any_moment_is_one_line_and_exit_130(make_pipeline: MakePipeline, tmp_path: Path, when: str) -> None:
    """Ctrl-C while the command imports its modules, as the cluster's first worker process is spawned, and half a
    second into the spawn: no traceback (before: "RuntimeError: Nanny failed to start." in 126 lines, exit 1,
    the run not recorded; during imports a KeyboardInterrupt traceback), exit 130, and once the run has begun
    its tasks are recorded as interrupted."""
    write_notebook(tmp_path / "notebooks" / "timed.ipynb", TIMED_PARAMS, TIMED_BODY)
    timed = {**leaf_task(nap=120.0), "notebook": "notebooks/timed.ipynb"}
    pipeline = make_pipeline({"leaf": timed, "other": {**timed, "claims": [], "parameters": {"smoke": {"nap": 120.0}}}},
                             parts=[{"title": "P", "tasks": ["leaf", "other"]}])
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(Path(__file__).parents[2]),
                                                                      os.environ.get("PYTHONPATH")]))}
    proc = subprocess.Popen([sys.executable, "-m", "fnnbook", "run", "--profile", "smoke", "--pipeline",
                             str(pipeline), "--no-progress", "--workers", "2"], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    if when == "imports":
        time.sleep(0.3)  # the interpreter is up, the command's imports (dask, papermill) take seconds
        assert not psutil.Process(proc.pid).children()
    else:
        deadline = time.time() + 120
        while time.time() < deadline and not psutil.Process(proc.pid).children():
            time.sleep(0.01)  # the first process the cluster starts
        assert psutil.Process(proc.pid).children(), "the cluster never started a process"
        time.sleep(0.5 if when == "spawn+0.5s" else 0.0)
    family = psutil.Process(proc.pid).children(recursive=True)
    os.killpg(proc.pid, signal.SIGINT)  # Ctrl-C reaches the terminal's whole foreground process group
    out, _ = proc.communicate(timeout=120)
    assert proc.returncode == 130, out
    assert "Traceback" not in out and "Nanny failed" not in out, out
    assert out.strip().splitlines()[-1] == "interrupted", out
    psutil.wait_procs(family, timeout=15)
    assert not _processes_in(tmp_path), "a process of the run outlived it"
    status = tmp_path / "outputs" / "smoke" / STATUS_FILE
    if when == "imports":
        assert out.strip() == "interrupted" and not status.exists()
    else:
        recorded = json.loads(status.read_text())
        assert {recorded[t]["message"] for t in ("leaf", "other")} == {"interrupted"}, recorded

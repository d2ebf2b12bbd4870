"""The runner under faults: concurrent runs, file-system faults, a second Ctrl-C, stale staging, file modes.

Most tests swap papermill for a stand-in that writes the leaf notebook's products at once (no kernel), so a
loop of twenty concurrent runs takes seconds; the full-disk test runs a real kernel on a small tmpfs.
"""

from __future__ import annotations

import json
import os
import random
import shutil
import signal
import subprocess
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from fnnbook import load_spec, run
from fnnbook.cli import main
from fnnbook.layout import holding, read_status
from fnnbook.params import FINGERPRINT_FILE
from fnnlib.io import atomic_write, file_sha256

from .nbfactory import MakePipeline, child_task, leaf_task


def _stand_in(input_path: str, output_path: str, parameters: dict[str, Any], **_: Any) -> None:
    """papermill.execute_notebook for the leaf notebook: its two products, a pause between them."""
    out = Path(parameters["out_dir"])
    (out / "value.txt").write_text(str(parameters["value"] * parameters["scale"]))
    time.sleep(random.uniform(0.0, 0.01))
    (out / "results.json").write_text(json.dumps({"numbers": {"value": parameters["value"]}}))
    shutil.copy(input_path, output_path)


@pytest.fixture
def no_kernel(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr("fnnbook.execution.papermill.execute_notebook", _stand_in)


def _quiet(spec, tasks=None, **kw):  # type: ignore[no-untyped-def]
    return run(spec, "smoke", tasks, progress_bar=False, echo=kw.pop("echo", lambda _: None), **kw)


def _consistent(out: Path) -> int:
    """The one value a task's output folder holds, checked against its run record; fails on a mix."""
    record = json.loads((out / FINGERPRINT_FILE).read_text())
    value = record["parameters"]["value"]
    assert (out / "value.txt").read_text() == str(value * 1.0)
    assert json.loads((out / "results.json").read_text())["numbers"]["value"] == value
    assert all(file_sha256(out / p) == h for p, h in record["products"].items())
    return value


@pytest.mark.usefixtures("no_kernel")
def test_two_runs_with_different_parameters_never_mix(make_pipeline: MakePipeline) -> None:
    spec_a = load_spec(make_pipeline({"leaf": leaf_task(value=2)}))
    spec_b = load_spec(make_pipeline({"leaf": leaf_task(value=3)}))  # the same output root
    rng = random.Random(0)
    seen = set()
    for _ in range(20):
        reports: dict[str, Any] = {}

        def go(key: str, spec: Any, delay: float) -> None:
            time.sleep(delay)
            reports[key] = _quiet(spec, force=True)

        threads = [threading.Thread(target=go, args=("a", spec_a, 0.0)),
                   threading.Thread(target=go, args=("b", spec_b, rng.uniform(0.0, 0.02)))]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        assert reports["a"].ok and reports["b"].ok
        seen.add(_consistent(spec_a.output_dir("smoke", "leaf")))
        assert not list((spec_a.output_root / "smoke" / ".staging").glob("*/*"))
    assert seen <= {2, 3}


@pytest.mark.usefixtures("no_kernel")
def test_a_second_run_waits_and_says_who_holds_the_outputs(make_pipeline: MakePipeline) -> None:
    spec = load_spec(make_pipeline())
    lines: list[str] = []
    with holding(spec, "smoke", ["leaf"]):
        t = threading.Thread(target=lambda: lines.append(_quiet(spec, echo=lines.append).ok))
        t.start()
        deadline = time.time() + 10
        while not any("waiting" in str(line) for line in lines) and time.time() < deadline:
            time.sleep(0.02)
        assert not spec.output_dir("smoke", "leaf").exists()  # it waits: nothing written meanwhile
    t.join()
    waiting = next(line for line in lines if "waiting" in str(line))
    assert f"pid {os.getpid()} on " in waiting and "leaf" in waiting
    assert lines[-1] is True


@pytest.mark.usefixtures("no_kernel")
def test_stale_staging_of_a_killed_run_is_cleared_when_the_task_is_skipped(make_pipeline: MakePipeline) -> None:
    spec = load_spec(make_pipeline())
    assert _quiet(spec).ok
    left = spec.output_root / "smoke" / ".staging" / "4242-0badf00d" / "leaf"  # SIGKILL mid-task
    left.mkdir(parents=True)
    (left / "value.txt").write_text("half")
    report = _quiet(spec)
    assert report.outcome("leaf").status == "skipped"
    assert not left.parent.exists()


def test_products_get_the_mode_open_would_give() -> None:
    old = os.umask(0o022)
    try:
        path = Path(os.environ.get("TMPDIR", "/tmp")) / f"fnn-mode-{os.getpid()}.txt"
        with atomic_write(path, "w") as fh:
            fh.write("x")
        assert path.stat().st_mode & 0o777 == 0o644
        os.umask(0o077)
        with atomic_write(path, "w") as fh:
            fh.write("y")
        assert path.stat().st_mode & 0o777 == 0o600
        path.unlink()
    finally:
        os.umask(old)


def test_a_second_ctrl_c_still_records_the_interrupted_run(make_pipeline: MakePipeline,
                                                           monkeypatch: pytest.MonkeyPatch) -> None:
    spec = load_spec(make_pipeline())

    def first(input_path: str, output_path: str, parameters: dict[str, Any], **_: Any) -> None:
        (Path(parameters["out_dir"]) / "value.txt").write_text("half")
        raise KeyboardInterrupt

    def second() -> int:  # the user presses Ctrl-C again while the kernels are being stopped
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(0.05)
        return 0

    monkeypatch.setattr("fnnbook.execution.papermill.execute_notebook", first)
    monkeypatch.setattr("fnnbook.execution.kill_kernels", second)
    with pytest.raises(KeyboardInterrupt):
        _quiet(spec)
    log = (spec.output_root / "smoke" / "_logs" / "leaf.log").read_text()
    assert "--- FAILED" in log
    assert not list((spec.output_root / "smoke" / ".staging").glob("*/*"))
    assert read_status(spec, "smoke")["leaf"] == {"status": "failed", "message": "interrupted"}


@pytest.mark.usefixtures("no_kernel")
def test_a_missing_permission_fails_one_task_and_the_others_go_on(make_pipeline: MakePipeline,
                                                                  monkeypatch: pytest.MonkeyPatch,
                                                                  capsys: pytest.CaptureFixture[str]) -> None:
    path = make_pipeline({"leaf": leaf_task(), "child": child_task(), "other": leaf_task(value=5)})
    import fnnbook.execution as execution

    real = execution._open_log

    def denied(logs: Path, name: str) -> Any:
        if name == "leaf":
            raise PermissionError(13, "Permission denied", str(logs / f"{name}.log"))
        return real(logs, name)

    monkeypatch.setattr(execution, "_open_log", denied)
    assert main(["run", "--pipeline", str(path), "--profile", "smoke", "--workers", "1", "--no-progress"]) == 2
    out = capsys.readouterr()
    assert "Traceback" not in out.out + out.err
    assert "leaf ... FAILED" in out.out and "PermissionError: Permission denied: " in out.out
    assert "child ... not run (upstream leaf failed)" in out.out
    assert "other ... ok" in out.out
    assert not list((path.parent / "outputs" / "smoke" / ".staging").glob("*/*"))


@pytest.fixture
def tmpfs(tmp_path: Path) -> Any:
    """Mount a small tmpfs (size in KiB) under tmp_path; unmounted afterwards. Skipped where mount is refused."""
    mounted: list[Path] = []

    def make(kib: int) -> Path:
        where = tmp_path / f"tmpfs{len(mounted)}"
        where.mkdir()
        done = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={kib}k", "tmpfs", str(where)],
                              capture_output=True, check=False)
        if done.returncode != 0:
            pytest.skip(f"cannot mount a tmpfs here: {done.stderr.decode().strip()}")
        mounted.append(where)
        return where

    yield make
    for where in mounted:
        subprocess.run(["umount", "-l", str(where)], check=False)


def _big_leaf(make_pipeline: MakePipeline, root: Path) -> Path:
    """The leaf task plus a task whose notebook writes 1 MiB (more than the small disk holds)."""
    from .nbfactory import LEAF_PARAMS, write_notebook

    nb = root.parent / "notebooks" / "big.ipynb"
    write_notebook(nb, LEAF_PARAMS, "import pathlib\n(pathlib.Path(out_dir) / 'big.bin').write_bytes(b'0' * 2**20)\n")
    big = {**leaf_task(), "notebook": "notebooks/big.ipynb", "products": ["big.bin"], "claims": []}
    return make_pipeline({"big": big}, output_root=str(root))


def test_a_full_disk_is_one_line_exit_2_and_no_staging(make_pipeline: MakePipeline, tmpfs: Any,
                                                       capfd: pytest.CaptureFixture[str]) -> None:
    root = tmpfs(512)
    path = _big_leaf(make_pipeline, root)
    code = main(["run", "--pipeline", str(path), "--profile", "smoke", "--workers", "1", "--no-progress"])
    out = capfd.readouterr()
    assert code == 2
    assert "Traceback" not in out.out + out.err
    assert "big ... FAILED" in out.out and "No space left on device" in out.out
    assert not list((root / "smoke" / ".staging").glob("*/*"))


def test_a_read_only_output_root_is_one_line_and_exit_2(make_pipeline: MakePipeline, tmpfs: Any,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    root = tmpfs(256)
    path = make_pipeline(output_root=str(root))
    subprocess.run(["mount", "-o", "remount,ro", str(root)], check=True)
    assert main(["run", "--pipeline", str(path), "--profile", "smoke", "--workers", "1", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Read-only file system" in err and "Traceback" not in err


_INTRUDER = """
import sys
from distributed import Client
try:
    with Client(sys.argv[1], timeout="2s") as c:
        print("connected:", c.scheduler_info()["address"])  # from here it could run code on the workers
except Exception as exc:
    print("refused:", type(exc).__name__)
"""


def test_the_local_cluster_refuses_other_local_clients() -> None:
    import sys

    from fnnbook.executor import local_cluster

    with local_cluster(0) as client:  # the scheduler alone: what a client talks to
        address = client.scheduler.address
        assert address.startswith("tls://")
        port = address.rsplit(":", 1)[1]
        # tls:// without the run's certificate is refused the same way (the handshake needs it)
        done = subprocess.run([sys.executable, "-c", _INTRUDER, f"tcp://127.0.0.1:{port}"], capture_output=True,
                              text=True, timeout=60, check=False)
        assert "refused:" in done.stdout and "connected:" not in done.stdout, (done.stdout, done.stderr)
        assert client.scheduler_info()["address"] == address  # the run's own client still talks to it


def _members_task() -> dict[str, Any]:
    return {**leaf_task(), "products": ["results.json", "value.txt", "member_seed*.txt"]}


def _with_members(input_path: str, output_path: str, parameters: dict[str, Any], **kw: Any) -> None:
    if "value" not in parameters:  # the child task: nothing to write
        shutil.copy(input_path, output_path)
        return
    _stand_in(input_path, output_path, parameters, **kw)
    for seed in (0, 1):
        (Path(parameters["out_dir"]) / f"member_seed{seed}.txt").write_text(f"seed {seed}")


@pytest.mark.parametrize("fault", ["truncate", "swap", "delete"])
def test_a_damaged_member_reruns_its_task_and_the_downstream(fault: str, make_pipeline: MakePipeline,
                                                             monkeypatch: pytest.MonkeyPatch) -> None:
    """Every file of a glob product is hashed in the run record: a damaged member makes the task stale."""
    monkeypatch.setattr("fnnbook.execution.papermill.execute_notebook", _with_members)
    spec = load_spec(make_pipeline({"leaf": _members_task(), "child": {**child_task(), "products": []}}))
    assert _quiet(spec).ok
    out = spec.output_dir("smoke", "leaf")
    {"truncate": lambda: (out / "member_seed1.txt").write_text(""),
     "swap": lambda: shutil.copy(out / "member_seed0.txt", out / "member_seed1.txt"),
     "delete": lambda: (out / "member_seed1.txt").unlink()}[fault]()
    report = _quiet(spec)
    assert [o.status for o in report.outcomes] == ["ok", "ok"]
    assert (out / "member_seed1.txt").read_text() == "seed 1"


def test_every_member_checkpoint_a_task_reads_is_a_product() -> None:
    spec = load_spec(Path(__file__).resolve().parents[2] / "pipeline.yaml")
    assert "residual_seed*.pt" in spec.tasks["quadrotor_learning"].products


def test_readers_of_an_upstream_go_side_by_side(make_pipeline: MakePipeline, monkeypatch: pytest.MonkeyPatch) -> None:
    """A run that only reads `leaf` (up to date) does not wait for another reader of `leaf`."""
    monkeypatch.setattr("fnnbook.execution.papermill.execute_notebook", _with_members)
    spec = load_spec(make_pipeline({"leaf": _members_task(), "child": {**child_task(), "products": []}}))
    assert _quiet(spec, ["leaf"]).ok
    lines: list[str] = []
    with holding(spec, "smoke", (), read=["leaf"]):  # e.g. the book, or a run of another dependant
        report = _quiet(spec, ["child"], echo=lines.append)
    assert report.ok and [o.status for o in report.outcomes] == ["skipped", "ok"]
    assert not any("waiting" in line for line in lines)

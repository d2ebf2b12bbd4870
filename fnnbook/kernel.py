"""Notebook kernels: their options (torch threads, quiet log, IPC sockets), ending them, and core counts."""

from __future__ import annotations

import asyncio
import contextlib
import os
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import psutil

__all__ = ["KERNEL", "TASK_THREADS", "cpu_count", "kernel_arguments", "kernel_config", "kill_kernels",
           "stop_kernels", "task_kernel", "task_threads"]

KERNEL = "python3"
#: torch intra-op threads in each notebook's kernel when run in-process with one core (importing fnnlib
#: no longer sets them); a run on K workers gives each task cores // K (see fnnbook.executor)
TASK_THREADS = 1
_END_MARKERS = ("\n--- ok after ", "\n--- FAILED")


#: Run once in each kernel before the first cell: torch gets its threads the moment the notebook imports it
#: (a meta-path hook), so a kernel whose notebook never imports torch does not pay ~2 s of CPU for it.
_TORCH_THREADS_HOOK = """
def _fnn_torch_threads(threads):
    import sys
    from importlib.machinery import PathFinder

    class SetTorchThreads:
        def find_spec(self, name, path=None, target=None):
            if name != "torch":
                return None
            sys.meta_path.remove(self)
            spec = PathFinder.find_spec(name, path)
            run = spec.loader.exec_module

            def exec_module(module):
                run(module)
                module.set_num_threads(threads)

            spec.loader.exec_module = exec_module
            return spec

    if "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(threads)
    else:
        sys.meta_path.insert(0, SetTorchThreads())


_fnn_torch_threads(%d)
del _fnn_torch_threads
"""


def kernel_arguments(threads: int) -> list[str]:
    """ipykernel options: torch's threads set when the notebook imports torch; the kernel's own log quiet.

    (The kernel's log goes to the terminal, not to the task's log: messages such as a reply that cannot be
    sent while Ctrl-C shuts it down. The notebook's output and errors still reach the task's log.)
    """
    return [f"--IPKernelApp.exec_lines={[_TORCH_THREADS_HOOK % int(threads)]!r}", "--IPKernelApp.log_level=CRITICAL"]



#: the tasks of this process whose kernel is starting, running or shutting down (:func:`task_kernel`)
_TASKS: set[object] = set()
_TASKS_LOCK = threading.Lock()


@contextlib.contextmanager
def task_kernel() -> Iterator[None]:
    """Count one task's kernel as this process's while the block starts, runs and ends it (:func:`stop_kernels`)."""
    token = object()
    with _TASKS_LOCK:
        _TASKS.add(token)
    try:
        yield
    finally:
        with _TASKS_LOCK:
            _TASKS.discard(token)


def kill_kernels() -> int:
    """End this process's notebook kernels (its ipykernel child processes); return how many."""
    kernels = _kill(_kernels())
    psutil.wait_procs(kernels, timeout=5)
    return len(kernels)


async def stop_kernels(patience: float = 30.0) -> int:
    """End this process's kernels, and every one that starts until the tasks running now have ended.

    Cancelling a run's tasks on a Dask worker (awaited there). A kernel still starting when the stop comes
    is no child process yet: it is killed as it appears, so no task's kernel outlives the task, whose
    worker may be killed next (an orphaned kernel would keep running, and hold the run's terminal).
    ``patience`` (seconds) bounds the wait for the tasks to end. Returns how many kernels were killed.
    """
    with _TASKS_LOCK:
        doomed = set(_TASKS)
    killed = len(_kill(_kernels()))
    deadline = time.monotonic() + patience
    while time.monotonic() < deadline:
        with _TASKS_LOCK:
            if not doomed & _TASKS:
                break
        await asyncio.sleep(0.05)
        killed += len(_kill(_kernels()))
    return killed


def _kernels() -> list[psutil.Process]:
    return [p for p in psutil.Process().children(recursive=True) if _is_kernel(p)]


def _kill(procs: list[psutil.Process]) -> list[psutil.Process]:
    for proc in procs:
        with contextlib.suppress(psutil.Error):
            proc.kill()
    return procs


def _is_kernel(proc: psutil.Process) -> bool:
    try:
        return "ipykernel" in " ".join(proc.cmdline())
    except psutil.Error:
        return False


def kernel_config(folder: str) -> Any:
    """Kernels talk over IPC sockets in ``folder`` (no TCP port opened, no 'without encryption' warning)."""
    from traitlets.config import Config

    return Config({"KernelManager": {"transport": "ipc", "ip": str(Path(folder) / "kernel")}})



def cpu_count() -> int:
    """Cores this process may use."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def task_threads(workers: int) -> int:
    """torch threads per task: cores // workers, at least 1."""
    return max(1, cpu_count() // workers)


"""Where a pipeline task's seconds go: its notebook run as a script under cProfile, its time split by package.

Runs each named task's notebook source (``notebooks/src/<NN>_<name>.py``) in this process with the parameters
the runner would inject for the profile, writing into a scratch folder (its upstream tasks' outputs must be in
the output root already, e.g. after ``make main``). Prints the task's wall time, the share of it spent in each
package (torch, torchdiffeq, numpy, fnnlib, ...: the time of the functions defined there, children excluded),
and the functions of this repository that take the most time with their children.

    .venv/bin/python benchmarks/profile_tasks.py spiral tuned_gains --profile paper --output-root outputs \\
        --data-dir DATA_DIR [--top 25]
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

from fnnbook.runner import check  # noqa: E402
from fnnbook.spec import load_spec  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def package_of(filename: str, func: str) -> str:
    """The package a function belongs to: site-packages' top folder, this repository's top folder; a compiled
    function (no file) by the library its name names (torch's operators, numpy's)."""
    if filename == "~":
        for lib in ("torch", "numpy", "scipy"):
            if lib in func:
                return f"{lib} (compiled)"
        return "python builtins"
    if filename.startswith("<frozen"):
        return "python (imports)"
    path = Path(filename)
    parts = path.parts
    if "site-packages" in parts:
        return parts[parts.index("site-packages") + 1].split(".")[0].removesuffix("-stubs")
    try:
        return path.resolve().relative_to(ROOT).parts[0]
    except ValueError:
        return "python" if filename.startswith("<") or "lib/python" in filename else path.name


def script(notebook: Path, params: dict) -> str:
    """The notebook source with the injected parameters as a cell right after its parameters cell."""
    source = notebook.read_text(encoding="utf-8")
    head, sep, rest = source.partition('# %% tags=["parameters"]')
    if not sep:
        raise SystemExit(f"{notebook}: no parameters cell")
    cell, nxt, tail = rest.partition("\n# %%")
    injected = "".join(f"\n{k} = {v!r}" for k, v in params.items())
    return head + sep + cell + "\n# %%" + injected + "\n" + nxt + tail


def profile_task(spec, profile: str, name: str, top: int) -> None:
    plan = check(spec, profile, [name])
    params = dict(plan.parameters[name])
    scratch = Path(tempfile.mkdtemp(prefix=f"profile-{name}-"))
    params["out_dir"] = str(scratch)
    notebook = ROOT / "notebooks" / "src" / (Path(spec.tasks[name].notebook).stem + ".py")
    code = compile(script(notebook, params), str(notebook), "exec")
    prof = cProfile.Profile()
    t0 = time.perf_counter()
    prof.runctx("exec(code, {'__name__': '__main__'})", {"code": code}, {})
    wall = time.perf_counter() - t0
    stats = pstats.Stats(prof)
    by_package: dict[str, float] = defaultdict(float)
    ours = []
    for (filename, line, func), (_, _, tottime, cumtime, _) in stats.stats.items():  # type: ignore[attr-defined]
        by_package[package_of(filename, func)] += tottime
        if filename.startswith(str(ROOT)) and not any(p in filename for p in ("benchmarks", ".venv")):
            ours.append((cumtime, f"{Path(filename).relative_to(ROOT)}:{line} {func}"))
    print(f"\n== {name} ({profile}): {wall:.1f} s wall")
    total = sum(by_package.values()) or 1.0
    for pkg, t in sorted(by_package.items(), key=lambda kv: -kv[1])[:12]:
        print(f"  {pkg:<28} {t:8.1f} s  {100 * t / total:5.1f} %")
    print(f"  -- the {top} functions of this repository with the most time, children included --")
    for cum, where in sorted(ours, reverse=True)[:top]:
        print(f"  {cum:8.1f} s  {where}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("tasks", nargs="+")
    ap.add_argument("--profile", default="paper")
    ap.add_argument("--output-root", default=str(ROOT / "outputs"))
    ap.add_argument("--data-dir", default=None)
    ap.add_argument("--top", type=int, default=25)
    args = ap.parse_args()
    spec = load_spec(ROOT / "pipeline.yaml").with_paths(output_root=args.output_root, data_dir=args.data_dir)
    for name in args.tasks:
        if name not in spec.tasks:
            raise SystemExit(f"unknown task {name!r}; the tasks: {sorted(spec.tasks)}")
    for name in args.tasks:
        profile_task(spec, args.profile, name, args.top)


if __name__ == "__main__":
    main()

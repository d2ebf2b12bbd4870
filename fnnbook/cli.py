"""Command line: ``fnn-pipeline {run,check,list,book,data}``.

Examples
--------
::

    fnn-pipeline list
    fnn-pipeline check --profile paper
    fnn-pipeline run --profile smoke spiral
    fnn-pipeline run --profile paper --force spiral
    fnn-pipeline run --profile paper --workers 1                       # one task after another, in-process
    fnn-pipeline run --profile paper --scheduler tcp://10.0.0.5:8786   # on a running Dask cluster
    fnn-pipeline book --profile paper
    fnn-pipeline data fetch                                            # the authors' published throws
    fnn-pipeline data fetch --optional                                 # the same; no network is a note, not an error
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from fnnbook.book import make_book
from fnnbook.data import BOTTLE_SOURCES, fetch_bottle, fetch_release, fetch_tanks
from fnnbook.executor import default_workers
from fnnbook.pipeline import run
from fnnbook.outcome import Status
from fnnbook.outcome import Action
from fnnbook.runner import check, decide, read_status
from fnnbook.spec import PipelineError, PipelineSpec, load_spec
from fnnlib.data.bottle import DataError

__all__ = ["main"]

PIPELINE_FILE = "pipeline.yaml"


def _find_pipeline(given: str | None) -> Path:
    if given is not None:
        return Path(given)
    here = Path.cwd().resolve()
    for folder in (here, *here.parents):
        if (folder / PIPELINE_FILE).is_file():
            return folder / PIPELINE_FILE
    raise PipelineError(f"no {PIPELINE_FILE} in {here} or its parents; pass --pipeline PATH")


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="fnn-pipeline",
        description="Run the reproduction's notebooks (pipeline.yaml) and build the book.")
    sub = parser.add_subparsers(dest="command", required=True)

    def common(p: argparse.ArgumentParser, *, profile: bool = True, data: bool = True) -> None:
        p.add_argument("--pipeline", metavar="PATH", help="pipeline file (default: ./pipeline.yaml, "
                       "searched upwards)")
        if profile:
            p.add_argument("--profile", required=True, help="parameter profile, e.g. paper or smoke")
        p.add_argument("--output-root", metavar="DIR", help="override output_root of pipeline.yaml")
        if data:
            p.add_argument("--data-dir", metavar="DIR", help="override data_dir of pipeline.yaml")

    p_run = sub.add_parser("run", help="execute tasks (and their stale upstream tasks)")
    common(p_run)
    p_run.add_argument("tasks", nargs="*", metavar="TASK", help="tasks to run (default: all)")
    p_run.add_argument("--force", action="store_true", help="rerun the named tasks even if up to date")
    p_run.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    where = p_run.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, metavar="K",
                       help="run on a local Dask cluster of K single-threaded worker processes (default: the "
                            "cores, capped by memory); 1 runs the tasks one after another in this process")
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="run on a running Dask cluster (tcp://host:port); its workers need this checkout "
                            "and venv at the same path and the same output root")
    p_run.add_argument("--threads", type=int, metavar="N",
                       help="torch threads per task (default: cores // workers, at least 1)")

    p_check = sub.add_parser("check", help="validate pipeline.yaml and every task's parameters")
    common(p_check)
    p_check.add_argument("tasks", nargs="*", metavar="TASK", help="tasks to check (default: all)")

    p_list = sub.add_parser("list", help="list tasks, their claims and status per profile")
    common(p_list, profile=False)

    p_book = sub.add_parser("book", help="assemble the executed notebooks and scoreboard, build the book")
    common(p_book)  # the data directory of the run: what decides whether the outputs shown are current
    p_book.add_argument("--book-dir", metavar="DIR", help="book folder (default: book/ beside pipeline.yaml)")

    p_data = sub.add_parser("data", help="get the data the real-data tasks read")
    data_sub = p_data.add_subparsers(dest="data_command", required=True)
    p_fetch = data_sub.add_parser("fetch", help="download the authors' published throws (Sec. 5.1) into the "
                                                "data directory and check their pinned SHA-256")
    common(p_fetch, profile=False)
    p_fetch.add_argument("--url", action="append", metavar="TEMPLATE",
                         help="a source: URL template with {name}; repeat it for more, tried in order (default: "
                              + "; then ".join(BOTTLE_SOURCES.values()) + ")")
    p_fetch.add_argument("--release", action="store_true",
                         help="also the authors' trained networks (what `make why` evaluates beside ours) into "
                              "DATA_DIR/release/, from the official release at its pinned commit")
    p_fetch.add_argument("--tanks", action="store_true",
                         help="also the cascaded tanks benchmark's data file into DATA_DIR/cascaded_tanks/, "
                              "extracted from its official archive (SHA-256 pinned)")
    p_fetch.add_argument("--optional", action="store_true",
                         help="when no source serves the files (no network), say so in one line and exit 0")
    return parser


def _spec(args: argparse.Namespace) -> PipelineSpec:
    spec = load_spec(_find_pipeline(args.pipeline))
    return spec.with_paths(output_root=args.output_root, data_dir=getattr(args, "data_dir", None))


def _states(spec: PipelineSpec, profile: str) -> dict[str, str]:
    """Each task's state in ``profile``: up to date, stale (with the input that changed), not run, data missing."""
    spec = spec.for_profile(profile)
    names = [n for n, t in spec.tasks.items() if profile in t.parameters]
    try:
        plan = check(spec, profile, names)
    except PipelineError:
        plan = None
    states: dict[str, str] = {}
    for name in names:
        try:
            one = plan if plan is not None else check(spec, profile, [name])
        except PipelineError:
            states[name] = "invalid (run check)"
            continue
        exists = spec.output_dir(profile, name).exists()
        if name in one.missing_data:  # e.g. another --data-dir than the run's
            states[name] = "data missing here" + (" (outputs of an earlier run kept)" if exists else "")
            continue
        decision = decide(spec, one)[name]
        if decision.action is Action.SKIP:
            states[name] = "up to date"
        elif decision.action is Action.NOT_RUN:
            states[name] = f"not run ({decision.reason})"
        else:
            states[name] = f"stale ({decision.reason})" if exists else "not run"
    return states


def _list(spec: PipelineSpec) -> None:
    states = {profile: _states(spec, profile) for profile in spec.profiles}
    for part in spec.parts:
        print(part.title)
        for name in (n for listed in part.tasks for n in spec.grids.get(listed, (listed,))):
            task = spec.tasks[name]
            status = [f"{profile}: {states[profile][name]}" if name in states[profile] else
                      f"{profile}: not in its profile_grid" for profile in spec.profiles
                      if name in states[profile] or profile in task.left_out]
            print(f"  {name:<16} {task.title}")
            print(f"  {'':<16} claims {' '.join(task.claims) or '-'}; upstream "
                  f"{' '.join(task.upstream) or '-'}; {'; '.join(status)}")


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``fnn-pipeline``; returns the exit status."""
    args = _parser().parse_args(argv)
    try:
        spec = _spec(args)
        if args.command == "list":
            _list(spec)
            return 0
        if args.command == "check":
            plan = check(spec, args.profile, args.tasks or None)
            print(f"ok: {len(plan.order)} task(s) valid in profile {args.profile!r}: "
                  f"{', '.join(plan.order)}")
            for task, why in plan.missing_data.items():
                print(f"note: {task} will not run: {why}")
            return 0
        if args.command == "run":
            workers = args.workers if args.workers is not None else default_workers()
            report = run(spec, args.profile, args.tasks or None, force=args.force,
                         progress_bar=not args.no_progress, workers=workers, scheduler=args.scheduler,
                         threads=args.threads, echo=lambda line: print(line, flush=True))
            return 2 if report.io_error else (0 if report.ok else 1)
        if args.command == "data":
            if spec.data_dir is None:
                raise PipelineError("the pipeline has no data_dir; pass --data-dir DIR")
            sources = {f"--url {i}": url for i, url in enumerate(args.url, 1)} if args.url else None
            try:
                fetch_bottle(spec.data_dir, sources=sources)
            except DataError as exc:
                if not args.optional:
                    raise
                print(f"note: going on without the bottle throws (the bottle task and claims O1-O2 will read "
                      f"'not run: data missing'): {exc}", flush=True)
            if args.tanks:
                try:
                    fetch_tanks(spec.data_dir)
                except DataError as exc:
                    if not args.optional:
                        raise
                    print(f"note: going on without the cascaded tanks data (its chapter and claims will read "
                          f"'not run: data missing'): {exc}", flush=True)
            if args.release:
                try:
                    fetch_release(spec.data_dir)
                except DataError as exc:
                    if not args.optional:
                        raise
                    print(f"note: going on without the authors' networks (the whys judge ours only): {exc}",
                          flush=True)
            return 0
        if args.command == "book":
            book_dir = Path(args.book_dir) if args.book_dir else spec.root / "book"
            start = time.perf_counter()
            html = make_book(spec, args.profile, book_dir, echo=lambda line: print(line, flush=True))
            not_run = {t: s["message"] for t, s in read_status(spec, args.profile).items()
                       if s.get("status") in (Status.FAILED, Status.NOT_RUN)}
            for task, why in not_run.items():
                print(f"note: {task} is shown as not run or from an older run ({why})")
            print(f"book of profile {args.profile} (output root {spec.output_root}) built in "
                  f"{time.perf_counter() - start:.1f} s: {html / 'index.html'}")
            return 0
    except (PipelineError, DataError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # the file system's (read-only, full, no permission): one line, not a traceback
        where = f": {exc.filename}" if exc.filename else ""
        print(f"error: {exc.strerror or exc}{where}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    raise AssertionError(f"unhandled command {args.command!r}")  # argparse restricts the choices


if __name__ == "__main__":
    sys.exit(main())

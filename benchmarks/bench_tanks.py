"""The cascaded tanks chapter's task time, and where its seconds go.

Runs the chapter's measurements (``fnnbook.tanks_eval.run_seeds``) with the notebook's paper parameters on the
benchmark's records (or the synthetic twin without them) and prints the seconds of each stage: training
through the observer (the seeds as one stacked ensemble), the no-feedback baselines, the validation
(free runs, every horizon's cascade, the hand grid) and the Kalman filters. The whole task, notebook and
kernel included, is what the pipeline reports::

    .venv/bin/python benchmarks/bench_tanks.py [--data-dir /work/shared/data]
    .venv/bin/fnn-pipeline run --profile paper --output-root /tmp/tanks --data-dir DATA --workers 1 --force cascaded_tanks
"""

from __future__ import annotations

import argparse
import json
import time
import warnings
from pathlib import Path

import fnnlib as F
from fnnbook import tanks_eval as TE
from fnnlib.data.tanks import TANKS_FILE

SOURCE = Path(__file__).resolve().parents[1] / "notebooks" / "src" / "19_cascaded_tanks.py"


def paper_parameters() -> dict:
    """The notebook's parameters cell, as the paper profile runs it (its ``paper`` profile sets none)."""
    cell = SOURCE.read_text().split('# %% tags=["parameters"]')[1].split("# %%")[0]
    values: dict = {}
    exec(cell, values)  # plain values only (the notebooks' rule)
    return {k: v for k, v in values.items() if not k.startswith("__")}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data-dir", default="data")
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args()
    F.set_num_threads(args.threads)
    warnings.simplefilter("ignore", F.GainWarning)
    p = paper_parameters()
    real = (Path(args.data_dir) / "cascaded_tanks" / TANKS_FILE).is_file()
    rec = F.tanks_records("real" if real else "synthetic", data_dir=args.data_dir, n_samples=p["synthetic_samples"],
                          seed=p["seed"], noise_std=p["synthetic_noise"])
    t0 = time.perf_counter()
    runs, seconds, _ = TE.run_seeds(rec, p["seeds"], p)
    total = time.perf_counter() - t0
    print(json.dumps({"records": rec.source, "seeds": p["seeds"], "seconds": {k: round(v, 2) for k, v in seconds.items()},
                      "total_s": round(total, 2),
                      "free_run_V": {s: round(r["free_run"]["observer_trained"], 4) for s, r in runs.items()}}, indent=1))


if __name__ == "__main__":
    main()

"""The cascaded tanks chapter's task time, and where its seconds go.

Runs the chapter's measurements (``fnnlib.tanks.evaluation.run_seeds``) with the notebook's paper parameters on the
benchmark's records (or the synthetic twin without them) and prints the seconds of each stage: training
through the observer (the seeds as one stacked ensemble), the no-feedback baselines, the validation
(free runs, every horizon's cascade, the hand grid) and the Kalman filters. The whole task, notebook and
kernel included, is what the pipeline reports::

    .venv/bin/python benchmarks/bench_tanks.py [--data-dir /work/shared/data]
    .venv/bin/fnn-pipeline run --profile paper --output-root /tmp/tanks --data-dir DATA --workers 1 --force cascaded_tanks

Measured on the 2-core machine (one torch thread, other sessions' jobs beside it, load 1-2), the pipeline's
task time of ``cascaded_tanks`` in the paper profile: 68.7 s with a Python loop over the seeds (stages: training
through the observer 27.4 s, the no-feedback baseline 4.9 s, validation and Kalman filters 29.8 s); 47.5 s with
the seeds as one stacked ensemble (16.6 s, 16.9 s, 1.5 s + 7.8 s), the baseline now three times the work (two
starts over segments four times longer, the better kept). The numbers of the chapter are the same to the last
digit (the stacked members are tested equal to the seeds alone).
"""

from __future__ import annotations

import argparse
import json
import time
import warnings
from pathlib import Path

from fnnlib.data.tanks import tanks_records
from fnnlib.feedback import GainWarning
from fnnlib.threads import set_num_threads
from fnnlib.tanks import evaluation as TE
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
    set_num_threads(args.threads)
    warnings.simplefilter("ignore", GainWarning)
    p = paper_parameters()
    real = (Path(args.data_dir) / "cascaded_tanks" / TANKS_FILE).is_file()
    rec = tanks_records("real" if real else "synthetic", data_dir=args.data_dir, n_samples=p["synthetic_samples"],
                          seed=p["seed"], noise_std=p["synthetic_noise"])
    t0 = time.perf_counter()
    runs, seconds, _ = TE.run_seeds(rec, p["seeds"], TE.TanksSettings.of(p))
    total = time.perf_counter() - t0
    print(json.dumps({"records": rec.source, "seeds": p["seeds"], "seconds": {k: round(v, 2) for k, v in seconds.items()},
                      "total_s": round(total, 2),
                      "free_run_V": {s: round(r["free_run"]["observer_trained"], 4) for s, r in runs.items()}}, indent=1))


if __name__ == "__main__":
    main()

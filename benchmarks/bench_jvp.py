"""The flatness maps' Jacobian-vector product: reverse mode twice (``fnnlib``'s ``jvp``) against ``torch.func.jvp``.

For each implementation, in a fresh interpreter: the CPU time of the first flight reference (what a notebook
kernel or a test process pays once: ``torch.func.jvp`` loads ``torch._dynamo`` on its first product), whether
``torch._dynamo`` got loaded, and the median wall time of ``flat_reference`` and of ``state_to_flat`` on the
paper's Lissajous command, ``--points`` samples 0.02 s apart (what each flight pays per reference). Both run in
the same invocation, so their ratio is measured on one machine state.

    .venv/bin/python benchmarks/bench_jvp.py [--points 300] [--repeats 50]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys

_CHILD = r"""
import json, statistics, sys, time, warnings
t0 = time.process_time()
import torch
import fnnlib.quadrotor.control.flatness as F
from fnnlib.quadrotor.system import TEST_TRUTH
from fnnlib.quadrotor.control.lissajous import lissajous
from fnnlib.quadrotor.presets import PAPER_LISSAJOUS
import numpy as np
torch.set_num_threads(1)
impl, points, repeats = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
if impl == "torch.func.jvp":
    def forward_mode(fn, primals, tangents):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DeprecationWarning)
            return torch.func.jvp(fn, primals, tangents)
    F.jvp = forward_mode
d = lissajous(0.02 * np.arange(points), **PAPER_LISSAJOUS)  # the paper's test curve, at the flight's Ts
Psi, s = (torch.from_numpy(np.concatenate(parts, -1)) for parts in ((d.p, d.v, d.a, d.j), (d.s,)))
imported = time.process_time()
x, u = F.flat_reference(Psi, s, params=TEST_TRUTH)
first = time.process_time() - imported

def median(fn):
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)

print(json.dumps({"imports_s": imported - t0, "first_reference_s": first,
                  "dynamo_loaded": "torch._dynamo" in sys.modules,
                  "flat_reference_ms": 1e3 * median(lambda: F.flat_reference(Psi, s, params=TEST_TRUTH)),
                  "state_to_flat_ms": 1e3 * median(lambda: F.state_to_flat(x, u, params=TEST_TRUTH))}))
"""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--points", type=int, default=300, help="samples of the command (a 6 s flight at 0.02 s)")
    parser.add_argument("--repeats", type=int, default=50)
    args = parser.parse_args()
    rows = {}
    for impl in ("fnnlib jvp (reverse twice)", "torch.func.jvp"):
        done = subprocess.run([sys.executable, "-c", _CHILD, impl, str(args.points), str(args.repeats)],
                              capture_output=True, text=True, check=True)
        rows[impl] = json.loads(done.stdout.strip().splitlines()[-1])
    print(f"{'implementation':<28} {'first ref. CPU s':>16} {'dynamo':>7} {'flat_reference ms':>18} "
          f"{'state_to_flat ms':>17}")
    for impl, r in rows.items():
        print(f"{impl:<28} {r['first_reference_s']:>16.3f} {str(r['dynamo_loaded']):>7} "
              f"{r['flat_reference_ms']:>18.2f} {r['state_to_flat_ms']:>17.2f}")
    ours, theirs = rows["fnnlib jvp (reverse twice)"], rows["torch.func.jvp"]
    print(f"first reference: {theirs['first_reference_s'] - ours['first_reference_s']:+.3f} s CPU saved per process; "
          f"per call: flat_reference x{ours['flat_reference_ms'] / theirs['flat_reference_ms']:.2f}, "
          f"state_to_flat x{ours['state_to_flat_ms'] / theirs['state_to_flat_ms']:.2f} (ours / torch.func)")


if __name__ == "__main__":
    main()

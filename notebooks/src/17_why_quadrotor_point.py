# %% [markdown]
# # Why Q3-Q5 stand where they stand: one thrust bound (Sec. 5.2.2, App. A.5.4, A.9; Eqs. (27)-(30))
#
# One point of the why grid of the flight test: the MPC of Eq. (28) with the thrust box $[0, u_{max}]$ at this
# task's `u_max`, flown under both cost variants (Eq. (28) as written, R = I; and as the authors' release flies
# it), with the two adaptive gains the paper does not state swept: AdapNN's (App. A.5.4: "adjusted for optimal
# performance") over `Gamma_adapnn_grid` and AdapFNN's $\Gamma$ of Eq. (30) over `Gamma_grid`. Every other
# setting, the five trained networks and MLPs and the drawn disturbances are those of the paper-profile flight
# test (`quadrotor_mpc`), read from its run record, so at its bound the flights are its own.
#
# Where `data_dir` holds the authors' release and `u_max` is one of `authors_u_max`, their five residual
# networks (and their two MLPs) fly the same units too. This task only flies and records; the aggregate
# `why_quadrotor` applies the claims' rules.

# %% tags=["parameters"]
profile = "why"
out_dir = "outputs/manual/why_quadrotor_point"
upstream_dirs = {"quadrotor_learning": "outputs/paper/quadrotor_learning", "quadrotor_mpc": "outputs/paper/quadrotor_mpc"}
data_dir = None
# the settings and their paper values, from fnnbook.tasks.why_quadrotor_point (written by `make notebooks`)
u_max = 6.0
Gamma_grid = [2.0, 8.0, 32.0]
Gamma_adapnn_grid = [0.16, 0.64, 2.56]
authors_u_max = [6.0]

# %%
from fnnbook.tasks.why_quadrotor_point import WhyQuadrotorPointSettings
settings = WhyQuadrotorPointSettings.from_namespace(globals())  # checked as `fnn-pipeline check` checks them

# %% tags=["hide-input"]
import json
import time
from functools import partial
from pathlib import Path

import numpy as np

from fnnbook.results import RESULTS_FILENAME, read_results
from fnnlib.training import load_seed_checkpoints
import fnnlib.quadrotor.mpc as M
from fnnbook.params import upstream_parameters
from fnnlib.quadrotor.evaluation import at_gains, fly_record
from fnnlib import release
from fnnlib.quadrotor.presets import PAPER_LISSAJOUS, PAPER_THRUST_MAX
from fnnlib.quadrotor.system import NOMINAL, Quadrotor

t_start = time.perf_counter()

# %% [markdown]
# ## The flight test's settings, as it flew them
# Read from the run record of `quadrotor_mpc`: its settings, its metrics, its costs and, per cost, the gain of
# AdapNN it chose on validation flights.

# %% tags=["hide-input"]
out = Path(out_dir)
out.mkdir(parents=True, exist_ok=True)
up = {k: Path(v) for k, v in upstream_dirs.items()}
ran = upstream_parameters(up["quadrotor_mpc"])  # the flight test's settings, as it flew them
q_mpc = read_results(up["quadrotor_mpc"] / RESULTS_FILENAME).metrics
costs = list(ran["costs"])
chosen = {c: q_mpc["adapnn_gamma"][c]["chosen"] for c in costs}  # AdapNN's gain chosen on validation there

# %% [markdown]
# ## The paper profile's units, rebuilt
# Unit $k$: trained residual network $k$, MLP $k$ and drawn disturbance $k$ (`flight_tests`, the
# builder the flight test uses). The profile's own gains must be grid values, so that the grid passes through
# the profile's point.

# %% tags=["hide-input", "nbval-check-output"]
members, mlps = ([(seed, net.double()) for seed, net, _ in
                  load_seed_checkpoints(up["quadrotor_learning"], stem, expected_kind="AeroResidual",
                                          run=upstream_parameters(up["quadrotor_learning"]))]
                 for stem in ("residual", "mlp"))
setup = M.flight_tests(M.FlightSettings.of(ran))
if [list(f) for f in setup.forces] != q_mpc["disturbances"]:
    raise ValueError(f"the rebuilt disturbances {setup.forces} are not those quadrotor_mpc flew {q_mpc['disturbances']}")
if ran["Gamma"] not in Gamma_grid or not set(chosen.values()) <= set(Gamma_adapnn_grid):
    raise ValueError(f"the grids must hold the profile's gains: Gamma = {ran['Gamma']} in Gamma_grid = {Gamma_grid}, "
                     f"AdapNN's {chosen} in Gamma_adapnn_grid = {Gamma_adapnn_grid}")
kw = dict(plant=Quadrotor(NOMINAL), L=ran["L"], beta=ran["beta"], N=ran["N"], Gamma=ran["Gamma"], Ts=ran["Ts"])
need = M.thrust_needed(setup.vehicle, PAPER_LISSAJOUS, steps=ran["steps"], Ts=ran["Ts"])
compile_s = M.warm_up(*[n for _, n in members + mlps]) if ran["backend"] == "numba" else 0.0
print(f"u_max = {u_max:g} N; the test vehicle needs {need['hover']:.2f} N per motor to hover and {need['peak']:.2f} N "
      f"at the reference's peak: {'enough' if u_max >= need['peak'] else 'NOT enough'} thrust")


# %% [markdown]
# ## The flights
# The five models without an adaptive gain fly once per unit and cost; AdapNN once per value of
# `Gamma_adapnn_grid`, AdapFNN once per value of `Gamma_grid` (the other models do not depend on them).
# AdapFNN's flights keep the share of each flight's steps inside Theorem 2's bound (`fly_record`).

# %% tags=["hide-input"]
mpcs = {c: M.MPCSettings.of(ran).build(cost=c, u_max=u_max) for c in costs}
fly = partial(fly_record, tests=setup.unit_tests, model_settings=kw, adapnn_grid=Gamma_adapnn_grid,
              Gamma_grid=Gamma_grid, transient=int(round(ran["transient_s"] / ran["Ts"])))  # one set, one cost
ours = {c: fly(members, mlps, mpc=mpcs[c], adapnn_gamma=chosen[c], names=["Nomi", "Neural", "MLP", "FB", "FNN"])
        for c in costs}
units = [f"network {s}, MLP {m}, disturbance {k + 1}" for k, ((s, _), (m, _)) in enumerate(zip(members, mlps))]
if u_max == ran["u_max_judged"]:  # the profile's point: its flights again, to the last digit of the record
    for c in costs:
        same = {n: at_gains(ours[c], n, chosen[c], ran["Gamma"])["rmse"] for n in ours[c]}
        for n, v in same.items():
            if not np.allclose(v, q_mpc["paired_mean_axis_rmse_m"][c][n], rtol=1e-9, atol=0):
                raise ValueError(f"{c}, {n}: RMSE {v} here, {q_mpc['paired_mean_axis_rmse_m'][c][n]} in quadrotor_mpc")
    print("at the profile's bound the flights are quadrotor_mpc's own (RMSE equal to 1e-9 relative)")

# %% [markdown]
# ## The authors' networks on the same units
# Unit $k$ pairs the release's residual run $k$ (`load_release_residual`, five random initialisations) with
# disturbance $k$; the release has two MLPs, so unit $k$ flies MLP $k \bmod 2$ (the MLP comparison then rests on
# two MLPs). Nomi and FB carry no network: their flights are ours above, flight for flight.

# %% tags=["hide-input"]
their = None
if not release.release_present(data_dir, "quadrotor/"):  # every file there, its SHA-256 the published one
    print(f"authors' networks: not evaluated, ours judged only (the release's quadrotor networks are not all "
          f"in data_dir = {data_dir!r} with their published SHA-256)")
elif u_max not in authors_u_max:
    print(f"authors' networks: not flown at {u_max:g} N (authors_u_max = {authors_u_max})")
else:  # the release's first S runs (all five for the paper profile's five units), MLP k mod 2 for unit k
    their = release.load_release_quadrotor_networks(data_dir, len(setup.unit_tests))


# %% [markdown]
# Their residual networks fly in place of ours as Neural, MLP and FNN (and as AdapNN and AdapFNN, over the
# gains of both grids), on the same units, costs and MPCs.

# %% tags=["hide-input"]
authors = None
if their is not None:
    theirs, their_mlps = their
    compile_s += M.warm_up(*[n for _, n in theirs + their_mlps]) if ran["backend"] == "numba" else 0.0
    authors = {c: {"Nomi": ours[c]["Nomi"], "FB": ours[c]["FB"]}
               | fly(theirs, their_mlps, mpc=mpcs[c], adapnn_gamma=chosen[c], names=["Neural", "MLP", "FNN"])
               for c in costs}
    authors["units"] = [f"release run {r}, MLP {m}, disturbance {k + 1}"
                        for k, ((r, _), (m, _)) in enumerate(zip(theirs, their_mlps))]
    print(f"authors' networks flown: {len(theirs)} residual runs, MLPs {sorted(set(m for m, _ in their_mlps))}")

# %%
seconds = time.perf_counter() - t_start
point = {"u_max": u_max, "costs": costs, "units": units, "ours": ours, "authors": authors, "need": need,
         "Gamma_grid": Gamma_grid, "Gamma_adapnn_grid": Gamma_adapnn_grid, "profile_Gamma": ran["Gamma"],
         "profile_Gamma_adapnn": chosen, "u_max_judged": ran["u_max_judged"], "paper_u_max": PAPER_THRUST_MAX,
         "seconds": seconds, "compile_s": compile_s}
(out / "point.json").write_text(json.dumps(point, indent=1))
print(f"{u_max:g} N: flown in {seconds:.1f} s (compile {compile_s:.1f} s)")

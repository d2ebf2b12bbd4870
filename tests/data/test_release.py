"""The loaders of the authors' released networks: layouts on fakes saved in the release's form, the refusing
unpickler, clear errors; the real files (and the evidence that the mapping is right) when FNN_DATA_DIR names
the data directory."""

from __future__ import annotations

import builtins
import hashlib
import os
import pickle
import sys
import zipfile
from collections import OrderedDict
from pathlib import Path

import numpy as np
import pytest
import torch
from torch import nn

from fnnlib import release
from fnnlib.release import (
    ReleaseError,
    UnsafePickleError,
    load_release_bottle_ode,
    load_release_losses,
    load_release_mlp,
    load_release_residual,
    load_release_spiral_feedback,
    load_release_spiral_ode,
    read_pickled_module,
)

SPIRAL_ODE = "Neural_ODE_ite1000_loss0.008033.pt"
SPIRAL_FB = "FeedbackNN_ite1074_loss0.483191.pt"
BOTTLE = "Neural_ODE_ite1000_loss0.047562.pt"
RUN = release.RESIDUAL_RUNS[0]
MLP_RUN = release.MLP_RUNS[0]
KEYS = {
    "ode": f"spiral_curve/trained_model/{SPIRAL_ODE}",
    "fb": f"spiral_curve/trained_model/{SPIRAL_FB}",
    "bottle": f"irregular_object/trained_model/{BOTTLE}",
    "residual": f"quadrotor/learning_NODE/learned_models/{RUN}/model_param_epoch50.npy",
    "mlp": f"quadrotor/learning_MLP/learned_models/{MLP_RUN}/model_param_epoch500.pth",
    "losses": f"quadrotor/learning_NODE/log/{RUN}/loss_record.npy",
}


# ---------------------------------------------------------------- stand-ins of the release's classes
class ODEFunc(nn.Module):
    """Same module/class name and layout as the release's ``__main__.ODEFunc`` (an MLP in ``self.net``)."""

    def __init__(self, sizes: tuple[int, ...], act: type[nn.Module] = nn.ReLU) -> None:
        super().__init__()
        layers: list[nn.Module] = []
        for i, (a, b) in enumerate(zip(sizes[:-1], sizes[1:])):
            layers += [nn.Linear(a, b)] + ([act()] if i < len(sizes) - 2 else [])
        self.net = nn.Sequential(*layers)

    def forward(self, t, y):
        return self.net(y)


class BackFunc(ODEFunc):
    """The release's ``__main__.BackFunc`` (the neural feedback), same layout."""


class DragMLP(nn.Module):
    """The release's ``Drag_MLP``: 6-36-36-36-3, tanh, no bias on the output layer (saved as a state dict)."""

    def __init__(self) -> None:
        super().__init__()
        self.input_layer, self.hidden_layer1, self.hidden_layer2 = nn.Linear(6, 36), nn.Linear(36, 36), nn.Linear(36, 36)
        self.output_layer = nn.Linear(36, 3, bias=False)

    def forward(self, x):
        for layer in (self.input_layer, self.hidden_layer1, self.hidden_layer2):
            x = torch.tanh(layer(x))
        return self.output_layer(x)


for _cls in (ODEFunc, BackFunc):
    _cls.__module__, _cls.__qualname__ = "__main__", _cls.__name__


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _place(root: Path, key: str) -> Path:
    """``root/release/key``, its folders made."""
    path = root / "release" / key
    path.parent.mkdir(parents=True, exist_ok=True)
    return path


def _pin(monkeypatch: pytest.MonkeyPatch, root: Path, key: str) -> None:
    """Pin the digest of the fake now at ``root/release/key`` (the loaders check every file against the table)."""
    table = dict(release.RELEASE_FILES)
    table[key] = _digest(root / "release" / key)
    monkeypatch.setattr(release, "RELEASE_FILES", table)


def _save_module(monkeypatch: pytest.MonkeyPatch, root: Path, key: str, module: nn.Module) -> Path:
    """torch.save the whole module, pickled by reference as ``__main__.<class>`` like the release's files."""
    monkeypatch.setattr(sys.modules["__main__"], type(module).__name__, type(module), raising=False)
    path = _place(root, key)
    torch.save(module, path)
    _pin(monkeypatch, root, key)
    return path


def _seeded(module: nn.Module, seed: int) -> nn.Module:
    torch.manual_seed(seed)
    with torch.no_grad():
        for p in module.parameters():
            p.normal_(0.0, 0.5)
    return module


# ---------------------------------------------------------------- spiral and bottle (whole pickled modules)
@pytest.mark.parametrize("act, name", [(nn.ReLU, "relu"), (nn.Tanh, "tanh")])
def test_spiral_ode_fake_loads_with_its_widths_and_activation(tmp_path, monkeypatch, act, name) -> None:
    fake = _seeded(ODEFunc((2, 7, 2), act), 0)
    _save_module(monkeypatch, tmp_path, KEYS["ode"], fake)
    f = load_release_spiral_ode(tmp_path, SPIRAL_ODE)
    assert f.config == {"n_state": 2, "hidden": [7], "activation": name, "n_input": 0}
    x = torch.randn(5, 2)
    assert torch.equal(f(0.0, x), fake(0.0, x))  # autonomous: the release ignores t too


def test_spiral_feedback_fake_loads(tmp_path, monkeypatch) -> None:
    fake = _seeded(BackFunc((2, 5, 5, 2)), 1)
    _save_module(monkeypatch, tmp_path, KEYS["fb"], fake)
    h = load_release_spiral_feedback(tmp_path, SPIRAL_FB)
    e = torch.randn(4, 2)
    assert h.config["hidden"] == [5, 5] and torch.equal(h(e), fake(0.0, e))


def test_mirror_reflects_the_spiral_networks_exactly(tmp_path, monkeypatch) -> None:
    fake = _seeded(BackFunc((2, 6, 6, 2)), 2)
    _save_module(monkeypatch, tmp_path, KEYS["fb"], fake)
    h = load_release_spiral_feedback(tmp_path, SPIRAL_FB, mirror=True)
    S = torch.tensor([1.0, -1.0])
    e = torch.randn(8, 2)
    assert torch.allclose(h(e), S * fake(0.0, S * e), rtol=0, atol=1e-6)


def test_bottle_fake_loads_on_the_six_state(tmp_path, monkeypatch) -> None:
    fake = _seeded(ODEFunc((6, 8, 8, 8, 6)), 3)
    _save_module(monkeypatch, tmp_path, KEYS["bottle"], fake)
    f = load_release_bottle_ode(tmp_path, BOTTLE)
    x = torch.randn(3, 6)
    assert f.config["hidden"] == [8, 8, 8] and torch.equal(f(0.0, x), fake(0.0, x))


def test_a_network_of_another_kind_or_size_is_refused(tmp_path, monkeypatch) -> None:
    _save_module(monkeypatch, tmp_path, KEYS["fb"], _seeded(ODEFunc((2, 4, 2)), 0))  # an ODEFunc as a feedback
    with pytest.raises(ReleaseError, match="expected a pickled __main__.BackFunc"):
        load_release_spiral_feedback(tmp_path, SPIRAL_FB)
    _save_module(monkeypatch, tmp_path, KEYS["bottle"], _seeded(ODEFunc((2, 4, 2)), 0))  # a spiral-sized net
    with pytest.raises(ReleaseError, match="do not fit NeuralODE"):
        load_release_bottle_ode(tmp_path, BOTTLE)


# ---------------------------------------------------------------- quadrotor (parameter arrays)
def _release_layers(seed: int) -> list[tuple[np.ndarray, np.ndarray | None]]:
    gen = np.random.default_rng(seed)
    return [(gen.normal(0, 0.3, (o, i)), gen.normal(0, 0.3, o) if b else None) for i, o, b in
            ((6, 36, True), (36, 36, True), (36, 36, True), (36, 3, False))]


def _release_forward(layers, v_theta: np.ndarray) -> np.ndarray:
    """``Quadrotor_NODE.NN_model`` on rows of (v, Theta): tanh after each hidden layer, no last bias."""
    h = v_theta
    for W, b in layers[:-1]:
        h = np.tanh(h @ W.T + b)
    return h @ layers[-1][0].T


def test_residual_column_is_unpacked_column_major_and_negated(tmp_path, monkeypatch) -> None:
    layers = _release_layers(0)
    # the release's column: per layer vec(W) column-major (CasADi), then b
    column = np.concatenate([np.concatenate([W.T.ravel(), b if b is not None else []]) for W, b in layers])[:, None]
    assert column.shape == (3024, 1)
    np.save(_place(tmp_path, KEYS["residual"]), column)
    _pin(monkeypatch, tmp_path, KEYS["residual"])
    res = load_release_residual(tmp_path, RUN)
    x = torch.randn(10, 12, dtype=torch.float64)
    want = -_release_forward(layers, x[:, 3:9].numpy())  # v' = a_nom - NN in the release; ours adds
    np.testing.assert_allclose(res(x).detach().numpy(), want, rtol=1e-12, atol=1e-12)
    assert res.config == {"hidden": [36, 36, 36], "activation": "tanh"} and not res.last.bias.any()


def test_mlp_state_dict_loads_negated(tmp_path, monkeypatch) -> None:
    fake = _seeded(DragMLP(), 4)
    torch.save(fake.state_dict(), _place(tmp_path, KEYS["mlp"]))
    _pin(monkeypatch, tmp_path, KEYS["mlp"])
    mlp = load_release_mlp(tmp_path, MLP_RUN)
    x = torch.randn(7, 12)
    assert torch.allclose(mlp(x), -fake(x[:, 3:9]), rtol=0, atol=1e-6)


def test_losses_are_one_per_epoch(tmp_path, monkeypatch) -> None:
    np.save(_place(tmp_path, KEYS["losses"]), np.linspace(13.0, 0.9, 50)[:, None])
    _pin(monkeypatch, tmp_path, KEYS["losses"])
    loss = load_release_losses(tmp_path, RUN)
    assert loss.shape == (50,) and loss[0] == 13.0


def test_wrong_arrays_are_refused(tmp_path, monkeypatch) -> None:
    np.save(_place(tmp_path, KEYS["residual"]), np.zeros((3000, 1)))
    _pin(monkeypatch, tmp_path, KEYS["residual"])
    with pytest.raises(ReleaseError, match=r"shape \(3024, 1\)"):
        load_release_residual(tmp_path, RUN)
    np.save(tmp_path / "release" / KEYS["residual"], np.zeros((3024, 1), dtype=np.float32))
    _pin(monkeypatch, tmp_path, KEYS["residual"])
    with pytest.raises(ReleaseError, match="float64"):
        load_release_residual(tmp_path, RUN)


# ---------------------------------------------------------------- files: missing, corrupt, unknown names
def test_a_missing_file_is_named_with_where_it_comes_from(tmp_path) -> None:
    with pytest.raises(ReleaseError, match=r"missing .*Neural_ODE_ite1000_loss0\.008033\.pt.*JIAjindou"):
        load_release_spiral_ode(tmp_path, SPIRAL_ODE)


def test_a_file_failing_its_checksum_is_refused_with_its_path(tmp_path, monkeypatch) -> None:
    _save_module(monkeypatch, tmp_path, KEYS["ode"], ODEFunc((2, 3, 2)))
    monkeypatch.setattr(release, "RELEASE_FILES", dict(release.RELEASE_FILES) | {KEYS["ode"]: "0" * 64})
    with pytest.raises(ReleaseError, match=r"Neural_ODE_ite1000_loss0\.008033\.pt fails its SHA-256 check"):
        load_release_spiral_ode(tmp_path, SPIRAL_ODE)


def test_unknown_names_are_refused_before_any_reading(tmp_path) -> None:
    with pytest.raises(ValueError, match="unknown spiral network"):
        load_release_spiral_ode(tmp_path, "FeedbackNN_demo.pt")  # a feedback, not a neural ODE
    with pytest.raises(ValueError, match="unknown residual run"):
        load_release_losses(tmp_path, MLP_RUN)


# ---------------------------------------------------------------- hostile pickles: refused, nothing runs
class _System:
    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return os.system, (f"touch {self.marker}",)


class _Eval(_System):
    def __reduce__(self):
        return builtins.eval, (f"open({str(self.marker)!r}, 'w').close()",)


def _torch_archive(path: Path, pkl: bytes) -> None:
    """A zip in torch's layout whose data.pkl is ``pkl``."""
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("archive/data.pkl", pkl)
        zf.writestr("archive/byteorder", "little")
        zf.writestr("archive/version", "3\n")


def _hostile(kind: str, path: Path, marker: Path) -> None:
    if kind == "os.system":  # pickled as GLOBAL 'posix system'
        torch.save({"net": _System(marker)}, path)
    elif kind == "builtins.eval":
        torch.save([_Eval(marker)], path)
    elif kind == "posix.system by hand":
        _torch_archive(path, b"cposix\nsystem\n(S'touch " + str(marker).encode() + b"'\ntR.")
    elif kind == "STACK_GLOBAL":
        _torch_archive(path, pickle.dumps(_System(marker), protocol=4))
    elif kind == "bare pickle":
        path.write_bytes(pickle.dumps(_System(marker), protocol=2))


@pytest.mark.parametrize("kind, message", [
    ("os.system", "names the global 'posix.system'"),
    ("builtins.eval", r"names the global '(__builtin__|builtins)\.eval'"),  # protocol 2 writes __builtin__
    ("posix.system by hand", "names the global 'posix.system'"),
    ("STACK_GLOBAL", "opcode STACK_GLOBAL"),
    ("bare pickle", "not a torch zip archive"),
])
def test_hostile_pickles_are_refused_and_nothing_runs(tmp_path, monkeypatch, kind, message) -> None:
    marker = tmp_path / "executed"
    path = _place(tmp_path, KEYS["ode"])
    _hostile(kind, path, marker)
    _pin(monkeypatch, tmp_path, KEYS["ode"])  # the checksum passes: only the unpickler stands in the way
    with pytest.raises(ReleaseError, match=message):
        load_release_spiral_ode(tmp_path, SPIRAL_ODE)
    with pytest.raises(ReleaseError, match=message):
        read_pickled_module(path)
    assert not marker.exists()


@pytest.mark.parametrize("kind, named", [("os.system", "posix.system"), ("builtins.eval", "eval")])
def test_the_weights_only_unpickler_alone_refuses_them_too(tmp_path, kind, named) -> None:
    marker = tmp_path / "executed"
    _hostile(kind, tmp_path / "evil.pt", marker)
    with pytest.raises(UnsafePickleError, match=f"names '{named}'"):
        release._torch_restricted_load(tmp_path / "evil.pt")  # the second lock, without the scan
    assert not marker.exists()


def test_an_object_array_is_refused_unread(tmp_path, monkeypatch) -> None:
    marker = tmp_path / "executed"
    path = _place(tmp_path, KEYS["residual"])
    with path.open("wb") as fh:
        np.save(fh, np.array([_System(marker)], dtype=object), allow_pickle=True)
    _pin(monkeypatch, tmp_path, KEYS["residual"])
    with pytest.raises(ReleaseError, match="pickled"):
        load_release_residual(tmp_path, RUN)
    assert not marker.exists()


def test_a_fake_in_the_release_layout_names_only_allowed_globals(tmp_path, monkeypatch) -> None:
    path = _save_module(monkeypatch, tmp_path, KEYS["ode"], ODEFunc((2, 3, 2)))
    pkl = release._scan_globals(path)  # passes: no global outside the allow-list
    assert b"posix" not in pkl and "posix system" not in release.ALLOWED_GLOBALS


# ---------------------------------------------------------------- the real files
DATA = os.environ.get("FNN_DATA_DIR")
real = pytest.mark.skipif(not DATA or not (Path(DATA) / "release").is_dir(),
                          reason="set FNN_DATA_DIR to a data directory holding release/ (the authors' networks)")


def _recorded_loss(name: str) -> float:
    return float(name.split("_loss")[1].split("_")[0].removesuffix(".pt"))


@real
def test_real_files_pass_their_checksums_and_load() -> None:
    kinds = [(load_release_spiral_ode, release.SPIRAL_ODE_NAMES), (load_release_spiral_feedback,
             release.SPIRAL_FEEDBACK_NAMES), (load_release_bottle_ode, release.BOTTLE_ODE_NAMES),
             (load_release_residual, release.RESIDUAL_RUNS), (load_release_mlp, release.MLP_RUNS),
             (load_release_losses, release.RESIDUAL_RUNS)]
    for load, names in kinds:
        for name in names:
            assert load(DATA, name) is not None
    losses = load_release_losses(DATA, RUN)
    assert losses.shape == (50,) and losses[-1] < losses[0] / 5  # Q1: the training converged


@real
@pytest.mark.parametrize("name", ["Neural_ODE_ite1000_loss0.008033.pt", "Neural_ODE_ite0400_loss0.301785.pt"])
def test_real_spiral_ode_reproduces_its_recorded_loss_and_the_nominal_rate(name) -> None:
    """The file name's loss is the release's mean |x_pred - x| over the nominal rollout (2000 points, 20 s):
    reproduced to 1 %. The rate fits the release's spiral (y @ A) within 3 % and Eq. (26) as printed not at
    all (the release's spiral turns the other way); mirrored, the network fits Eq. (26)'s nominal as well."""
    from torchdiffeq import odeint
    from fnnlib.systems import Spiral

    t, x0 = torch.linspace(0.0, 20.0, 2000), torch.tensor([[9.0, 0.0]])
    theirs, paper = release.release_spiral(2.0, 0.1, 0.0), Spiral(2.0, 0.1, 0.0)
    rel = {}
    for mirror, system in ((False, theirs), (False, paper), (True, paper)):
        f = load_release_spiral_ode(DATA, name, mirror=mirror)
        x = system.exact_solution(x0.double(), t.double()).float()[0]
        with torch.no_grad():
            rate = system(0.0, x.double()).float()
            rel[mirror, system] = float((f(0.0, x) - rate).norm(dim=-1).mean() / rate.norm(dim=-1).mean())
            if system is theirs:
                loss = float((odeint(f, x0, t, method="rk4")[:, 0] - x).abs().mean())
                assert loss == pytest.approx(_recorded_loss(name), rel=0.01)
    assert rel[False, theirs] < 0.03 and rel[True, paper] == pytest.approx(rel[False, theirs], rel=1e-3)
    assert rel[False, paper] > 1.0


@real
def test_real_spiral_feedback_reproduces_its_recorded_loss() -> None:
    """``FeedbackNN_ite1074`` was trained on ``Neural_ODE_ite0400`` over the release's 20 cases; its file name
    holds mean |label - h| over them (label: the rate the neural ODE misses), computed one optimiser step
    before the save: reproduced within 0.02. The opposite sign of h makes the observer diverge."""
    f = load_release_spiral_ode(DATA, "Neural_ODE_ite0400_loss0.301785.pt")
    h = load_release_spiral_feedback(DATA, SPIRAL_FB)
    T, Ts = 1000, 20.0 / 1000  # the release's grid (linspace(0, 20, 1000)) and its step 20 / 1000
    t = torch.linspace(0.0, 20.0, T).double()
    x0 = torch.tensor([9.0, 0.0], dtype=torch.float64)
    x = torch.stack([release.release_spiral(0.8 + 0.12 * i, 0.04 + 0.005 * i, -24.0 + 2.4 * i).exact_solution(x0, t)
                     for i in range(20)]).float()  # (20, T, 2)

    def loss(sign: float) -> float:
        with torch.no_grad():
            rate = f(0.0, x)
            label = (x[:, 1:] - x[:, :-1]) / Ts - rate[:, :-1]
            x_hat, out = x[:, 0].clone(), []
            for j in range(T - 1):  # the observer x_hat' = f(x) + h(x - x_hat), Euler at Ts
                c = sign * h(x[:, j] - x_hat)
                out.append(c)
                x_hat = x_hat + Ts * (rate[:, j] + c)
            return float((label - torch.stack(out, 1)).abs().mean())

    assert loss(1.0) == pytest.approx(_recorded_loss(SPIRAL_FB), abs=0.02)
    assert not loss(-1.0) < 10.0


@real
def test_real_bottle_ode_reproduces_its_loss_and_rolls_out_a_test_throw() -> None:
    """Training throws: mean |x_pred - x| over the 21 full rollouts, recorded one Adam step before the save:
    within 5 %. Test throws: the 0.5 s open-loop position error from each throw's first sample is a few cm,
    and the learned p' is the measured v (the state order is [p, v])."""
    from torchdiffeq import odeint
    from fnnlib.data import load_bottle

    train, test = load_bottle(DATA)
    f = load_release_bottle_ode(DATA, BOTTLE)
    with torch.no_grad():
        x = train.state.float()
        pred = odeint(f, x[:, 0], torch.linspace(0.0, 1.058, 1058), method="dopri5").transpose(0, 1)
        assert float((pred - x).abs().mean()) == pytest.approx(_recorded_loss(BOTTLE), rel=0.05)
        xt = test.state.float()
        p_half = odeint(f, xt[:, 0], test.t[:501].float(), method="rk4")[-1, :, :3]
        err = (p_half - xt[:, 500, :3]).norm(dim=-1)
        rate = f(0.0, xt)
    assert float(err.mean()) < 0.15 and float(err.max()) < 0.3
    assert float((rate[..., :3] - xt[..., 3:]).norm(dim=-1).mean()) < 0.05 * float(xt[..., 3:].norm(dim=-1).mean())


@real
def test_real_residual_and_mlp_predict_the_drag_on_a_dfbc_flight() -> None:
    """One DFBC flight on the release's training vehicle (drag diag(0.7, 0.7, 0.2)): the residuals predict the
    drag acceleration -R D R^T v with an RMS error under 50 % of its RMS (trained end to end through the
    closed loop: 16-38 % per flight, the z drag least), the single-step MLPs under 10 % (about 4 %); the
    unnegated networks are off by about 200 %."""
    from fnnlib.quadrotor.control.dfbc import DFBC
    from fnnlib.data.quadrotor import make_flights
    from fnnlib.quadrotor.presets import PAPER_DFBC_GAINS, PAPER_FLIGHT_DATA
    from fnnlib.quadrotor.system import NOMINAL, TRAINING_TRUTH, Quadrotor

    flight = make_flights(1, 150, Ts=0.02, seed=3, truth=TRAINING_TRUTH, controller=DFBC(NOMINAL, **PAPER_DFBC_GAINS),
                          n_waypoints=3, box=PAPER_FLIGHT_DATA["box"], max_speed=10.0, substeps=4)
    x = flight.x[0, :, :12]
    drag = Quadrotor(TRAINING_TRUTH).drag_acceleration(x)

    def rel(net, sign=1.0) -> float:
        with torch.no_grad():
            a = sign * net(x.to(next(net.parameters()).dtype)).double()
        return float((a - drag).pow(2).sum(-1).mean().sqrt() / drag.pow(2).sum(-1).mean().sqrt())

    residuals = [load_release_residual(DATA, run) for run in release.RESIDUAL_RUNS]
    mlps = [load_release_mlp(DATA, run) for run in release.MLP_RUNS]
    assert max(rel(r) for r in residuals) < 0.5 and max(rel(m) for m in mlps) < 0.10
    assert min(rel(r, -1.0) for r in residuals + mlps) > 1.5


def test_the_loaders_are_on_fnnlib_flat_face() -> None:
    import fnnlib

    assert fnnlib.release.load_release_spiral_ode is load_release_spiral_ode and fnnlib.release.UnsafePickleError is UnsafePickleError


def test_a_feedback_loss_curve_is_cut_at_its_iteration_and_checked(tmp_path: Path, monkeypatch) -> None:
    key = "spiral_curve/trained_model/iteration_ite5.txt"
    path = _place(tmp_path, key)
    path.write_text("[3.0 2.0 1.0 0.7 0.45 0.0\n 0.0 0.0]")
    _pin(monkeypatch, tmp_path, key)
    monkeypatch.setattr(release, "SPIRAL_LOSS_NAMES", ("iteration_ite5.txt",))
    assert release.load_release_feedback_losses(tmp_path, "iteration_ite5.txt").tolist() == [3.0, 2.0, 1.0, 0.7, 0.45]
    path.write_text("[3.0 2.0 1.0 0.7 0.45 0.3 0.0 0.0]")  # a loss after the stop: not the layout
    _pin(monkeypatch, tmp_path, key)
    with pytest.raises(release.ReleaseError, match="positive losses then zeros"):
        release.load_release_feedback_losses(tmp_path, "iteration_ite5.txt")
    with pytest.raises(ValueError, match="unknown loss curve"):
        release.load_release_feedback_losses(tmp_path, "iteration_ite6.txt")


def test_present_loss_names_are_the_curves_there_with_their_published_digest(tmp_path: Path) -> None:
    assert release.present_loss_names(tmp_path) == ()
    key = "spiral_curve/iteration_ite135.txt"
    _place(tmp_path, key).write_text("[1.0 0.4 0.0]")  # there, but not the published file
    assert release.present_loss_names(tmp_path) == ()
    if DATA and (Path(DATA) / "release" / key).is_file():
        _place(tmp_path, key).write_bytes((Path(DATA) / "release" / key).read_bytes())
        assert release.present_loss_names(tmp_path) == ("../iteration_ite135.txt",)


@real
def test_real_feedback_loss_curves_end_where_their_networks_were_saved() -> None:
    """Each curve stops at the iteration of its FeedbackNN_ite<K> network, below the stopping level 0.5, at the
    loss recorded in that network's file name."""
    saved = {n.split("_")[1]: _recorded_loss(n) for n in release.SPIRAL_FEEDBACK_NAMES if "_loss" in n}
    assert len(release.SPIRAL_LOSS_NAMES) == 6
    present = release.present_loss_names(DATA)  # a data directory may hold only some curves (ours: ite135)
    assert present, "no loss curve of the release in the data directory"
    for name in present:
        curve = release.load_release_feedback_losses(DATA, name)
        ite = name.rsplit("/", 1)[-1].split("_")[1].removesuffix(".txt")
        assert len(curve) == int(ite.removeprefix("ite")) and curve[-1] < 0.5 < curve[0]
        assert abs(curve[-1] - saved[ite]) < 1e-5


def test_without_the_release_the_grouped_loaders_give_nothing(tmp_path) -> None:
    """The authors' spiral networks load only as a set; the loss curves only where present; a unit beyond the
    release's residual runs is refused."""
    assert release.load_release_spiral_networks(tmp_path, "Neural_ODE_ite400_loss0.2.pt", SPIRAL_FB,
                                                "Neural_ODE_domran.pt") is None
    assert release.load_present_feedback_losses(tmp_path) == {}
    with pytest.raises(ValueError, match="residual runs"):
        release.load_release_quadrotor_networks(tmp_path, len(release.RESIDUAL_RUNS) + 1)


@real
def test_real_grouped_loaders_pair_the_units_and_load_the_spiral_set() -> None:
    f, h, f_dr = release.load_release_spiral_networks(DATA, "Neural_ODE_ite400_loss0.2.pt", SPIRAL_FB,
                                                      "Neural_ODE_domran.pt")
    assert type(f).__name__ == type(f_dr).__name__ == "NeuralODE" and type(h).__name__ == "NeuralFeedback"
    theirs, mlps = release.load_release_quadrotor_networks(DATA, 5)
    assert [r for r, _ in theirs] == list(release.RESIDUAL_RUNS[:5])
    assert [r for r, _ in mlps] == [release.MLP_RUNS[k % len(release.MLP_RUNS)] for k in range(5)]
    assert all(p.dtype == torch.float64 for _, n in theirs + mlps for p in n.parameters())
    curves = release.load_present_feedback_losses(DATA)
    assert list(curves) == list(release.present_loss_names(DATA)) and all(c.ndim == 1 for c in curves.values())

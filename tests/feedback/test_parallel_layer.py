"""The batched first layer (Newton on the whole sequence, :mod:`fnnlib.feedback.gaps`) against its sequential
reference: values to 1e-10 in float64, gradients, the iterations it takes, and the chunked fallback."""

from __future__ import annotations

import math

import pytest
import torch
from torch import nn

import fnnlib as F
from fnnlib.feedback import cascade_depths
from fnnlib.feedback.cascade import run_cascade
from fnnlib.feedback.gaps import first_layer, layer_loop, measure_fn, start_state
from fnnlib.feedback.measurement import check_measurements
from fnnlib.feedback.sampling import row_steps

F64 = torch.float64
TS, T = 0.05, 300
C = torch.tensor([[1.0, 0.0]], dtype=F64)


class Duffing(nn.Module):
    """A forced Duffing oscillator, x'' = -d x' - a x - b x^3 + u: the plant of the partial-measurement trial."""

    def forward(self, t, x, u=None):
        p, v = x[..., :1], x[..., 1:]
        acc = -0.3 * v - p - 0.5 * p ** 3 + (0.0 if u is None else u)
        return torch.cat([v, acc], -1)


def _net():
    torch.manual_seed(0)
    return F.NeuralODE(2, (16, 16), "tanh", n_input=1).double()


def _record(B=3, noise=0.02, lost=0.2, seed=0):
    g = torch.Generator().manual_seed(seed)
    u = torch.sin(0.8 * torch.arange(T, dtype=F64) * TS)[None, :, None].expand(B, T, 1).clone()
    x0 = torch.randn(B, 2, generator=g, dtype=F64)
    xs = [x0]
    plant = Duffing()
    for k in range(T - 1):
        xs.append(xs[-1] + TS * plant(0.0, xs[-1], u[:, k]))
    x = torch.stack(xs, -2)
    y = x[..., :1] + noise * torch.randn(B, T, 1, generator=g, dtype=F64)
    y[torch.rand(B, T, generator=g) < lost] = float("nan")
    return x, y, u


def _gain():
    return torch.tensor([[2.0], [3.0]], dtype=F64)


@pytest.mark.parametrize("model", ["plant", "net"])
def test_observer_equals_its_sequential_reference(model):
    f = Duffing() if model == "plant" else _net()
    x, y, u = _record()
    obs = F.MeasuredFeedback(f, TS, L=_gain(), measurement=F.Measurement(C=C), allow_unstable=True)
    fast, slow = obs.observe(y, u), obs.observe_loop(y, u)
    torch.testing.assert_close(fast.x_hat, slow.x_hat, rtol=0, atol=1e-10)
    torch.testing.assert_close(fast.f_hat, slow.f_hat, rtol=0, atol=1e-10)


def test_measurement_function_and_uneven_times_equal_the_reference():
    x, y, u = _record(B=2)
    g = torch.Generator().manual_seed(3)
    t = torch.cumsum(TS * (0.5 + torch.rand(2, T, generator=g, dtype=F64)), -1)
    h = lambda s: torch.sin(s[..., :1])  # noqa: E731  a nonlinear sensor
    obs = F.MeasuredFeedback(Duffing(), None, L=_gain(), measurement=F.Measurement(C=h, x0=torch.zeros(2, dtype=F64)),
                             allow_unstable=True)
    y = torch.sin(y)
    fast, slow = obs.observe(y, u, t=t), obs.observe_loop(y, u, t=t)
    torch.testing.assert_close(fast.x_hat, slow.x_hat, rtol=0, atol=1e-10)


def test_full_state_gaps_layer_equals_the_reference_and_counts_its_iterations():
    f = _net()
    x, _, u = _record()
    z = x + 0.01 * torch.randn(x.shape, generator=torch.Generator().manual_seed(1), dtype=F64)
    z[:, 100:160] = float("nan")  # a long gap: open loop through it
    z[torch.rand(z.shape[:-1], generator=torch.Generator().manual_seed(2)) < 0.2] = float("nan")
    meas = check_measurements(z, 2, u=u, f=f)
    L = torch.tensor([3.0, 4.0], dtype=F64)
    x0 = start_state(meas, 2, None)
    est, depth0, out, iters = first_layer(f, meas, L, TS, x0)
    ref, ref_out = layer_loop(f, meas.y, L, TS, x0, mask=meas.mask, u=meas.u)
    torch.testing.assert_close(est.x_hat, ref.x_hat, rtol=0, atol=1e-10)
    torch.testing.assert_close(out, ref_out, rtol=0, atol=1e-10)
    assert 1 <= iters <= 12  # the iterations Newton takes on a contracting layer (shown by the benchmark too)


def test_chunked_fallback_when_newton_does_not_converge():
    """An expanding model through a long gap: the whole-record Newton may not converge in its budget; the
    chunked solve still equals the reference."""
    f = lambda t, x: 1.5 * x + 0.3 * torch.sin(3 * x)  # noqa: E731  unstable
    z = torch.linspace(0, 1, 200, dtype=F64)[:, None].repeat(1, 2)
    z[20:180] = float("nan")
    meas = check_measurements(z, 2)
    L = torch.tensor([5.0, 5.0], dtype=F64)
    x0 = start_state(meas, 2, None)
    from fnnlib.feedback import gaps
    est, _, _, iters = first_layer(f, meas, L, 0.01, x0)
    ref, _ = layer_loop(f, meas.y, L, 0.01, x0, mask=meas.mask)
    torch.testing.assert_close(est.x_hat, ref.x_hat, rtol=1e-10, atol=1e-10)
    steps = gaps.layer_step(f, meas.y, L, 0.01, mask=meas.mask)
    full, _ = gaps.solve_layer(lambda a, b: (lambda xx: gaps.layer_step(f, meas.y[a:b], L, 0.01,
                                                                        mask=meas.mask[a:b])(xx)[2]),
                               x0, 200, max_iter=3)  # forced fallback: pieces of 64 rows
    torch.testing.assert_close(full[:-1], ref.x_hat, rtol=1e-10, atol=1e-10)
    full, _ = gaps.solve_layer(lambda a, b: (lambda xx: gaps.layer_step(f, meas.y[a:b], L, 0.01,
                                                                        mask=meas.mask[a:b])(xx)[2]),
                               x0, 200, chunk=50)  # chunks
    torch.testing.assert_close(full[:-1], ref.x_hat, rtol=1e-10, atol=1e-10)
    assert steps is not None


def test_gradients_through_the_batched_layer_equal_the_loops():
    f = _net()
    x, y, u = _record(B=2)
    meas = check_measurements(y, 2, C=C, u=u, f=f)
    L = _gain().clone().requires_grad_(True)
    x0 = start_state(meas, 2, None)
    measure = measure_fn(meas, F64)

    def loss_fast():
        _, _, out, _ = first_layer(f, meas, L, TS, x0, diagonal=False)
        return out.pow(2).mean()

    def loss_slow():
        _, out = layer_loop(f, meas.y, L, row_steps(TS, 0, T), x0, mask=meas.mask, u=meas.u, measure=measure,
                            diagonal=False)
        return out.pow(2).mean()

    params = [L, *f.parameters()]
    g_fast = torch.autograd.grad(loss_fast(), params)
    g_slow = torch.autograd.grad(loss_slow(), params)
    for a, b in zip(g_fast, g_slow):
        torch.testing.assert_close(a, b, rtol=1e-8, atol=1e-10)


def test_cascade_with_an_observer_is_its_layer_then_the_paper_cascade():
    f = _net()
    x, y, u = _record(B=2)
    obs = F.MeasuredFeedback(f, TS, L=_gain(), measurement=F.Measurement(C=C), allow_unstable=True)
    z_hat = obs.observe_loop(y, u).x_hat
    first = z_hat[..., 1:, :]
    all_depths = cascade_depths(f, y, TS, 6, F.Gains(2.0, 0.1), u=u, observer=obs)
    torch.testing.assert_close(all_depths[0], z_hat, rtol=0, atol=1e-10)
    torch.testing.assert_close(all_depths[1][..., :-1, :], first, rtol=0, atol=1e-10)
    rest = run_cascade(f, all_depths[1], [torch.full((2,), 2.0 * math.exp(-0.1 * i),
                                                         dtype=F64) for i in range(1, 6)], TS, u=u, first_depth=1)
    torch.testing.assert_close(all_depths[-1], rest, rtol=0, atol=1e-12)
    # L = 0 after the observer: the open-loop Euler rollout from the observer's one-step estimate
    open_loop = obs.predict(y, 6, u)
    zero = F.cascade_predict(f, y, TS, 6, F.Gains(0.0), u=u, observer=obs)
    torch.testing.assert_close(zero, open_loop, rtol=0, atol=1e-10)


def test_a_long_record_is_solved_in_chunks_and_equals_the_reference():
    """Beyond 1024 samples the record is solved a chunk at a time (a poor guess's linearisation can expand
    over thousands of steps); the result is still the sequential loop's."""
    g = torch.Generator().manual_seed(5)
    T_long = 2500
    u = torch.randn(1, T_long, 1, generator=g, dtype=F64)
    y = 0.3 * torch.randn(1, T_long, 1, generator=g, dtype=F64).cumsum(1) / T_long ** 0.5
    y[torch.rand(1, T_long, generator=g) < 0.2] = float("nan")
    obs = F.MeasuredFeedback(Duffing(), TS, L=_gain(), measurement=F.Measurement(C=C), allow_unstable=True)
    torch.testing.assert_close(obs.observe(y, u).x_hat, obs.observe_loop(y, u).x_hat, rtol=0, atol=1e-10)

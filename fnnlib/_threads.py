"""Torch thread settings for fnnlib's small networks."""

from __future__ import annotations

import torch

DEFAULT_THREADS = 1


def set_num_threads(n: int = DEFAULT_THREADS) -> None:
    """Set torch's intra-op threads.

    fnnlib sets 1 thread when it is imported: its networks are tiny (tens of
    units), and on a few CPU cores one thread is faster than thread-pool
    overhead. Call this with a larger ``n`` to change that.
    """
    if int(n) < 1:
        raise ValueError(f"number of threads must be >= 1, got {n}")
    torch.set_num_threads(int(n))

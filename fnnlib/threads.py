"""Torch thread settings for fnnlib's small networks."""

from __future__ import annotations

import torch

#: torch threads for the small networks (one is fastest on a few cores)
DEFAULT_THREADS = 1


def set_num_threads(n: int = DEFAULT_THREADS) -> None:
    """Set torch's intra-op threads.

    Importing fnnlib leaves the thread count alone. The default, 1, suits its
    tiny networks (tens of units): on a few CPU cores one thread is faster
    than thread-pool overhead. The pipeline runner calls this at the start of
    each notebook's kernel with cores / workers (1 when every core runs a task).
    """
    if int(n) < 1:
        raise ValueError(f"number of threads must be >= 1, got {n}")
    torch.set_num_threads(int(n))

"""fnnlib: feedback neural ODEs (Jia et al., "Feedback Favors the Generalization of Neural ODEs", ICLR 2025).

The public face is the method (see :mod:`fnnlib._api`: at most about 30 names); the paper's own systems,
settings, sweeps, the quadrotor stack and the released networks live in named subpackages.
Importing fnnlib changes no global state; :func:`fnnlib.threads.set_num_threads` sets torch's
intra-op threads.

Names are loaded on first use (PEP 562, see :mod:`fnnlib._api`): ``import fnnlib`` is cheap, and a submodule
such as :mod:`fnnlib.io` can be imported without torch.
"""

from __future__ import annotations

import importlib
import importlib.util
from typing import Any


def __getattr__(name: str) -> Any:
    if name == "__version__":  # written once, in pyproject.toml; read from the installed package's metadata
        from importlib.metadata import PackageNotFoundError, version  # noqa: PLC0415

        try:
            return version("fnnlib")
        except PackageNotFoundError:  # a source tree on sys.path that was never installed
            return "0+unknown"
    if not name.startswith("__") and importlib.util.find_spec(f"{__name__}.{name}") is not None:
        return importlib.import_module(f"{__name__}.{name}")  # a submodule (``from fnnlib import io``)
    api = importlib.import_module("fnnlib._api")  # loads every subpackage, each set as an attribute here
    if name in globals():
        return globals()[name]
    try:
        value = getattr(api, name)
    except AttributeError:
        raise AttributeError(f"module 'fnnlib' has no attribute {name!r}") from None
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(importlib.import_module("fnnlib._api").__all__))

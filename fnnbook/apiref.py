"""The book's API reference page: fnnlib's face, grouped by the part of the method, then its subpackages.

The face is ``fnnlib._api.__all__`` (``import fnnlib as F``). Each of its names sits in one group of
:data:`GROUPS`, with a summary table (each name with its docstring's first paragraph, math included) and an
``autofunction`` / ``autoclass`` entry per callable (numpydoc docstrings read by napoleon, their math rendered
by MathJax); a constant is documented by its ``#:`` comment, read from the module that defines it. (Sphinx's
autosummary would cut each summary at the first ". ", which here is mostly "Eq. (7)".) The subpackages of
:data:`SUBPACKAGES` follow, one summary table each: their public names beyond the face.
"""

from __future__ import annotations

import importlib
import inspect
import os
import pkgutil
from dataclasses import dataclass
from pathlib import Path

__all__ = ["API_PAGE", "GROUPS", "SUBPACKAGES", "PublicName", "public_names", "render_api_page",
           "subpackage_names", "write_api_page"]

#: the page's name inside the book folder (without suffix)
API_PAGE = "api"

#: group title -> the face's names in it, in the page's order (the groups of ``fnnlib/_api.py``)
GROUPS: dict[str, tuple[str, ...]] = {
    "Systems and measurements (Eq. (1))": ("DynamicalSystem", "add_measurement_noise"),
    "The neural ODE and its training (Eqs. (2)-(3))": (
        "NeuralODE", "NeuralODEEnsemble", "ODERecipe", "train_neural_ode", "OutputRecipe", "train_from_outputs"),
    "The feedback layer and the cascade (Eqs. (7)-(8), (11), Sec. 3.3)": (
        "LinearFeedback", "decayed_gains", "cascade_predict", "rollout_predict"),
    "The neural feedback (Eq. (12), Alg. 1)": ("NeuralFeedback", "FeedbackRecipe", "train_neural_feedback"),
    "The gain and its checks (Theorem 1, Eqs. (9), (25))": (
        "check_gain", "GainError", "noise_amplification", "place_observer_gain"),
    "Tuning the gain from data": ("tune_gains", "TuneRecipe", "TunedGains", "choose_gain"),
    "Observers": ("Observer", "LuenbergerObserver", "KalmanObserver", "ExtendedKalmanObserver",
                  "UnscentedKalmanObserver", "NeuralFeedbackObserver"),
    "Partial measurements (y = C x or h(x))": ("MeasuredFeedback", "model_jacobian", "check_measurements"),
    "Options, checked on construction": ("Gains", "Measurement", "Solver", "Covariances", "SigmaPoints"),
}

#: module -> what it holds: the named homes of everything beyond the face, in the page's order
SUBPACKAGES: dict[str, str] = {
    "fnnlib.feedback": "the whole Sec. 3 core: the batched sweeps, the differentiable cascade, the gain helpers",
    "fnnlib.observers": "every observer and its tools",
    "fnnlib.systems": "the paper's systems (the spiral of Eq. (26), switched spirals) and others",
    "fnnlib.models": "the networks: ensembles, the neural feedback, the ARX baseline",
    "fnnlib.training": "recipes (the paper's among them), training loops and checkpoints",
    "fnnlib.stability": "Theorem 1's balls, the ISS bound of Eq. (25) and the error measures of the theory chapter",
    "fnnlib.metrics": "prediction errors",
    "fnnlib.stats": "the paired-seed comparison",
    "fnnlib.paper": "the paper's sweeps (Sec. 3.4, App. A.3)",
    "fnnlib.paper.spiral_presets": "the paper's Sec. 3-4 settings, each written once",
    "fnnlib.paper.feedback_eval": "the Sec. 4 evaluation of a neural feedback, for any networks",
    "fnnlib.data": "the thrown-bottle data of Sec. 5.1",
    "fnnlib.data.tanks": "the cascaded tanks benchmark's records and metric",
    "fnnlib.tanks.evaluation": "what the cascaded tanks chapter measures on a learned model",
    "fnnlib.release": "the authors' released networks, read safely",
    "fnnlib.quadrotor.presets": "the paper's Sec. 5 settings, each written once",
    "fnnlib.quadrotor.system": "the quadrotor of Eq. (27) and its parameter sets",
    "fnnlib.quadrotor.residual": "the aerodynamic residual networks of Sec. 5.2 (AeroResidual, AdaptiveResidual)",
    "fnnlib.quadrotor.training": "the residual's training by Alg. 3 (App. A.5.2) and the paper's recipe",
    "fnnlib.quadrotor.evaluation": "the flight records of the Q3-Q5 why grid",
    "fnnlib.quadrotor.control": "Sec. 5's reference trajectories and flatness controller",
    "fnnlib.quadrotor.mpc": "Sec. 5.3's MPC with the learned models",
    "fnnlib.seeding": "seeds and generators",
    "fnnlib.plotting": "the book's figures",
    "fnnlib.threads": "torch's threads",
}


@dataclass(frozen=True)
class PublicName:
    """One public name of fnnlib.

    Attributes
    ----------
    name : str
        As ``fnnlib.<name>`` (the face) or ``<source>.<name>`` (a subpackage).
    source : str
        The module that defines it.
    kind : str
        ``"class"``, ``"function"`` or ``"data"``.
    doc : str
        Its docstring (a constant: its ``#:`` comment); "" when it has none.
    """

    name: str
    source: str
    kind: str
    doc: str


def _data_doc(name: str, package: str) -> str:
    """The ``#:`` comment over ``name = ...`` in ``package`` or one of its modules ("" when none)."""
    from sphinx.pycode import ModuleAnalyzer  # noqa: PLC0415 (the book's dependency)

    pkg = importlib.import_module(package)
    modules = [package]
    if hasattr(pkg, "__path__"):
        modules += [m.name for m in pkgutil.walk_packages(pkg.__path__, prefix=f"{package}.")]
    for module in modules:
        docs = ModuleAnalyzer.for_module(module).find_attr_docs()
        if ("", name) in docs:
            return "\n".join(docs[("", name)]).strip()
    return ""


def _own_doc(obj: object) -> str:
    """A class's or function's own docstring; a dataclass's generated ``Name(field, ...)`` does not count."""
    doc = obj.__doc__ or ""
    if inspect.isclass(obj) and doc.startswith(f"{obj.__name__}("):
        return ""
    return inspect.cleandoc(doc)


def _describe(name: str, obj: object, module: str) -> PublicName:
    if inspect.isclass(obj):
        return PublicName(name, getattr(obj, "__module__", module), "class", _own_doc(obj))
    if inspect.isroutine(obj):
        return PublicName(name, getattr(obj, "__module__", module), "function", _own_doc(obj))
    return PublicName(name, module, "data", _data_doc(name, module))


def public_names() -> list[PublicName]:
    """Every name of the face (``fnnlib._api.__all__``), in the order of :data:`GROUPS`.

    Raises
    ------
    ValueError
        If a name of the face is in no group, or a group names what the face does not hold.
    """
    import fnnlib  # noqa: PLC0415

    face = list(dict.fromkeys(importlib.import_module("fnnlib._api").__all__))
    grouped = [n for names in GROUPS.values() for n in names]
    if missing := [n for n in face if n not in grouped]:
        raise ValueError(f"fnnlib.{missing[0]}: on the face but in no group of fnnbook.apiref.GROUPS")
    if extra := [n for n in grouped if n not in face]:
        raise ValueError(f"fnnbook.apiref.GROUPS names {extra[0]!r}, which is not on fnnlib's face")
    return [_describe(n, getattr(fnnlib, n), "fnnlib") for n in grouped]


def subpackage_names(module: str) -> list[PublicName]:
    """The public names of one subpackage or module beyond the face: its ``__all__``, or else the names it
    defines that do not start with ``_``."""
    mod = importlib.import_module(module)
    face = set(importlib.import_module("fnnlib._api").__all__)
    names = getattr(mod, "__all__", None)
    if names is None:
        names = [n for n, v in vars(mod).items() if not n.startswith("_") and not inspect.ismodule(v)
                 and (getattr(v, "__module__", module) == module or not callable(v)) and n.isidentifier()
                 and n not in ("annotations",)]
    return [_describe(n, getattr(mod, n), module) for n in names if n not in face]


def _group(name: str) -> str:
    return next(title for title, names in GROUPS.items() if name in names)


def _indent(text: str, by: str = "   ") -> list[str]:
    return [by + line if line.strip() else "" for line in text.splitlines()]


def _entry(item: PublicName) -> list[str]:
    if item.kind == "class":
        return [f".. autoclass:: fnnlib.{item.name}", "   :members:", "   :show-inheritance:", ""]
    if item.kind == "function":
        return [f".. autofunction:: fnnlib.{item.name}", ""]
    import fnnlib  # noqa: PLC0415

    value = getattr(fnnlib, item.name)
    head = [f".. py:data:: {item.name}", "   :module: fnnlib"]
    if isinstance(value, (int, float, str)):
        head.append(f"   :value: {value!r}")
    elif type(value).__module__.startswith("fnnlib"):  # a recipe: its class, documented on this page
        head.append(f"   :type: {type(value).__name__}")
    return [*head, "", *_indent(item.doc), ""]


def _first(doc: str) -> str:
    return " ".join(doc.split("\n\n", 1)[0].split()).replace("|", "\\|")


def render_api_page(names: list[PublicName] | None = None) -> str:
    """The API reference page (MyST markdown): the face by group (a summary table and each entry), then each
    subpackage of :data:`SUBPACKAGES` (a summary table)."""
    names = public_names() if names is None else names
    out = ["# API reference", "",
           "`import fnnlib as F` gives the method: the names below, grouped by the part of the paper they "
           "implement; each entry's docstring gives the paper's equation and the shapes. Everything else has a "
           "named home, listed after them (for example `from fnnlib.paper import colon_range`); the modules "
           "are listed one line each in the repository's `ARCHITECTURE.md`.", ""]
    for title in GROUPS:
        group = [n for n in names if _group(n.name) == title]
        if not group:
            continue
        out += [f"## {title}", "", "```{eval-rst}", ".. list-table::", "   :widths: 30 70",
                "   :class: api-summary", ""]
        for item in group:
            out += [f"   * - :py:obj:`~fnnlib.{item.name}`", f"     - {_first(item.doc)}"]
        out.append("")
        for item in group:
            out += _entry(item)
        out += ["```", ""]
    out += ["## Beyond the face", ""]
    for module, what in SUBPACKAGES.items():
        items = subpackage_names(module)
        if not items:
            continue
        out += [f"### `{module}`: {what}", "", "| name | what it is |", "| --- | --- |"]
        out += [f"| `{item.name}` | {_first(item.doc)} |" for item in items]
        out.append("")
    return "\n".join(out)


def write_api_page(folder: str | os.PathLike[str]) -> Path:
    """Write :func:`render_api_page` to ``<folder>/api.md``; returns its path."""
    path = Path(folder) / f"{API_PAGE}.md"
    path.write_text(render_api_page(), encoding="utf-8")
    return path

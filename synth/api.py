"""The engine's one entry point: ``synthesize(method, exemplar, ...) -> Result``.

Methods register themselves in :data:`METHODS` (name -> :class:`MethodSpec`). The service, the
worker and the CLI all go through :func:`synthesize`, so they share parameters and results.
"""

from __future__ import annotations

import importlib
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from synth.errors import InvalidInput, InvalidParameter
from synth.params import MethodParams, validate_params

__all__ = ["METHODS", "MethodSpec", "Progress", "Result", "available_methods", "synthesize"]


class Progress(Protocol):
    """Progress protocol: any callable ``(stage, fraction)``; it may raise to cancel the work."""

    def __call__(self, stage: str, fraction: float) -> None: ...


@dataclass(frozen=True)
class Result:
    """What a synthesis returns.

    ``image`` is float32 in [0, 1]: ``(H, W)``, ``(H, W, 3)`` or a volume ``(D, H, W)``.
    ``tensor_field`` is the synthesized (or constraint) structure tensor field ``(H, W, 3)`` when the
    method has one. ``extras`` holds further named float images (e.g. ``constraint_orientation``),
    ``stats`` numbers measured during the run (e.g. mean best-match distance per level).
    """

    method: str
    image: np.ndarray
    params: dict[str, Any]
    seed: int
    timings: dict[str, float]
    tensor_field: np.ndarray | None = None
    extras: dict[str, np.ndarray] = field(default_factory=dict)
    stats: dict[str, Any] = field(default_factory=dict)


Runner = Callable[..., Result]


@dataclass(frozen=True)
class MethodSpec:
    """A registered method: its name, one-line summary, parameter model and runner.

    ``run(exemplar, size=..., params=..., seed=..., progress=..., constraint=...) -> Result``.
    ``constraint`` is ``'none'``, ``'optional'`` or ``'required'``; ``output_ndim`` 2 or 3.
    """

    name: str
    summary: str
    params_model: type[MethodParams]
    run: Runner
    constraint: str = "none"
    output_ndim: int = 2
    paper: str = ""

    def schema(self) -> dict[str, Any]:
        return self.params_model.model_json_schema()


METHODS: dict[str, MethodSpec] = {}

# Method modules register on import; importing them here keeps the registry complete.
_METHOD_MODULES: Sequence[str] = (
    "synth.methods.wei_levoy",
    "synth.methods.tensor_constrained",
    "synth.methods.arbitrary_shape",
)


def register(spec: MethodSpec) -> MethodSpec:
    METHODS[spec.name] = spec
    return spec


def _load_methods() -> None:
    for module in _METHOD_MODULES:
        try:
            importlib.import_module(module)
        except ModuleNotFoundError as exc:
            if exc.name != module:  # a real import error inside the module
                raise


def available_methods() -> dict[str, MethodSpec]:
    """All registered methods, by name."""
    _load_methods()
    return dict(METHODS)


def _noop_progress(stage: str, fraction: float) -> None:
    return None


def synthesize(
    method: str,
    exemplar: np.ndarray,
    *,
    size: tuple[int, ...] | None = None,
    params: dict[str, Any] | MethodParams | None = None,
    seed: int = 0,
    progress: Progress | None = None,
    constraint: np.ndarray | None = None,
) -> Result:
    """Run ``method`` on ``exemplar`` and return a :class:`Result`.

    Parameters
    ----------
    method : str
        A name in :func:`available_methods` (``'wei-levoy'``, ``'tensor-constrained'``, ...).
    exemplar : ndarray
        float32 image in [0, 1], ``(h, w)`` or ``(h, w, 3)`` (see :mod:`synth.io`).
    size : tuple of int, optional
        Output array shape ``(H, W)`` (or ``(D, H, W)`` for volumes). Defaults to the constraint's
        shape when there is one, else twice the exemplar's.
    params : dict or the method's parameter model
        Validated against the method's model before any work; unknown names are errors.
    seed : int
        Same inputs, parameters and seed give the same bytes.
    progress : callable ``(stage, fraction)``, optional
        Called at least every 2% of the work; may raise (e.g. :class:`synth.Cancelled`) to stop.
    constraint : ndarray, optional
        Constraint image of methods that take one.
    """
    methods = available_methods()
    if method not in methods:
        raise InvalidParameter("method", method, f"unknown method (known: {', '.join(sorted(methods))})")
    spec = methods[method]
    model = validate_params(spec.params_model, params)
    if not isinstance(seed, int | np.integer) or not 0 <= int(seed) < 2**32:
        raise InvalidParameter("seed", seed, "must be an integer in [0, 2**32)")
    ex = np.asarray(exemplar)
    if ex.ndim not in (2, 3) or (ex.ndim == 3 and ex.shape[2] != 3):
        raise InvalidInput("exemplar", f"shape {ex.shape} is neither (H, W) grey nor (H, W, 3) RGB")
    ex = np.ascontiguousarray(ex, dtype=np.float32)
    if spec.constraint == "required" and constraint is None:
        raise InvalidInput("constraint", f"method '{method}' needs a constraint image")
    if spec.constraint == "none" and constraint is not None:
        raise InvalidInput("constraint", f"method '{method}' takes no constraint image")
    con = None if constraint is None else np.ascontiguousarray(constraint, dtype=np.float32)
    out_size = _output_size(size, ex, con, spec.output_ndim)
    start = time.perf_counter()
    result = spec.run(
        ex, size=out_size, params=model, seed=int(seed), progress=progress or _noop_progress, constraint=con
    )
    result.timings.setdefault("total", time.perf_counter() - start)
    return result


def _output_size(
    size: tuple[int, ...] | None, exemplar: np.ndarray, constraint: np.ndarray | None, ndim: int
) -> tuple[int, ...]:
    if size is None:
        if constraint is not None:
            return tuple(constraint.shape[:2])
        base = tuple(2 * s for s in exemplar.shape[:2])
        return base if ndim == 2 else (base[0], *base)
    shape = tuple(int(s) for s in size)
    if len(shape) != ndim:
        raise InvalidParameter("size", size, f"needs {ndim} values for this method")
    if any(s < 8 or s > 8192 for s in shape):
        raise InvalidParameter("size", size, "each side must lie in [8, 8192] pixels")
    return shape

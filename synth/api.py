"""The engine's one entry point: ``synthesize(method, exemplar, ...) -> Result``.

Methods register themselves in :data:`METHODS` (name -> :class:`MethodSpec`). The service, the
worker and the CLI all go through :func:`synthesize`, so they share parameters and results.
"""

from __future__ import annotations

import dataclasses
import importlib
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from texsynth.synth.errors import InvalidInput, InvalidParameter
from texsynth.synth.io.depth import InputBits, array_to_unit
from texsynth.synth.io.limits import check_output_size
from texsynth.synth.params import MethodParams, validate_params
from texsynth.synth.threads import check_threads, use_threads

__all__ = [
    "METHODS",
    "PLANES",
    "MethodSpec",
    "Progress",
    "Result",
    "available_methods",
    "check_inputs",
    "find_method",
    "synthesize",
]

#: The orthogonal planes of a volume ``(D, H, W) = (z, y, x)`` (ALGORITHMS.md, "Conventions"): ``xy`` is
#: the slice at fixed ``z`` (``vol[z]``, rows ``y``, columns ``x``), ``xz`` at fixed ``y`` (``vol[:, y]``,
#: rows ``z``, columns ``x``), ``yz`` at fixed ``x`` (``vol[:, :, x]``, rows ``z``, columns ``y``).
PLANES: tuple[str, ...] = ("xy", "xz", "yz")


class Progress(Protocol):
    """Progress protocol: any callable ``(stage, fraction)``; it raises :class:`synth.Cancelled` to stop
    the work (anything else it raises is a bug and propagates as it is)."""

    def __call__(self, stage: str, fraction: float) -> None: ...


@dataclass(frozen=True)
class Result:
    """What a synthesis returns.

    ``image`` is float32 in [0, 1]: ``(H, W)``, ``(H, W, 3)`` or a volume ``(D, H, W)``.
    ``tensor_field`` is the synthesized (or constraint) structure tensor field ``(H, W, 3)`` when the
    method has one. ``extras`` holds further named float images (e.g. ``constraint_orientation``),
    ``stats`` numbers measured during the run (e.g. mean best-match distance per level).
    ``input_bits`` is the exemplar's bit depth (:class:`texsynth.synth.io.InputBits`), which writers keep.
    """

    method: str
    image: np.ndarray
    params: dict[str, Any]
    seed: int
    timings: dict[str, float]
    tensor_field: np.ndarray | None = None
    extras: dict[str, np.ndarray] = field(default_factory=dict)
    stats: dict[str, Any] = field(default_factory=dict)
    input_bits: InputBits | None = None


Runner = Callable[..., Result]


@dataclass(frozen=True)
class MethodSpec:
    """A registered method: its name, one-line summary, parameter model and runner.

    ``run(exemplar, size=..., params=..., seed=..., progress=..., constraint=...) -> Result``; a method
    with ``plane_exemplars`` also gets ``exemplars={'xy': ..., 'xz': ..., 'yz': ...}`` (the one
    exemplar three times when the material is isotropic) and ``exemplar`` is then ``exemplars['xy']``.
    ``constraint`` is ``'none'``, ``'optional'`` or ``'required'``; ``output_ndim`` 2 or 3.
    """

    name: str
    summary: str
    params_model: type[MethodParams]
    run: Runner
    constraint: str = "none"
    output_ndim: int = 2
    paper: str = ""
    #: Takes one exemplar per orthogonal plane (``exemplar_xy``, ``exemplar_xz``, ``exemplar_yz``) as
    #: an alternative to the one exemplar (anisotropic materials).
    plane_exemplars: bool = False
    #: Cheap checks of the parameters against the inputs' shapes (``{role: shape}``, plus ``'output'``:
    #: the output's shape when the caller knows it), run before any work (the service calls them before
    #: queueing, so a patch larger than the exemplar, or a tileable output too small for two patch steps,
    #: is a 422 at once); raise the engine's errors. ``None``: the method has none beyond its parameter
    #: model.
    precheck: Callable[[Any, Mapping[str, tuple[int, ...]]], None] | None = None
    #: Measured run time per output element with the defaults on the reference machine (2 cores,
    #: docs/benchmarks.md), a lower bound: the service refuses before queueing a job whose estimate
    #: already exceeds its time limit. ``0``: no estimate (the method is fast at every allowed size).
    seconds_per_element: float = 0.0

    def schema(self) -> dict[str, Any]:
        return self.params_model.model_json_schema()

    @property
    def inputs(self) -> dict[str, str]:
        """The images this method takes, by role: ``'required'``, ``'optional'`` or ``'alternative'``.

        ``'alternative'`` marks the per-plane exemplars: all three together, instead of ``exemplar``.
        The API, the CLI and the browser page ask for exactly these.
        """
        roles = {"exemplar": "required" if not self.plane_exemplars else "alternative"}
        if self.plane_exemplars:
            roles.update({f"exemplar_{plane}": "alternative" for plane in PLANES})
        if self.constraint != "none":
            roles["constraint"] = self.constraint
        return roles


METHODS: dict[str, MethodSpec] = {}

# Method modules register on import; importing them here keeps the registry complete.
_METHOD_MODULES: Sequence[str] = (
    "texsynth.synth.methods.wei_levoy",
    "texsynth.synth.methods.tensor_constrained",
    "texsynth.synth.methods.arbitrary_shape",
    "texsynth.synth.methods.solid_wei_levoy",
    "texsynth.synth.methods.solid_kopf",
    "texsynth.synth.methods.solid_chen_wang",
    "texsynth.synth.methods.quilting",
    "texsynth.synth.methods.gaussian_patch",
    "texsynth.synth.methods.random_phase",
    "texsynth.synth.methods.feature_guided",
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


def find_method(name: str) -> MethodSpec | None:
    """The method ``name``, or ``None`` when no module registers it.

    Imports only the module that, by the naming rule of :data:`_METHOD_MODULES`
    (``'wei-levoy'`` -> ``texsynth.synth.methods.wei_levoy``), should register it, so that one synthesis does
    not import every method's dependencies; falls back to all of them.
    """
    if name not in METHODS:
        module = f"texsynth.synth.methods.{name.replace('-', '_')}"
        if module in _METHOD_MODULES:
            try:
                importlib.import_module(module)
            except ModuleNotFoundError as exc:
                if exc.name != module:  # a real import error inside the module
                    raise
    if name not in METHODS:
        _load_methods()
    return METHODS.get(name)


def check_inputs(spec: MethodSpec, roles: Sequence[str] | set[str]) -> None:
    """Check which input images were given against what ``spec`` declares (:attr:`MethodSpec.inputs`).

    One rule for the API, the CLI and the service, checked before anything is decoded or queued: the
    exemplar (or, for solid methods, all three per-plane exemplars instead), the constraint when the
    method requires one and not when it takes none, and nothing else. Raises
    :class:`~texsynth.synth.errors.InvalidInput` naming the input.
    """
    given = set(roles)
    declared = spec.inputs
    for role in sorted(given - set(declared)):
        if role == "constraint":
            raise InvalidInput("constraint", f"method '{spec.name}' takes no constraint image; leave it out")
        if role.startswith("exemplar_"):
            raise InvalidInput(
                role, f"method '{spec.name}' takes one exemplar, not one per plane (it makes 2-D images)"
            )
        raise InvalidInput(role, f"not an input of method '{spec.name}' (inputs: {', '.join(declared)})")
    planes = [f"exemplar_{plane}" for plane in PLANES]
    given_planes = [role for role in planes if role in given]
    if spec.plane_exemplars and given_planes:
        if "exemplar" in given:
            raise InvalidInput(
                "exemplar", "give one exemplar or one per plane (exemplar_xy, exemplar_xz, exemplar_yz)"
            )
        missing = [role for role in planes if role not in given]
        if missing:
            raise InvalidInput(missing[0], "missing: per-plane exemplars come as all three")
    elif "exemplar" not in given:
        also = " (or exemplar_xy, exemplar_xz and exemplar_yz)" if spec.plane_exemplars else ""
        raise InvalidInput("exemplar", f"missing: method '{spec.name}' needs an exemplar image{also}")
    if spec.constraint == "required" and "constraint" not in given:
        raise InvalidInput("constraint", f"method '{spec.name}' needs a constraint image")


def _noop_progress(stage: str, fraction: float) -> None:
    return None


def synthesize(
    method: str,
    exemplar: np.ndarray | None = None,
    *,
    size: tuple[int, ...] | None = None,
    params: dict[str, Any] | MethodParams | None = None,
    seed: int = 0,
    progress: Progress | None = None,
    constraint: np.ndarray | None = None,
    exemplars: Mapping[str, np.ndarray] | None = None,
    max_output: int | None = None,
    threads: int | None = None,
) -> Result:
    """Run ``method`` on ``exemplar`` and return a :class:`Result`.

    Parameters
    ----------
    method : str
        A name in :func:`available_methods` (``'wei-levoy'``, ``'tensor-constrained'``, ...).
    exemplar : ndarray
        ``(h, w)`` or ``(h, w, 3)``: uint8, uint16 (scaled by the bit depth they use: 12-bit data in
        16 bits by 4095), bool, or float in [0, 1] (:mod:`texsynth.synth.io.depth`; other floats are an
    error). size : tuple of int, optional
        Output array shape ``(H, W)`` (or ``(D, H, W)`` for volumes). Defaults to the constraint's
        shape when there is one, else twice the exemplar's.
    params : dict or the method's parameter model
        Validated against the method's model before any work; unknown names are errors.
    seed : int
        Same inputs, parameters and seed give the same bytes.
    progress : callable ``(stage, fraction)``, optional
        Called at least every 2% of the work; raises :class:`synth.Cancelled` to stop.
    constraint : ndarray, optional
        Constraint image of methods that take one.
    exemplars : mapping ``{'xy', 'xz', 'yz'} -> ndarray``, optional
        One grey exemplar per orthogonal plane (:data:`PLANES`), for the solid methods, instead of
        ``exemplar``: each plane's slices of the volume must look like its own exemplar.
    max_output : int, optional
        Largest ``size`` (pixels or voxels) accepted; default: :mod:`texsynth.synth.io.limits`' ``max_output``
        (the service passes its own, lower one).
    threads : int, optional
        numba threads the synthesis runs on, 1 to ``NUMBA_NUM_THREADS``; default: all of them (every
        core). The bytes are the same whatever the count (:mod:`texsynth.synth.threads`).
    """
    spec = find_method(method)
    if spec is None:
        known = ", ".join(sorted(available_methods()))
        raise InvalidParameter("method", method, f"unknown method (known: {known})")
    model = validate_params(spec.params_model, params)
    if not isinstance(seed, int | np.integer) or not 0 <= int(seed) < 2**32:
        raise InvalidParameter("seed", seed, "must be an integer in [0, 2**32)")
    threads = check_threads(threads)
    given = {"exemplar"} if exemplar is not None else set()
    given |= {f"exemplar_{plane}" for plane in exemplars or {}}
    check_inputs(spec, given | ({"constraint"} if constraint is not None else set()))
    planes, depth = _plane_exemplars(exemplar, exemplars) if spec.plane_exemplars else (None, None)
    if planes is not None:
        ex = planes["xy"]
    else:
        ex, depth = _checked_image("exemplar", exemplar)
    con = None if constraint is None else array_to_unit(constraint, "constraint")[0]
    out_size = _output_size(size, ex, con, spec.output_ndim, planes, max_output)
    extra: dict[str, Any] = {"exemplars": planes} if planes is not None else {}
    start = time.perf_counter()
    with use_threads(threads):
        result = spec.run(
            ex,
            size=out_size,
            params=model,
            seed=int(seed),
            progress=progress or _noop_progress,
            constraint=con,
            **extra,
        )
    result.timings.setdefault("total", time.perf_counter() - start)
    return dataclasses.replace(result, input_bits=depth)


def _checked_image(role: str, image: np.ndarray | None) -> tuple[np.ndarray, InputBits]:
    """``image`` as float32 in [0, 1] by the one dtype policy (:mod:`texsynth.synth.io.depth`), and its
    depth."""
    if image is None:
        raise InvalidInput(role, "missing")
    arr = np.asarray(image)
    if arr.ndim not in (2, 3) or (arr.ndim == 3 and arr.shape[2] != 3):
        raise InvalidInput(role, f"shape {arr.shape} is neither (H, W) grey nor (H, W, 3) RGB")
    return array_to_unit(arr, role)


def _plane_exemplars(
    exemplar: np.ndarray | None, exemplars: Mapping[str, np.ndarray] | None
) -> tuple[dict[str, np.ndarray], InputBits]:
    """The three per-plane exemplars of a solid method (the one exemplar thrice when isotropic), and
    the ``xy`` one's depth."""
    if exemplar is not None:
        grey, depth = _checked_grey("exemplar", exemplar)
        return dict.fromkeys(PLANES, grey), depth
    assert exemplars is not None  # check_inputs saw all three
    checked = {plane: _checked_grey(f"exemplar_{plane}", exemplars[plane]) for plane in PLANES}
    return {plane: image for plane, (image, _) in checked.items()}, checked["xy"][1]


def _checked_grey(role: str, image: np.ndarray) -> tuple[np.ndarray, InputBits]:
    arr, depth = _checked_image(role, image)
    if arr.ndim != 2:
        raise InvalidInput(role, f"solid methods take grey exemplars; this one has shape {arr.shape}")
    return arr, depth


def _output_size(
    size: tuple[int, ...] | None,
    exemplar: np.ndarray,
    constraint: np.ndarray | None,
    ndim: int,
    planes: dict[str, np.ndarray] | None = None,
    max_output: int | None = None,
) -> tuple[int, ...]:
    if size is None:
        if constraint is not None:
            return tuple(constraint.shape[:2])
        if ndim == 3:
            # The exemplar's own scale: (D, H, W) from the xz rows and the xy image (Kopf: 128^2 -> 128^3).
            depth = planes["xz"].shape[0] if planes is not None else exemplar.shape[0]
            return (int(depth), *(int(s) for s in exemplar.shape[:2]))
        return tuple(2 * s for s in exemplar.shape[:2])
    return check_output_size(size, ndim, max_elements=max_output)

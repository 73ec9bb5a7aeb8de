"""What the API does, without HTTP: validate a submission, store it, queue it; report; cancel.

Routes stay thin: they parse the request and call a :class:`Service` method. Everything a request
can get wrong is checked here *before* anything is stored or queued, and raised as an engine error
(:mod:`texsynth.synth.errors`) that the API maps to 413/415/422.
"""

from __future__ import annotations

import contextlib
import itertools
import json
import math
import random
import re
import shutil
import threading
import time
import uuid
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any

from celery import group

from texsynth.app.admission import Admission
from texsynth.app.auth import ANONYMOUS, Principal, Tokens
from texsynth.jobs.config import Settings
from texsynth.jobs.methods import methods
from texsynth.jobs.queue import QUEUE, TASK_NAME, create_celery
from texsynth.jobs.reaper import Reaper
from texsynth.jobs.store import SIZE_FIELDS, TERMINAL, JobRecord
from texsynth.synth import __version__ as synth_version
from texsynth.synth.api import MethodSpec, check_inputs
from texsynth.synth.errors import InvalidParameter
from texsynth.synth.io import FORMAT_FILES, sniff_format
from texsynth.synth.io.limits import MAX_SIDE, MIN_SIDE, check_output_size
from texsynth.synth.params import validate_params
from texsynth.synth.pipeline import load_inputs

__all__ = ["SIZE_FIELDS", "VOXEL_UNITS", "JobRequest", "Service", "Upload"]

#: Length units a volume's voxel size may be given in (ImageJ's names; "um" is a micrometre).
VOXEL_UNITS: tuple[str, ...] = ("nm", "um", "mm", "pm", "angstrom")
VOXEL_SIZE_MAX = 1e6


def _output_shape(size: dict[str, int]) -> tuple[int, ...]:
    """The output's array shape ``(H, W)`` or ``(D, H, W)`` from the size fields, for the prechecks."""
    return tuple(int(size[k]) for k in ("depth", "height", "width") if k in size)


@dataclass(frozen=True)
class Upload:
    role: str
    filename: str
    data: bytes


@dataclass(frozen=True)
class JobRequest:
    """A validated submission: everything needed to create and queue a job."""

    method: str
    params: dict[str, Any]  # the method's parameters (as validated, defaults filled)
    size: dict[str, int]  # the output's width, height (, depth)
    seed: int
    inputs: dict[str, tuple[str, bytes]]
    shapes: dict[str, tuple[int, ...]]  # the decoded inputs' array shapes, for admission control
    extras: dict[str, Any] = field(default_factory=dict)  # texsynth.jobs.store.EXTRA_FIELDS


class Service:
    """The job service of one API process: settings, tokens, job store, Celery producer, reaper."""

    def __init__(self, settings: Settings) -> None:
        self.settings = settings
        settings.ensure_dirs()
        self.tokens = Tokens.from_settings(settings)
        self.store = settings.open_store(keep_open=True)
        self.disk_full_at: float | None = None  # when a write last failed for lack of room (health)
        self.admission = Admission(settings, self.store)
        self._admit_lock = threading.Lock()  # a quota check and the records it counts, together
        self.celery = create_celery(settings)
        self._send_lock = threading.Lock()
        self.reaper = Reaper(self.store, settings, self.send, self.terminate)

    # -- queue ----------------------------------------------------------------------------------

    def send(self, job_id: str) -> None:
        with self._send_lock:
            self.celery.send_task(TASK_NAME, args=[job_id], task_id=job_id, queue=QUEUE)

    def send_group(self, job_ids: list[str]) -> None:
        sig = group(
            self.celery.signature(TASK_NAME, args=(j,), immutable=True, queue=QUEUE).set(task_id=j)
            for j in job_ids
        )
        with self._send_lock:
            sig.apply_async()

    def terminate(self, job_id: str) -> None:
        """Kill the worker child running ``job_id`` (the fallback when the engine does not stop)."""
        with self._send_lock:
            self.celery.control.revoke(job_id, terminate=True, signal="SIGKILL")

    def broker_ok(self) -> bool:
        try:
            with self.celery.connection_for_write() as conn:
                conn.ensure_connection(max_retries=1, interval_start=0, timeout=2)
            return True
        except Exception:
            return False

    # -- methods ----------------------------------------------------------------------------------

    def methods(self) -> dict[str, MethodSpec]:
        return methods(self.settings)

    def method(self, name: str) -> MethodSpec:
        known = self.methods()
        if name not in known:
            raise InvalidParameter(
                "method", name, f"unknown method; choose one of: {', '.join(sorted(known))}"
            )
        return known[name]

    def size_schema(self, spec: MethodSpec) -> dict[str, Any]:
        """The output's size fields (sent as form fields), with the form hints of the parameters'
        schemas (:func:`texsynth.synth.params.ui`); a volume's also says its voxel size (ImageJ
        calibration)."""
        unit = "px" if spec.output_ndim == 2 else "voxels"
        side = {"type": "integer", "minimum": MIN_SIDE, "maximum": MAX_SIDE, "default": 128, "x-basic": True}
        props: dict[str, Any] = {
            "width": {**side, "title": "Output width", "x-unit": unit, "description": "Width of the output."},
            "height": {
                **side,
                "title": "Output height",
                "x-unit": unit,
                "description": "Height of the output.",
            },
        }
        if spec.output_ndim == 3:
            props["depth"] = {
                **side,
                "default": 64,
                "title": "Output depth",
                "x-unit": "voxels",
                "description": "Number of slices of the volume (z).",
            }
            props["voxel_size"] = {
                "type": ["number", "null"],
                "exclusiveMinimum": 0,
                "maximum": VOXEL_SIZE_MAX,
                "default": None,
                "nullable": True,
                "title": "Voxel size",
                "x-basic": True,
                "x-unit-field": "voxel_unit",  # the unit is that field's value
                "description": "Size of one voxel, written into the TIFF stack for Fiji; empty: "
                "uncalibrated.",
            }
            props["voxel_unit"] = {
                "type": "string",
                "enum": list(VOXEL_UNITS),
                "default": "nm",
                "title": "Voxel unit",
                "description": "Length unit of the voxel size (used only when a voxel size is given).",
            }
        return {"type": "object", "properties": props}

    # -- submission -----------------------------------------------------------------------------

    def validate(
        self,
        method: str,
        params_json: str | dict,
        seed: int | None,
        uploads: list[Upload],
        size: Mapping[str, Any] | None = None,
    ) -> JobRequest:
        """Check a submission completely (method, parameters, size, images) or raise an engine error.

        ``size``: the ``width``/``height``/``depth`` form fields; the same names inside ``params``
        (how the first clients sent them) are still accepted and moved out here. A volume's
        ``voxel_size`` and ``voxel_unit`` come with them (:meth:`_validate_voxel`)."""
        spec = self.method(method)
        params = _parse_params(params_json)
        size = dict(size or {})
        voxel = self._validate_voxel(spec, size.pop("voxel_size", None), size.pop("voxel_unit", None))
        size = self._validate_size(spec, _take_size(spec, params, size))
        model = validate_params(spec.params_model, params)
        if seed is None:
            seed = random.randrange(2**31)
        if not 0 <= seed < 2**32:
            raise InvalidParameter("seed", seed, "must be an integer in [0, 2**32)")
        by_role = {u.role: u for u in uploads if u.data or u.filename}
        check_inputs(spec, set(by_role))  # each role is the multipart field of the same name
        # The engine's one judge of images: format from the bytes (415), size from the header before
        # decoding (413), then a full decode (truncated or corrupt -> 422 now, not in the worker).
        images = load_inputs(
            {role: u.data for role, u in by_role.items()}, max_pixels=self.settings.max_input_pixels
        )
        shapes = {role: tuple(image.shape) for role, image in images.items()}
        del images
        params_out = model.model_dump(mode="json")
        self.admission.check_job(
            method, params_out, size, shapes, seconds_per_element=spec.seconds_per_element
        )
        if spec.precheck is not None and any(r.startswith("exemplar") for r in shapes):  # before queueing
            spec.precheck(model, {**shapes, "output": _output_shape(size)})
        return JobRequest(
            method=method,
            params=params_out,
            size=size,
            seed=int(seed),
            # stored under a name from the sniffed format, never the client's (no evil.html)
            inputs={
                role: (f"{role}.{FORMAT_FILES[sniff_format(u.data) or 'PNG'][0]}", u.data)
                for role, u in by_role.items()
            },
            shapes=shapes,
            extras={**voxel, "input_names": {u.role: _display_name(u.filename) for u in by_role.values()}},
        )

    def _validate_voxel(self, spec: MethodSpec, size: Any, unit: Any) -> dict[str, Any]:
        """A volume's calibration: ``voxel_size`` (> 0) in ``voxel_unit`` (one of :data:`VOXEL_UNITS`,
        ``nm`` when a size comes alone); nothing given: an uncalibrated stack."""
        if size is None:
            if unit not in (None, "") and unit not in VOXEL_UNITS:
                raise InvalidParameter("voxel_unit", unit, f"must be one of {', '.join(VOXEL_UNITS)}")
            return {}
        if spec.output_ndim != 3:
            raise InvalidParameter("voxel_size", size, f"method '{spec.name}' makes 2-D images, not volumes")
        if isinstance(size, bool) or not isinstance(size, int | float) or not math.isfinite(size):
            raise InvalidParameter("voxel_size", size, "must be a finite number")
        if not 0 < size <= VOXEL_SIZE_MAX:
            raise InvalidParameter("voxel_size", size, f"must be above 0 and at most {VOXEL_SIZE_MAX:g}")
        unit = unit or "nm"
        if unit not in VOXEL_UNITS:
            raise InvalidParameter("voxel_unit", unit, f"must be one of {', '.join(VOXEL_UNITS)}")
        return {"voxel_size": float(size), "voxel_unit": unit}

    def _validate_size(self, spec: MethodSpec, size: dict[str, Any]) -> dict[str, int]:
        needed = ("height", "width") if spec.output_ndim == 2 else ("depth", "height", "width")
        extra = set(size) - set(needed)
        if extra:
            raise InvalidParameter(
                sorted(extra)[0], size[sorted(extra)[0]], f"method '{spec.name}' makes 2-D images"
            )
        values = [size.get(name, 128 if name != "depth" else 64) for name in needed]
        checked = check_output_size(
            values, spec.output_ndim, names=needed, max_elements=self.settings.max_output(spec.output_ndim)
        )
        return dict(zip(needed, checked, strict=True))

    def manifest(self, req: JobRequest) -> dict[str, Any]:
        voxel = {k: req.extras[k] for k in ("voxel_size", "voxel_unit") if k in req.extras}
        return {
            "method": req.method,
            "params": req.params,
            "size": req.size,
            "seed": req.seed,
            **voxel,
            "input_names": req.extras.get("input_names", {}),
            "texsynth": synth_version,
        }

    def submit(self, req: JobRequest, principal: Principal = ANONYMOUS) -> JobRecord:
        with self._admit_lock:
            self.admission.check_queue(principal.name, 1)
            self.admission.check_storage(principal, req.inputs)
            job_id = uuid.uuid4().hex
            with self._undone_on_error([job_id]):
                job = self.store.create_job(
                    method=req.method,
                    params=req.params,
                    size=req.size,
                    seed=req.seed,
                    inputs=req.inputs,
                    manifest={**self.manifest(req), "owner": principal.name},
                    owner=principal.name,
                    job_id=job_id,
                    extras=req.extras,
                )
        self._queue([job.id])
        return self.store.get(job.id) or job

    @contextlib.contextmanager
    def _undone_on_error(self, job_ids: list[str], sweep_id: str | None = None) -> Iterator[None]:
        """Jobs being created are forgotten again if their creation fails (a full disk: 507), their
        half-written folders included: a refused submission leaves nothing behind."""
        try:
            yield
        except BaseException:
            with contextlib.suppress(Exception):  # the disk may refuse even that: the folders still go
                self.store.discard(job_ids, sweep_id)
            for job_id in job_ids:
                shutil.rmtree(self.store.job_dir(job_id), ignore_errors=True)
            raise

    def _queue(self, job_ids: list[str], sweep_id: str | None = None) -> None:
        """Send the jobs; if the broker refuses, forget them (records and files) and say so: a refused
        submission leaves nothing behind, and the client may simply try again."""
        try:
            if len(job_ids) == 1:
                self.send(job_ids[0])
            else:
                self.send_group(job_ids)
        except Exception as exc:
            self.store.discard(job_ids, sweep_id)
            raise BrokerUnavailable(str(exc)) from exc

    def submit_sweep(self, req: JobRequest, grid_json: str | dict, principal: Principal = ANONYMOUS) -> str:
        """One job per point of the parameter grid (a Celery group); returns the sweep's id."""
        spec = self.method(req.method)
        grid = _parse_json(grid_json, "grid")
        if not isinstance(grid, dict) or not grid:
            raise InvalidParameter(
                "grid", grid, 'must be an object of parameter -> list of values, e.g. {"n": [5, 9]}'
            )
        for name, values in grid.items():
            if not isinstance(values, list) or not values:
                raise InvalidParameter(f"grid.{name}", values, "must be a non-empty list of values")
        runs = math.prod(len(values) for values in grid.values())
        self.admission.check_sweep(runs, 0)
        points = []
        for combo in itertools.product(*grid.values()):
            point = dict(zip(grid.keys(), combo, strict=True))
            params = {**req.params, **point}
            size = self._validate_size(spec, {**req.size, **_take_size(spec, params, None)})
            try:
                model = validate_params(spec.params_model, params)
            except InvalidParameter as exc:
                raise InvalidParameter(f"grid.{exc.name}", exc.value, exc.reason) from None
            point_params = model.model_dump(mode="json")
            self.admission.check_job(
                req.method,
                point_params,
                size,
                req.shapes,
                field_prefix="grid.",
                seconds_per_element=spec.seconds_per_element,
            )
            if spec.precheck is not None and any(r.startswith("exemplar") for r in req.shapes):
                try:
                    spec.precheck(model, {**req.shapes, "output": _output_shape(size)})
                except InvalidParameter as exc:
                    raise InvalidParameter(f"grid.{exc.name}", exc.value, exc.reason) from None
            points.append((point_params, size))
        self.admission.check_sweep(runs, sum(math.prod(size.values()) for _, size in points))
        sweep_id = uuid.uuid4().hex
        job_ids = [uuid.uuid4().hex for _ in points]
        with self._admit_lock:
            self.admission.check_queue(principal.name, runs)
            self.admission.check_storage(principal, req.inputs)
            self._create_sweep_jobs(req, grid, points, principal, sweep_id, job_ids)
        self._queue(job_ids, sweep_id)
        return sweep_id

    def _create_sweep_jobs(
        self,
        req: JobRequest,
        grid: dict,
        points: list[tuple[dict[str, Any], dict[str, int]]],
        principal: Principal,
        sweep_id: str,
        job_ids: list[str],
    ) -> None:
        """The sweep's jobs (one per grid point, ids given) and its record, or none of them."""
        with self._undone_on_error(job_ids, sweep_id):
            for job_id, (params, size) in zip(job_ids, points, strict=True):
                self.store.create_job(
                    job_id=job_id,
                    method=req.method,
                    params=params,
                    size=size,
                    seed=req.seed,
                    inputs=req.inputs,
                    sweep_id=sweep_id,
                    manifest={
                        **self.manifest(req),
                        "params": params,
                        "size": size,
                        "sweep_id": sweep_id,
                        "owner": principal.name,
                    },
                    owner=principal.name,
                    share_inputs_of=job_ids[0] if job_id != job_ids[0] else None,  # the upload stored once
                    extras=req.extras,
                )
            self.store.create_sweep(
                sweep_id, req.method, grid, req.params, job_ids, owner=principal.name, size=req.size
            )

    # -- reporting ----------------------------------------------------------------------------------

    # -- ownership ----------------------------------------------------------------------------------

    def visible_job(self, job_id: str, principal: Principal) -> JobRecord | None:
        """The job, if ``principal`` may see it (another owner's job is as good as absent: 404)."""
        job = self.store.get(job_id)
        if job is None or not principal.can_see(job.owner, job.id):
            return None
        return job

    def visible_sweep(self, sweep_id: str, principal: Principal) -> dict[str, Any] | None:
        sweep = self.store.get_sweep(sweep_id)
        if sweep is None or principal.job is not None or not principal.can_see(sweep.get("owner")):
            return None
        return sweep

    def remove(self, job_id: str) -> str:
        """``DELETE /api/jobs/{id}``: cancel a queued or running job; delete a finished one (its files
        and its record). Returns what happened: ``cancelled``, ``cancelling`` or ``deleted``."""
        job = self.store.get(job_id)
        if job is not None and job.state in TERMINAL:
            self.store.delete(job_id)  # (False only if another request deleted it first)
            return "deleted"
        job = self.store.request_cancel(job_id)
        if job is not None and job.state == "cancelled":
            # A queued message is dropped by the workers; if revoking fails, the record says cancelled
            # and a delivered message skips the job anyway.
            with contextlib.suppress(Exception):
                self.celery.control.revoke(job_id)
            return "cancelled"
        return "cancelling"

    # -- reporting ----------------------------------------------------------------------------------

    def job_public(self, job: JobRecord) -> dict[str, Any]:
        base = f"/api/jobs/{job.id}"
        end = job.finished or (time.time() if job.state == "running" else None)
        access = self.tokens.sign(job.id)
        signed = f"?access={access}" if access else ""
        names = job.extras.get("input_names", {})
        preview = None
        if job.preview_at and job.state == "running":
            preview = f"{base}/preview.png?t={int(job.preview_at * 1000)}" + (
                f"&access={access}" if access else ""
            )
        return {
            "id": job.id,
            "url": base,
            "page": f"/#/jobs/{job.id}",
            "state": job.state,
            "method": job.method,
            "params": job.params,
            "size": job.size,
            "seed": job.seed,
            "stage": job.stage,
            "fraction": job.fraction,
            "message": job.message,
            "cancel_requested": job.cancel_requested is not None,
            "attempts": job.attempts,
            "created": job.created,
            "started": job.started,
            "finished": job.finished,
            "elapsed": (end - job.started) if (end and job.started) else None,
            "timings": job.timings,
            "metrics": job.metrics,
            "artifacts": {name: f"{base}/artifacts/{name}{signed}" for name in job.artifacts},
            "inputs": {role: f"{base}/inputs/{role}{signed}" for role in job.inputs},
            "preview": preview,
            "sweep_id": job.sweep_id,
            "owner": job.owner,
            "access": access,
            # of the output once there is one, else of the exemplar: the query changes with it
            "thumbnail": f"{base}/thumbnail.png?of={'output' if 'output.png' in job.artifacts else 'input'}"
            + (f"&access={access}" if access else ""),
            "artifacts_zip": f"{base}/artifacts.zip{signed}" if job.artifacts else None,
            "exemplar_name": names.get("exemplar", names.get("exemplar_xy")),
            "input_names": names,
            "voxel_size": job.extras.get("voxel_size"),
            "voxel_unit": job.extras.get("voxel_unit"),
        }

    def sweep_public(self, sweep: dict[str, Any]) -> dict[str, Any]:
        rows, counts, metric_names = [], {}, []
        for job_id in sweep["job_ids"]:
            job = self.store.get(job_id)
            if job is None:
                continue
            counts[job.state] = counts.get(job.state, 0) + 1
            # a headline measure's value is summary.<name> already, its target and direction the glossary's:
            # of the headline, the table keeps the verdicts
            headline = job.metrics.get("headline", {})
            flat = _flatten({k: v for k, v in job.metrics.items() if k != "headline"})
            flat.update({f"headline.{k}.verdict": v.get("verdict") for k, v in headline.items()})
            metric_names += [k for k in flat if k not in metric_names]
            rows.append(
                {
                    "job": job.id,
                    "state": job.state,
                    **{k: job.size[k] if k in job.size else job.params.get(k) for k in sweep["grid"]},
                    **flat,
                    "access": self.tokens.sign(job.id),  # not a column: for the page's thumbnails
                }
            )
        active = counts.get("queued", 0) + counts.get("running", 0)
        return {
            "id": sweep["id"],
            "url": f"/api/sweeps/{sweep['id']}",
            "method": sweep["method"],
            "grid": sweep["grid"],
            "params": sweep["params"],
            "size": sweep["size"],
            "state": "running" if active else "done",
            "counts": counts,
            "columns": ["job", "state", *sweep["grid"], *metric_names],
            "rows": rows,
        }

    def start(self) -> None:
        if not self.reaper.is_alive():
            self.reaper.start()

    def stop(self) -> None:
        self.reaper.stop()


class BrokerUnavailable(RuntimeError):
    """The broker did not take the job (HTTP 503)."""


#: Deepest nesting of lists and objects accepted in ``params`` and ``grid`` (no parameter nests at
#: all; Python's JSON parser overflows its stack near 1000, which was a 500).
MAX_JSON_DEPTH = 32


def _parse_json(value: str | dict, field: str) -> Any:
    """Strict JSON: ``NaN``, ``Infinity`` and numbers beyond float range (``1e400``) are refused,
    naming the field (they would pass some parameter bounds and break the job record); so is nesting
    deeper than :data:`MAX_JSON_DEPTH`, judged from the text before it is parsed."""
    if isinstance(value, dict):
        document = value
    else:
        depth = _nesting(value or "")
        if depth > MAX_JSON_DEPTH:
            raise InvalidParameter(
                field, value[:80], f"is nested {depth} levels deep; at most {MAX_JSON_DEPTH} are accepted"
            )
        try:
            document = json.loads(value or "{}", parse_constant=_no_constant)
        except json.JSONDecodeError as exc:
            raise InvalidParameter(
                field, value[:80], f"is not valid JSON ({exc.msg} at position {exc.pos})"
            ) from None
        except ValueError as exc:
            raise InvalidParameter(field, value[:80], str(exc)) from None
    _check_finite(document, field)
    return document


def _nesting(text: str) -> int:
    """The deepest nesting of ``[`` and ``{`` in JSON ``text``, brackets inside strings not counted
    (an upper bound for text that is not valid JSON, which the parser then refuses)."""
    depth = deepest = 0
    for bracket in _BRACKETS.findall(_STRINGS.sub("", text)):
        depth += 1 if bracket in "[{" else -1
        deepest = max(deepest, depth)
    return deepest


_STRINGS = re.compile(r'"(?:\\.|[^"\\])*"')
_BRACKETS = re.compile(r"[\[\]{}]")


def _no_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a number JSON allows; give a finite number")


def _check_finite(value: Any, field: str) -> None:
    if isinstance(value, float) and not math.isfinite(value):
        raise InvalidParameter(field, str(value), "must be a finite number")
    if isinstance(value, dict):
        for key, item in value.items():
            _check_finite(item, f"{field}.{key}" if field != "params" else str(key))
    elif isinstance(value, list):
        for item in value:
            _check_finite(item, field)


def _parse_params(value: str | dict) -> dict[str, Any]:
    params = _parse_json(value, "params")
    if not isinstance(params, dict):
        raise InvalidParameter("params", params, 'must be a JSON object, e.g. {"levels": 3}')
    return dict(params)


def _take_size(spec: MethodSpec, params: dict[str, Any], given: Mapping[str, int | None] | None) -> dict:
    """The output's sides from the ``width``/``height``/``depth`` form fields (``given``) and, as the
    first clients sent them, from inside ``params``, where they are removed (a method parameter of one
    of those names stays a parameter). The same side given both ways must agree."""
    size = {k: params.pop(k) for k in SIZE_FIELDS if k in params and k not in spec.params_model.model_fields}
    for name, value in (given or {}).items():
        if value is None:
            continue
        if name in size and size[name] != value:
            raise InvalidParameter(name, value, f"given twice, {size[name]} in params and {value} as a field")
        size[name] = value
    return size


def _display_name(filename: str) -> str:
    """An upload's file name as lists show it: the last path part, printable, at most 120 characters."""
    name = filename.replace("\\", "/").rsplit("/", 1)[-1]
    return "".join(c for c in name if c.isprintable())[:120]


def _flatten(metrics: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    flat = {}
    for key, value in metrics.items():
        if isinstance(value, dict):
            flat.update(_flatten(value, f"{prefix}{key}."))
        elif isinstance(value, int | float | str | bool) or value is None:
            flat[f"{prefix}{key}"] = value
    return flat

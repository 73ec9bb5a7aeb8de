"""Admission control in one place: what the service takes on before anything is stored or queued.

:class:`Admission` is asked by :class:`texsynth.app.service.Service` after a submission's parameters and
images were validated (the engine's own checks: finite numbers, sizes, formats):

- **the job's working memory**, estimated from the method, its parameters, the output size and the
  decoded inputs, against ``TEXSYNTH_MAX_JOB_MEMORY_BYTES`` (422, naming the parameter that drives
  it). The estimate is generous on purpose: for an image the measured peak of a whole run of the
  method, fixed and per output pixel (:data:`IMAGE_MEMORY`) or voxel (:data:`VOLUME_MEMORY`), a
  generic term per input pixel
  (:data:`GENERIC_BYTES_PER_ELEMENT`), plus the terms that are known to
  explode: a rotated dictionary's copies (``angular_step``) and its k-coherence sets. The engine
  still checks the k-coherence sets itself in the worker (``texsynth.synth.methods.arbitrary_shape``); here
  the same bound is applied before queueing, so the person gets the 422 at once;
- **the job's run time**, estimated from the method's measured rate per output element on one core and
  its measured 2-thread speed-up, for the threads a job gets (``TEXSYNTH_THREADS``), against the soft time
  limit (``TEXSYNTH_SOFT_TIME_LIMIT``, 422 naming the output size): a job the worker would stop after
  30 minutes anyway is refused at once. Either refusal states both estimates;
- **an exemplar much larger than the output** (422): above 512x512 pixels an exemplar may have at
  most ``TEXSYNTH_MAX_INPUT_OUTPUT_RATIO`` times the output's pixels (a 4096^2 exemplar for a 64^2
  output spends minutes loading for nothing);
- **a sweep's size**: runs (``TEXSYNTH_MAX_SWEEP_RUNS``) and output pixels of all runs together
  (``TEXSYNTH_MAX_SWEEP_PIXELS``), 422;
- **the owner's queue**: queued + running jobs per token (``TEXSYNTH_MAX_QUEUED_PER_TOKEN``), 429.
  Without tokens every client is the one anonymous owner, so the limit caps the whole queue;
- **the owner's storage**: bytes of inputs and artifacts its jobs keep (``TEXSYNTH_TOKEN_QUOTA_BYTES``
  or the token entry's ``quota=``): 507 when this submission's inputs do not fit, 413 when they alone
  exceed the quota.

Every refusal names the limit, the setting that raises it, and what to change.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from fastapi import HTTPException

from texsynth.app.auth import Principal
from texsynth.jobs.config import Settings
from texsynth.jobs.store import JobStore
from texsynth.synth.errors import InvalidInput, InvalidParameter

__all__ = ["Admission", "QuotaExceeded", "estimate_memory", "estimate_seconds", "parallel_fraction"]

#: Seconds a client refused for a full queue is told to wait (``Retry-After`` on the 429): a hint, about
#: the time a small job takes; the refusal stores nothing, so trying again later is always safe.
QUEUE_RETRY_AFTER = 10

#: Bytes of working memory per input pixel, the generic term (float32 arrays: the image and its pyramid,
#: feature and distance buffers, tensor fields).
GENERIC_BYTES_PER_ELEMENT = 48
#: A 2-D job's peak memory by method, ``(fixed bytes, bytes per output pixel)``: the whole
#: ``texsynth synthesize`` process' ``VmHWM`` (interpreter and compiled kernels, synthesis, pictures,
#: evaluation and plots) of ``python -m benchmarks.bench_memory --method M --size SxS --threads 2`` runs
#: from the 128^2 laminar HRTEM exemplar at 512^2 and 1024^2 (and 4096^2 for tensor-constrained): the
#: per-pixel term is 1.1 times the slope between the two largest sizes, rounded up to 10; the fixed term the
#: rest of the largest peak, rounded up to 16 MiB (docs/benchmarks.md, "Big outputs: 2-D images"). The
#: input pixels and a rotated dictionary are counted on top. Never below a measured peak
#: (tests/service/test_admission.py pins the measurements).
IMAGE_MEMORY: dict[str, tuple[int, int]] = {
    "arbitrary-shape": (416 * 2**20, 150),
    "feature-guided": (336 * 2**20, 190),
    "gaussian-patch": (304 * 2**20, 150),
    "quilting": (304 * 2**20, 150),
    "random-phase": (272 * 2**20, 150),
    "tensor-constrained": (304 * 2**20, 220),
    "wei-levoy": (304 * 2**20, 150),
}
#: A 2-D method missing from :data:`IMAGE_MEMORY` counts as the largest of each term.
IMAGE_MEMORY_DEFAULT: tuple[int, int] = (
    max(fixed for fixed, _ in IMAGE_MEMORY.values()),
    max(per_pixel for _, per_pixel in IMAGE_MEMORY.values()),
)
#: A volume job's peak memory by method, ``(fixed bytes, bytes per output voxel)``: the whole
#: ``texsynth synthesize`` process' ``VmHWM`` (synthesis, TIFF, pictures, evaluation, plots) of
#: ``python -m benchmarks.bench_memory --method M --size SxSxS --threads 2`` runs from the 128^2 laminar
#: HRTEM exemplar, and of a 512^3 ``solid-kopf`` job of the service (its worker's ``VmHWM``): the per-voxel
#: term is 1.1 times the slope between the two largest sizes, rounded up to 10; the fixed term the largest
#: rest of a peak, rounded up to 16 MiB (``benchmarks.bench_memory.admission_terms``; docs/benchmarks.md,
#: "Big outputs: volumes"). Never below a measured peak (tests/service/test_admission.py pins them).
VOLUME_MEMORY: dict[str, tuple[int, int]] = {
    "solid-chen-wang": (336 * 2**20, 140),
    "solid-kopf": (352 * 2**20, 70),
    "solid-wei-levoy": (352 * 2**20, 180),
}
#: A volume method missing from :data:`VOLUME_MEMORY` counts as the largest of each term.
VOLUME_MEMORY_DEFAULT: tuple[int, int] = (
    max(fixed for fixed, _ in VOLUME_MEMORY.values()),
    max(per_voxel for _, per_voxel in VOLUME_MEMORY.values()),
)
#: A method's synthesis speed-up from 1 to 2 threads on the project's 2-core machine, quiet (``python -m
#: benchmarks.bench_threads``; docs/benchmarks.md, "Threads"; the largest size measured). The run-time
#: estimate takes the fraction ``f = 2 (1 - 1 / s)`` of the work as parallel (Amdahl) and the rest as
#: serial; a method missing here is taken to scale perfectly (``s = 2``: a lower bound of its time).
TWO_THREAD_SPEEDUP: dict[str, float] = {
    "arbitrary-shape": 1.75,
    "feature-guided": 1.01,
    "gaussian-patch": 1.04,
    "quilting": 1.31,
    "random-phase": 1.61,
    "solid-chen-wang": 1.67,
    "solid-kopf": 1.89,
    "solid-wei-levoy": 1.88,
    "tensor-constrained": 1.71,
    "wei-levoy": 1.72,
}
#: Exemplars up to this many pixels are always accepted, whatever the output's size.
SMALL_EXEMPLAR = 512 * 512


def _gib(n: float) -> str:
    return f"{n / 2**30:.1f} GiB"


def _size(n: float) -> str:
    for unit, scale in (("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if n >= scale:
            return f"{n / scale:.1f} {unit}"
    return f"{int(n)} bytes"


class QuotaExceeded(Exception):
    """A submission that the owner's storage quota has no room for (HTTP 507, or 413 when the
    submission alone is larger than the quota)."""

    def __init__(self, status: int, detail: str) -> None:
        super().__init__(detail)
        self.status = status
        self.detail = detail


def estimate_memory(
    params: Mapping[str, Any],
    size: Mapping[str, int],
    shapes: Mapping[str, Sequence[int]],
    method: str | None = None,
) -> tuple[int, str, str]:
    """``(bytes, the parameter that drives them, why)``: a generous estimate of a job's peak memory.

    ``shapes`` are the decoded inputs' array shapes by role, ``size`` the output's sides, ``method`` the
    method's name: a 2-D output counts the method's measured :data:`IMAGE_MEMORY`.
    """
    out = math.prod(size.values())
    inputs = sum(math.prod(s[:2]) for s in shapes.values())
    fixed, per_pixel = IMAGE_MEMORY.get(method or "", IMAGE_MEMORY_DEFAULT)
    total = fixed + per_pixel * out + GENERIC_BYTES_PER_ELEMENT * inputs
    driver, why = (
        "width",
        f"{per_pixel} bytes per pixel of the {size.get('width')}x{size.get('height')} output and "
        f"{_size(fixed)} for the process, as measured, and {GENERIC_BYTES_PER_ELEMENT} per input pixel",
    )
    if "depth" in size:
        fixed, per_pixel = VOLUME_MEMORY.get(method or "", VOLUME_MEMORY_DEFAULT)
        total = fixed + per_pixel * out + GENERIC_BYTES_PER_ELEMENT * inputs
        sides = "x".join(str(size[k]) for k in ("width", "height", "depth"))
        driver, why = (
            "depth",
            f"{per_pixel} bytes per voxel of the {sides} volume and {_size(fixed)} for the process, "
            f"as measured, and {GENERIC_BYTES_PER_ELEMENT} per input pixel",
        )
    step = params.get("angular_step")
    exemplar = shapes.get("exemplar")
    if isinstance(step, int | float) and step > 0 and exemplar is not None:
        # A rotated dictionary (texsynth.synth.analysis.rotation): M copies, each on a square tile of the
        # exemplar's diagonal, holding the image, its tensors and a mask, plus its features and pyramid.
        rotations = round(360.0 / step)
        h, w = exemplar[:2]
        channels = exemplar[2] if len(exemplar) > 2 else 1
        side = math.ceil(math.hypot(h, w)) + 4
        dictionary = rotations * side * side * (channels + 4) * 4 * 2
        if params.get("k", 0) and params.get("search") != "exact":
            ks = min(int(params.get("neighbourhood_size", 9)), 9)
            dictionary += rotations * h * w * ks * ks * (channels + 3) * 12  # the engine's k-set bound
        total += dictionary
        if dictionary > per_pixel * out:
            driver, why = (
                "angular_step",
                f"{rotations} rotated copies of the {w}x{h} exemplar (angular_step={step:g})",
            )
    return int(total), driver, why


def parallel_fraction(speedup: float) -> float:
    """The parallel fraction ``f`` of a run that speeds up ``speedup`` times from 1 to 2 threads (Amdahl:
    ``s = 1 / (1 - f + f / 2)``, so ``f = 2 (1 - 1 / s)``), clipped to [0, 1].

    >>> parallel_fraction(2.0), parallel_fraction(1.0)
    (1.0, 0.0)
    """
    return min(1.0, max(0.0, 2.0 * (1.0 - 1.0 / max(float(speedup), 1e-9))))


def estimate_seconds(
    seconds_per_element: float, elements: int, threads: int, method: str | None = None
) -> float:
    """A job's run time: the method's one-core rate times the output's elements, its parallel part
    (:func:`parallel_fraction` of its measured :data:`TWO_THREAD_SPEEDUP`) divided by the job's threads.
    A method without a measured speed-up counts a perfect one (a lower bound)."""
    if isinstance(threads, bool) or not isinstance(threads, int) or threads < 1:
        raise InvalidParameter("threads", threads, "must be a whole number of threads, at least 1")
    if not math.isfinite(seconds_per_element) or seconds_per_element < 0:
        raise InvalidParameter("seconds_per_element", seconds_per_element, "must be a finite rate >= 0")
    share = parallel_fraction(TWO_THREAD_SPEEDUP.get(method or "", 2.0))
    return seconds_per_element * elements * ((1.0 - share) + share / threads)


class Admission:
    """The service's limits, applied to one submission (see the module's docstring)."""

    def __init__(self, settings: Settings, store: JobStore) -> None:
        self.settings = settings
        self.store = store

    def check_job(
        self,
        method: str,
        params: Mapping[str, Any],
        size: Mapping[str, int],
        shapes: Mapping[str, Sequence[int]],
        *,
        field_prefix: str = "",
        seconds_per_element: float = 0.0,
    ) -> None:
        """Memory, time and exemplar-to-output checks of one run; raises the engine's 422 errors.

        ``seconds_per_element``: the method's measured rate (``MethodSpec.seconds_per_element``).
        """
        limit = self.settings.max_job_memory_bytes
        need, driver, why = estimate_memory(params, size, shapes, method)
        elements = math.prod(size.values())
        threads = max(1, self.settings.threads or 1)
        seconds = estimate_seconds(seconds_per_element, elements, threads, method)
        speedup = TWO_THREAD_SPEEDUP.get(method)
        split = (
            f"{parallel_fraction(speedup):.0%} of it parallel, from the measured {speedup:.2f}x of 2 threads"
            if speedup is not None
            else "split perfectly between the threads"
        )
        timing = (
            f"about {seconds / 60:.0f} minutes with {threads} thread{'s' if threads > 1 else ''} "
            f"({elements} output elements at {seconds_per_element:.1e} s each on one core of the "
            f"project's machine, {split})"
        )
        if need > limit:
            raise InvalidParameter(
                field_prefix + driver,
                params.get(driver, size.get(driver)),
                f"{method} with these settings would need about {_gib(need)} of memory ({why}), more than "
                f"this service's limit of {_gib(limit)} per job (TEXSYNTH_MAX_JOB_MEMORY_BYTES)"
                + (f", and would run {timing}" if seconds_per_element > 0 else "")
                + "; ask for a smaller output, a smaller exemplar or a coarser setting",
            )
        if seconds > self.settings.soft_time_limit:
            side = "depth" if "depth" in size else "width"
            raise InvalidParameter(
                field_prefix + side,
                size[side],
                f"{method} would run {timing}, more than this service's time limit of "
                f"{self.settings.soft_time_limit / 60:.0f} minutes per job (TEXSYNTH_SOFT_TIME_LIMIT; "
                f"it would need about {_gib(need)} of memory); ask for a smaller output",
            )
        out = math.prod(v for k, v in size.items() if k != "depth")
        ratio = self.settings.max_input_output_ratio
        for role, shape in shapes.items():
            pixels = math.prod(shape[:2])
            if role.startswith("exemplar") and pixels > SMALL_EXEMPLAR and pixels > ratio * out:
                raise InvalidInput(
                    role,
                    f"the {shape[1]}x{shape[0]} {role} has {pixels / out:.0f} times the pixels of the "
                    f"{size['width']}x{size['height']} output; at most {ratio} times is accepted for "
                    f"exemplars above 512x512 (TEXSYNTH_MAX_INPUT_OUTPUT_RATIO): crop or downscale the "
                    "exemplar, or ask for a larger output",
                )

    def check_sweep(self, runs: int, pixels: int) -> None:
        """A sweep's number of runs and all its runs' output pixels together (422)."""
        if runs > self.settings.max_sweep_runs:
            raise InvalidParameter(
                "grid",
                runs,
                f"{runs} runs is more than the limit of {self.settings.max_sweep_runs} runs per sweep "
                "(TEXSYNTH_MAX_SWEEP_RUNS); sweep fewer values",
            )
        if pixels > self.settings.max_sweep_pixels:
            raise InvalidParameter(
                "grid",
                runs,
                f"the {runs} runs make {pixels} output pixels together, more than the limit of "
                f"{self.settings.max_sweep_pixels} per sweep (TEXSYNTH_MAX_SWEEP_PIXELS); "
                "sweep fewer values or ask for a smaller output",
            )

    def check_queue(self, owner: str | None, new_jobs: int) -> None:
        """The owner's queued + running jobs, with ``new_jobs`` more, within the limit (else 429)."""
        limit = self.settings.max_queued_per_token
        active = self.store.count_active(owner)
        if active + new_jobs > limit:
            who = f"token '{owner}'" if owner else "this service (no tokens: one queue for everyone)"
            room = max(0, limit - active)
            raise HTTPException(
                429,
                f"too many jobs queued: {who} has {active} queued or running, and at most {limit} are "
                f"allowed (TEXSYNTH_MAX_QUEUED_PER_TOKEN); this submission adds {new_jobs}, room for "
                f"{room}. Wait for some to finish, or cancel some",
                headers={"Retry-After": str(QUEUE_RETRY_AFTER)},
            )

    def check_storage(self, principal: Principal, inputs: Mapping[str, tuple[str, bytes]]) -> None:
        """The owner's stored bytes with these inputs added within its quota (else
        :class:`QuotaExceeded`); a quota of 0 means none."""
        quota = self.settings.token_quota_bytes if principal.quota is None else principal.quota
        if quota <= 0:
            return
        adding = sum(len(data) for _, data in inputs.values())
        who = f"token '{principal.name}'" if principal.name else "this service (no tokens: one quota for all)"
        setting = "its token entry's quota=" if principal.quota is not None else "TEXSYNTH_TOKEN_QUOTA_BYTES"
        if adding > quota:
            raise QuotaExceeded(
                413,
                f"this upload of {_size(adding)} alone is larger than the storage quota of {who}, "
                f"{_size(quota)} ({setting}); upload a smaller image",
            )
        used = self.store.usage(principal.name)
        if used + adding > quota:
            raise QuotaExceeded(
                507,
                f"storage quota reached: {who} keeps {_size(used)} of inputs and artifacts, and this "
                f"upload adds {_size(adding)}, more than its quota of {_size(quota)} ({setting}). "
                "Download what you need and delete finished jobs (DELETE /api/jobs/{id}) to make room",
            )

"""A small, real method for the service tests: ``test-blur`` (registered through TEXSYNTH_EXTRA_METHODS).

It tiles the exemplar to the output size and blurs it in ``steps`` steps, sleeping ``delay`` seconds
per step and reporting progress (with a preview) after each: a job whose duration the tests choose,
to watch progress, cancel it, or kill its worker mid-run. Deterministic for a given input and seed.
"""

from __future__ import annotations

import time

import numpy as np
from pydantic import Field
from scipy import ndimage as ndi

from texsynth.synth.analysis.tensor import structure_tensor
from texsynth.synth.api import MethodSpec, Result, register
from texsynth.synth.errors import InvalidParameter
from texsynth.synth.params import MethodParams


class BlurParams(MethodParams):
    steps: int = Field(10, ge=1, le=1000, description="blur steps (one progress report each)")
    delay: float = Field(0.05, ge=0.0, le=10.0, description="seconds of sleep per step")
    sigma: float = Field(0.5, gt=0.0, le=10.0, description="Gaussian blur per step, in pixels")
    fail: str = Field("", max_length=200, description="when set, the run fails after one step with this")


def _run(exemplar, *, size, params: BlurParams, seed, progress, constraint=None) -> Result:
    start = time.perf_counter()
    reps = [int(np.ceil(s / e)) for s, e in zip(size, exemplar.shape[:2], strict=True)]
    image = np.tile(exemplar, reps + [1] * (exemplar.ndim - 2))[: size[0], : size[1]]
    rng = np.random.default_rng(seed)
    image = np.roll(image, (int(rng.integers(size[0])), int(rng.integers(size[1]))), axis=(0, 1))
    accepts_preview = getattr(progress, "accepts_preview", False)
    for step in range(params.steps):
        sigma = (params.sigma, params.sigma, 0) if image.ndim == 3 else params.sigma
        image = ndi.gaussian_filter(image, sigma, mode="wrap")
        if params.delay:
            time.sleep(params.delay)
        kwargs = {"preview": image} if accepts_preview else {}
        progress(f"blur step {step + 1}/{params.steps}", (step + 1) / params.steps, **kwargs)
        if params.fail:
            raise InvalidParameter("fail", params.fail, "the test method was asked to fail")
    image = np.ascontiguousarray(image, dtype=np.float32)
    grey = image.mean(axis=2) if image.ndim == 3 else image
    return Result(
        method="test-blur",
        image=image,
        params=params.model_dump(),
        seed=seed,
        timings={"blur": time.perf_counter() - start},
        tensor_field=structure_tensor(grey),
        stats={"steps": params.steps},
    )


register(
    MethodSpec(
        name="test-blur",
        summary="Tile and blur (service tests only)",
        params_model=BlurParams,
        run=_run,
        constraint="optional",
    )
)


class StackParams(MethodParams):
    delay: float = Field(0.0, ge=0.0, le=10.0, description="seconds of sleep before returning")


def _run_stack(
    exemplar, *, size, params: StackParams, seed, progress, constraint=None, exemplars=None
) -> Result:
    """A volume whose xy slices repeat the xy exemplar (tiled), each z-slice shifted by one pixel."""
    depth, height, width = size
    xy = exemplars["xy"]
    reps = [int(np.ceil(s / e)) for s, e in zip((height, width), xy.shape, strict=True)]
    plane = np.tile(xy, reps)[:height, :width]
    volume = np.stack([np.roll(plane, z, axis=1) for z in range(depth)]).astype(np.float32)
    time.sleep(params.delay)
    progress("stacking", 1.0)
    return Result("test-stack", volume, params.model_dump(), seed, {"stack": 0.0})


register(
    MethodSpec(
        name="test-stack",
        summary="Stack shifted copies of the xy exemplar into a volume (service tests only)",
        params_model=StackParams,
        run=_run_stack,
        output_ndim=3,
        plane_exemplars=True,
    )
)

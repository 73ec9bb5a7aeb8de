"""Response models of the REST API, one group per resource (Public / ListPublic {data, count})."""

from __future__ import annotations

from enum import StrEnum
from typing import Any

from pydantic import BaseModel, Field

from texsynth.jobs.store import STATES

__all__ = [
    "DeletedPublic",
    "ErrorPublic",
    "ExamplePublic",
    "FieldError",
    "HealthPublic",
    "JobPublic",
    "JobState",
    "JobsPublic",
    "MethodPublic",
    "MethodsPublic",
    "SweepPublic",
]


class FieldError(BaseModel):
    """One bad field of a ``422`` (FastAPI's shape)."""

    loc: list[str | int] = Field(
        description="where: ['params', NAME] for a method's parameter, ['body', NAME] for another form "
        "field or an input image, ['query', NAME] for a list's filter"
    )
    msg: str = Field(description="what is wrong with it, one line")
    type: str = Field(description="machine-readable kind")
    input: Any = Field(None, description="the value given, when it is a plain value")


class ErrorPublic(BaseModel):
    detail: str | list[FieldError] = Field(
        description="what is wrong and what to do about it; a 422 lists one entry per bad field"
    )
    field: str | None = Field(None, description="the form field or parameter at fault (the first one)")
    error: str = Field(description="machine-readable kind: input_too_large, unsupported_format, ...")
    message: str | None = Field(None, description="a 422's entries as one line of text")


class ExamplePublic(BaseModel):
    name: str
    title: str
    kind: str = Field(description="2d (an exemplar) or constraint (a constraint image)")
    credit: str
    licence: str = Field(description="SPDX identifier: CC0-1.0 or MIT")
    url: str = Field(description="the PNG")
    thumbnail: str = Field(description="a small PNG for a gallery")
    suggested_method: str
    has_fringes: bool = Field(
        description="whether the image has lattice fringes (texsynth.synth.evaluate.glossary.fringes_shown): "
        "a job "
        "on it reports fringe statistics"
    )


class JobState(StrEnum):
    """A job's state (texsynth.jobs.store.STATES): queued -> running -> succeeded, failed or cancelled."""

    queued = "queued"
    running = "running"
    succeeded = "succeeded"
    failed = "failed"
    cancelled = "cancelled"


assert tuple(state.value for state in JobState) == STATES, "JobState must list texsynth.jobs.store.STATES"


class JobPublic(BaseModel):
    id: str
    url: str
    page: str
    state: JobState = Field(description="queued, running, succeeded, failed or cancelled")
    method: str
    params: dict[str, Any] = Field(description="the method's parameters")
    size: dict[str, int] = Field(description="the output's width, height (and depth)")
    seed: int
    stage: str
    fraction: float = Field(description="progress in [0, 1]")
    message: str = Field(description="why the job failed, or what happened to it")
    cancel_requested: bool
    attempts: int
    created: float
    started: float | None
    finished: float | None
    elapsed: float | None
    timings: dict[str, float]
    metrics: dict[str, Any]
    artifacts: dict[str, str] = Field(description="artifact name -> URL")
    inputs: dict[str, str] = Field(description="input role -> URL")
    preview: str | None = Field(None, description="URL of a small preview of the running synthesis")
    sweep_id: str | None = None
    owner: str | None = Field(None, description="the name of the token that submitted it (tokens set)")
    access: str | None = Field(
        None,
        description="with tokens: the signed query (?access=...) that opens this job's files without "
        "a header until it expires; the file URLs above already carry it",
    )
    thumbnail: str | None = Field(
        None, description="URL of a small PNG: of the output once there is one, else of the exemplar"
    )
    artifacts_zip: str | None = Field(None, description="URL of a zip of every artifact (once there are any)")
    exemplar_name: str | None = Field(None, description="the file name the exemplar was uploaded under")
    input_names: dict[str, str] = Field(default_factory=dict, description="input role -> uploaded file name")
    voxel_size: float | None = Field(None, description="a volume's voxel size (TIFF calibration); None: none")
    voxel_unit: str | None = Field(None, description="the unit of voxel_size")


class DeletedPublic(BaseModel):
    id: str
    state: str = Field(description="deleted")
    message: str


class JobsPublic(BaseModel):
    data: list[JobPublic]
    count: int


class MethodPublic(BaseModel):
    name: str
    summary: str
    paper: str
    inputs: dict[str, str] = Field(
        description="input images by multipart field: required, optional, or alternative (the per-plane "
        "exemplars exemplar_xy/exemplar_xz/exemplar_yz of solid methods, all three instead of 'exemplar')"
    )
    constraint: str = Field(description="none, optional or required")
    output_ndim: int
    params_schema: dict[str, Any]
    size_schema: dict[str, Any]


class MethodsPublic(BaseModel):
    data: list[MethodPublic]
    count: int


class SweepPublic(BaseModel):
    id: str
    url: str
    method: str
    grid: dict[str, list[Any]]
    params: dict[str, Any]
    size: dict[str, int] = Field(description="the output size of every run (unless swept in grid)")
    state: str = Field(description="running until every job ended, then done")
    counts: dict[str, int]
    columns: list[str]
    rows: list[dict[str, Any]] = Field(description="one row per run: job id, state, its grid values, metrics")


class HealthPublic(BaseModel):
    status: str
    api: bool
    broker: bool
    broker_url: str
    workers: list[str]
    queued: int
    running: int
    message: str

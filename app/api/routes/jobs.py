"""``/api/jobs``: submit, list, report, cancel; artifacts, inputs and previews are plain GETs."""

from __future__ import annotations

import mimetypes
import os
import tempfile
import time
import zipfile
from functools import lru_cache
from typing import Annotated, Any

import numpy as np
from fastapi import APIRouter, Depends, File, Form, HTTPException, Query, Response, UploadFile
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, JSONResponse, StreamingResponse
from starlette.background import BackgroundTask

from texsynth.app.api.deps import PrincipalDep, ServiceDep
from texsynth.app.auth import Principal
from texsynth.app.schemas import DeletedPublic, ErrorPublic, JobPublic, JobsPublic
from texsynth.app.service import VOXEL_UNITS, Service, Upload
from texsynth.jobs.store import STATES, JobRecord
from texsynth.synth.io import FORMAT_FILES, image_to_png_bytes, load_volume, sniff_format

router = APIRouter(prefix="/api/jobs", tags=["jobs"])

_ERRORS = {
    401: {"model": ErrorPublic, "description": "no token, or one the service does not know (tokens set)"},
    403: {"model": ErrorPublic, "description": "a browser's cross-origin request (CSRF) refused"},
    413: {"model": ErrorPublic, "description": "upload or image too large"},
    415: {"model": ErrorPublic, "description": "not an image format texsynth reads"},
    422: {"model": ErrorPublic, "description": "bad parameter or unusable image (the field is named)"},
    429: {"model": ErrorPublic, "description": "the token's limit of queued jobs is reached"},
}
_NOT_FOUND = {404: {"model": ErrorPublic, "description": "no such job (or another token's)"}}
_BINARY = {"schema": {"type": "string", "format": "binary"}}


def _file_answer(description: str, *media_types: str) -> dict[int | str, dict[str, Any]]:
    """A ``200`` whose body is a file of one of ``media_types`` (the real ones, not JSON)."""
    content = {
        media: ({"schema": {"type": "object"}} if media == "application/json" else _BINARY)
        for media in media_types
    }
    return {200: {"description": description, "content": content}, **_NOT_FOUND}


def _plane_file(plane: str, fixed: str) -> Any:
    return Annotated[
        UploadFile | None,
        File(
            description=f"solid methods, instead of 'exemplar' (anisotropic materials): what the {plane} "
            f"slices (fixed {fixed}) look like; all three per-plane exemplars come together"
        ),
    ]


def read_uploads(
    exemplar: Annotated[UploadFile | None, File(description="the exemplar image (PNG, TIFF, JPEG)")] = None,
    constraint: Annotated[
        UploadFile | None, File(description="constraint image, for methods that take one")
    ] = None,
    exemplar_xy: _plane_file("xy", "z") = None,
    exemplar_xz: _plane_file("xz", "y") = None,
    exemplar_yz: _plane_file("yz", "x") = None,
) -> list[Upload]:
    """The uploaded images by role: each multipart field's name is its role (a FastAPI dependency of
    every route that takes a job's inputs, so they all accept the same fields)."""
    files = {
        "exemplar": exemplar,
        "constraint": constraint,
        "exemplar_xy": exemplar_xy,
        "exemplar_xz": exemplar_xz,
        "exemplar_yz": exemplar_yz,
    }
    return [
        Upload(role, upload.filename or "", upload.file.read())
        for role, upload in files.items()
        if upload is not None
    ]


UploadsDep = Annotated[list[Upload], Depends(read_uploads)]


def read_size(
    width: Annotated[int | None, Form(description="output width (pixels); default 128")] = None,
    height: Annotated[int | None, Form(description="output height (pixels); default 128")] = None,
    depth: Annotated[int | None, Form(description="output depth (slices), solid methods; default 64")] = None,
    voxel_size: Annotated[
        float | None,
        Form(description="solid methods: the size of a voxel, written into the TIFF stack (ImageJ spacing)"),
    ] = None,
    voxel_unit: Annotated[
        str | None, Form(description=f"the unit of voxel_size: {', '.join(VOXEL_UNITS)}; default nm")
    ] = None,
) -> dict[str, Any]:
    """The output size's form fields (a FastAPI dependency of the routes that submit jobs), and a
    volume's calibration. Clients of the first API send the sides inside ``params``; both are accepted."""
    size: dict[str, Any] = {"width": width, "height": height, "depth": depth}
    if voxel_size is not None or voxel_unit:
        size.update(voxel_size=voxel_size, voxel_unit=voxel_unit or None)
    return size


SizeDep = Annotated[dict[str, Any], Depends(read_size)]


@router.post("", status_code=202, response_model=JobPublic, responses=_ERRORS)
def submit_job(
    service: ServiceDep,
    principal: PrincipalDep,
    response: Response,
    uploads: UploadsDep,
    size: SizeDep,
    method: Annotated[str, Form(min_length=1, description="a method name from GET /api/methods")],
    params: Annotated[str, Form(description="JSON object: the method's parameters")] = "{}",
    seed: Annotated[int | None, Form(description="random seed; same inputs + seed = same output")] = None,
) -> dict:
    """Validate and queue a synthesis job; ``202`` with the job's URL in ``Location``."""
    request = service.validate(method, params, seed, uploads, size)
    job = service.submit(request, principal)
    response.headers["Location"] = f"/api/jobs/{job.id}"
    return service.job_public(job)


@router.get("", response_model=JobsPublic)
def list_jobs(
    service: ServiceDep,
    principal: PrincipalDep,
    state: Annotated[str | None, Query(description=f"one of {', '.join(STATES)}")] = None,
    method: Annotated[str | None, Query(description="a method name: only its jobs")] = None,
    limit: Annotated[int, Query(ge=1, le=500)] = 50,
    offset: Annotated[int, Query(ge=0, le=2**31)] = 0,
) -> dict:
    """Jobs, newest first: the token's own (an admin's: everyone's); ``state`` and ``method`` filter,
    ``limit`` and ``offset`` page (``count`` is the number matching the filters)."""
    if state is not None and state not in STATES:
        raise RequestValidationError(
            [{"loc": ("query", "state"), "msg": f"must be one of {', '.join(STATES)}, not {state!r}"}]
        )
    if method is not None and method not in service.methods():
        known = ", ".join(sorted(service.methods()))
        raise RequestValidationError([{"loc": ("query", "method"), "msg": f"must be one of {known}"}])
    jobs, count = service.store.list(
        state=state, method=method, owner=principal.owner_filter, limit=limit, offset=offset
    )
    return {"data": [service.job_public(j) for j in jobs], "count": count}


def _job(service: ServiceDep, job_id: str, principal: Principal):
    job = service.visible_job(job_id, principal)
    if job is None:
        raise HTTPException(404, f"no job with id {job_id!r}; list jobs with GET /api/jobs")
    return job


@router.get("/{job_id}", response_model=JobPublic, responses=_NOT_FOUND)
def get_job(service: ServiceDep, principal: PrincipalDep, job_id: str) -> dict:
    """State, progress, timings, error message and artifact URLs of one job."""
    return service.job_public(_job(service, job_id, principal))


@router.delete(
    "/{job_id}",
    status_code=202,
    response_model=JobPublic,
    responses={
        **_NOT_FOUND,
        200: {"model": DeletedPublic, "description": "a finished job: its files and record are deleted"},
        202: {"model": JobPublic, "description": "a queued or running job: cancelled (or being stopped)"},
    },
)
def delete_job(service: ServiceDep, principal: PrincipalDep, job_id: str):
    """Cancel a queued or running job (``202``, the job); delete a finished one (``200``): its inputs,
    artifacts and record are gone. To delete a running job, DELETE it twice: cancel, then delete."""
    _job(service, job_id, principal)
    outcome = service.remove(job_id)
    if outcome == "deleted":
        return JSONResponse(
            {"id": job_id, "state": "deleted", "message": "the job's files and record are deleted"}
        )
    job = service.store.get(job_id)
    if job is None:  # deleted by a concurrent request
        raise HTTPException(404, f"no job with id {job_id!r}; list jobs with GET /api/jobs")
    return service.job_public(job)


@router.get(
    "/{job_id}/artifacts/{name:path}",
    response_class=FileResponse,
    responses=_file_answer(
        "the file: PNG images, TIFF images and stacks, JSON metrics and manifest (by the name's extension)",
        "image/png",
        "image/tiff",
        "application/json",
    ),
)
def get_artifact(service: ServiceDep, principal: PrincipalDep, job_id: str, name: str) -> FileResponse:
    """One artifact of a succeeded job (names are listed in the job's ``artifacts``)."""
    job = _job(service, job_id, principal)
    if name not in job.artifacts:
        listed = ", ".join(job.artifacts) or f"none yet (the job is {job.state})"
        raise HTTPException(404, f"job {job_id} has no artifact {name!r}; artifacts: {listed}")
    filename = name.rsplit("/", 1)[-1] if not name.endswith(".png") else None
    path = service.store.storage.local_path(job_id, f"out/{name}", job.artifacts_run)
    if path is not None:
        return FileResponse(path, filename=filename)
    return _stream(service, job, f"out/{name}", mimetypes.guess_type(name)[0], filename)


def _stream(
    service: Service,
    job: JobRecord,
    rel: str,
    media_type: str | None,
    filename: str | None = None,
    headers: dict[str, str] | None = None,
) -> StreamingResponse:
    """A file from the object store, streamed (never written to the API's disk)."""
    try:
        chunks, size = service.store.storage.open(job.id, rel, job.artifacts_run)
    except FileNotFoundError:
        raise HTTPException(404, f"job {job.id} has no file {rel!r} (yet)") from None
    headers = {"Content-Length": str(size), **(headers or {})}
    if filename is not None:
        headers["Content-Disposition"] = f'attachment; filename="{filename}"'
    return StreamingResponse(chunks, media_type=media_type or "application/octet-stream", headers=headers)


@router.get(
    "/{job_id}/artifacts.zip",
    response_class=FileResponse,
    responses=_file_answer("every artifact of the job in one zip", "application/zip"),
)
def get_artifacts_zip(service: ServiceDep, principal: PrincipalDep, job_id: str) -> FileResponse:
    """Every artifact of a finished job in one zip (``<job id>.zip``), under the folder ``<job id>/``."""
    job = _job(service, job_id, principal)
    if not job.artifacts:
        raise HTTPException(404, f"job {job_id} has no artifacts (it is {job.state})")
    storage = service.store.storage
    handle = tempfile.NamedTemporaryFile(prefix="texsynth-", suffix=".zip", delete=False)  # noqa: SIM115
    try:
        with handle, zipfile.ZipFile(handle, "w") as archive:
            for name in job.artifacts:
                # PNG and TIFF are compressed already: stored; JSON deflated
                kind = zipfile.ZIP_DEFLATED if name.endswith(".json") else zipfile.ZIP_STORED
                path = storage.local_path(job_id, f"out/{name}", job.artifacts_run)
                if path is not None:
                    archive.write(path, f"{job_id}/{name}", compress_type=kind)
                    continue
                chunks, _ = storage.open(job_id, f"out/{name}", job.artifacts_run)  # an object store
                info = zipfile.ZipInfo(f"{job_id}/{name}", time.localtime(job.finished or time.time())[:6])
                info.compress_type = kind
                with archive.open(info, "w") as member:
                    for chunk in chunks:
                        member.write(chunk)
    except BaseException:
        os.unlink(handle.name)
        raise
    return FileResponse(
        handle.name,
        media_type="application/zip",
        filename=f"texsynth-{job_id}.zip",
        background=BackgroundTask(os.unlink, handle.name),
    )


@router.get(
    "/{job_id}/thumbnail.png",
    response_class=Response,
    responses=_file_answer("a small PNG of the output, or of the exemplar before there is one", "image/png"),
)
def get_thumbnail(service: ServiceDep, principal: PrincipalDep, job_id: str) -> Response:
    """A PNG of at most :data:`THUMBNAIL_SIDE` px a side: the output's (a volume's middle slice) once the
    job has one, else its exemplar's (the ``xy`` one of per-plane exemplars), for job lists."""
    job = _job(service, job_id, principal)
    if "output.png" in job.artifacts:
        rel, run = "out/output.png", job.artifacts_run
    else:
        role = next((r for r in ("exemplar", "exemplar_xy") if r in job.inputs), None)
        if role is None:
            raise HTTPException(404, f"job {job_id} has neither an output nor an exemplar")
        rel, run = f"inputs/{job.inputs[role]}", None
    path = service.store.storage.local_path(job_id, rel, run)
    if path is not None:
        png = thumbnail_png(str(path), path.stat().st_mtime_ns)
    else:  # an object store: the image is read into memory, never written to the API's disk
        try:
            chunks, _ = service.store.storage.open(job_id, rel, run)
        except FileNotFoundError:
            raise HTTPException(404, f"job {job_id} has no file {rel!r} (yet)") from None
        png = _thumbnail_of_bytes(b"".join(chunks))
    return Response(png, media_type="image/png", headers={"Cache-Control": "max-age=600"})


#: The longest side of a job's thumbnail, pixels.
THUMBNAIL_SIDE = 96


@lru_cache(maxsize=256)
def thumbnail_png(path: str, mtime_ns: int) -> bytes:
    """A small 8-bit PNG of the image at ``path`` (cached by its modification time)."""
    from texsynth.synth.io import load_image

    return _thumbnail(load_image(path, name="thumbnail"))


def _thumbnail_of_bytes(data: bytes) -> bytes:
    """:func:`thumbnail_png` of an image's bytes (from an object store; nothing written to disk)."""
    from texsynth.synth.io import load_image

    return _thumbnail(load_image(data, name="thumbnail"))


def _thumbnail(image: np.ndarray) -> bytes:
    h, w = image.shape[:2]
    step = max(1, -(-max(h, w) // THUMBNAIL_SIDE))  # ceil: at most THUMBNAIL_SIDE
    if step > 1:  # block means: fast and alias-free enough for a list
        h2, w2 = h // step * step, w // step * step
        blocks = image[:h2, :w2].reshape(h2 // step, step, w2 // step, step, *image.shape[2:])
        image = blocks.mean(axis=(1, 3))
    return image_to_png_bytes(np.ascontiguousarray(image, dtype=np.float32))


_PLANE_AXIS = {"xy": 0, "xz": 1, "yz": 2}


@lru_cache(maxsize=4)
def _stack(path: str, mtime_ns: int) -> np.ndarray:
    """A finished job's ``output.tiff`` as a float volume (cached: a viewer asks for many slices)."""
    return load_volume(path, name="output.tiff", max_voxels=2**31 - 1)


@lru_cache(maxsize=4)
def _stored_stack(service: Service, job_id: str, run: str) -> np.ndarray:
    """The same from the object store (run ``run``'s upload; read in memory, not to disk)."""
    data = service.store.storage.read(job_id, "out/output.tiff", run)
    return load_volume(data, name="output.tiff", max_voxels=2**31 - 1)


@router.get(
    "/{job_id}/slices/{plane}/{index}.png",
    response_class=Response,
    responses={**_file_answer("an 8-bit PNG slice", "image/png"), 422: {"model": ErrorPublic}},
)
def get_slice(service: ServiceDep, principal: PrincipalDep, job_id: str, plane: str, index: int) -> Response:
    """Slice ``index`` of a volume job's output in ``plane`` (``xy``: fixed z, ``xz``: fixed y,
    ``yz``: fixed x) as an 8-bit PNG, for the job page's slice viewer."""
    job = _job(service, job_id, principal)
    if plane not in _PLANE_AXIS:
        raise HTTPException(422, f"plane must be one of {', '.join(_PLANE_AXIS)}, not {plane!r}")
    if "output.tiff" not in job.artifacts or job.size.get("depth") is None:
        raise HTTPException(404, f"job {job_id} has no volume (it is {job.state}; 2-D jobs have no slices)")
    path = service.store.storage.local_path(job_id, "out/output.tiff", job.artifacts_run)
    if path is not None:
        volume = _stack(str(path), path.stat().st_mtime_ns)
    else:
        volume = _stored_stack(service, job_id, job.artifacts_run or "")
    axis = _PLANE_AXIS[plane]
    if not 0 <= index < volume.shape[axis]:
        raise HTTPException(422, f"index must lie in [0, {volume.shape[axis] - 1}] for plane {plane}")
    data = image_to_png_bytes(np.take(volume, index, axis=axis))
    return Response(data, media_type="image/png", headers={"Cache-Control": "max-age=3600"})


@router.get(
    "/{job_id}/inputs/{role}",
    response_class=FileResponse,
    responses=_file_answer(
        "the uploaded image (type from its bytes)", "image/png", "image/tiff", "image/jpeg"
    ),
)
def get_input(service: ServiceDep, principal: PrincipalDep, job_id: str, role: str) -> FileResponse:
    """One stored input of the job, served with the image type sniffed from its bytes."""
    job = _job(service, job_id, principal)
    if role not in job.inputs:
        raise HTTPException(404, f"job {job_id} has no {role!r} input; inputs: {', '.join(job.inputs)}")
    rel = f"inputs/{job.inputs[role]}"
    path = service.store.storage.local_path(job_id, rel, None)
    if path is None:
        try:
            data = service.store.storage.read(job_id, rel, None)  # inputs are small (the body limit)
        except FileNotFoundError:
            raise HTTPException(404, f"job {job_id} has no stored {role!r} input") from None
        fmt = sniff_format(data[:16])
        return Response(data, media_type=FORMAT_FILES[fmt][1] if fmt else "application/octet-stream")
    with open(path, "rb") as fh:  # the type from the bytes, whatever name an older record kept
        fmt = sniff_format(fh.read(16))
    media_type = FORMAT_FILES[fmt][1] if fmt else "application/octet-stream"
    return FileResponse(path, media_type=media_type)


@router.get(
    "/{job_id}/preview.png", response_class=FileResponse, responses=_file_answer("a PNG preview", "image/png")
)
def get_preview(service: ServiceDep, principal: PrincipalDep, job_id: str) -> FileResponse:
    """A small preview of the running synthesis, when the method provides one."""
    job = _job(service, job_id, principal)
    path = service.store.storage.local_path(job_id, "preview.png", None)
    if path is None:
        return _stream(service, job, "preview.png", "image/png", headers={"Cache-Control": "no-store"})
    if not path.exists():
        raise HTTPException(404, "no preview yet")
    return FileResponse(path, headers={"Cache-Control": "no-store"})

"""Dependencies shared by the routes, as ``Annotated`` aliases: the service and who is asking."""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, HTTPException, Request

from texsynth.app.auth import Principal
from texsynth.app.service import Service

__all__ = ["PrincipalDep", "ServiceDep"]


def get_service(request: Request) -> Service:
    return request.app.state.service


def get_principal(request: Request) -> Principal:
    """Who makes the request, as :class:`texsynth.app.security.AuthMiddleware` found it."""
    principal = getattr(request.state, "principal", None)
    if principal is None:  # only a route outside /api could get here
        raise HTTPException(401, "this request needs a token")
    return principal


ServiceDep = Annotated[Service, Depends(get_service)]
PrincipalDep = Annotated[Principal, Depends(get_principal)]

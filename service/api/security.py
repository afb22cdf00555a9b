"""Bearer-token check for mutating endpoints (active when FINALDRIVE_API_TOKEN is set)."""

from __future__ import annotations

import secrets
from typing import Annotated

from fastapi import Depends
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

from finaldrive.service.api.deps import ServicesDep
from finaldrive.service.api.problems import ApiProblem

_bearer = HTTPBearer(auto_error=False, description="FINALDRIVE_API_TOKEN, when the server sets one")


def require_token(
    services: ServicesDep, credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)]
) -> None:
    expected = services.settings.api_token
    if expected is None:
        return
    given = credentials.credentials if credentials is not None else ""
    if not secrets.compare_digest(given.encode(), expected.get_secret_value().encode()):
        raise ApiProblem(
            401, "a valid `Authorization: Bearer <token>` header is required (the token is the server's "
            "FINALDRIVE_API_TOKEN)",
            slug="unauthorized", headers={"WWW-Authenticate": "Bearer"},
        )


MutationAuth = Depends(require_token)

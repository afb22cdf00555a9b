"""Service settings, read from the environment (prefix ``FINALDRIVE_``) when the app starts.

Nothing here runs at import time: :func:`get_settings` builds (and caches) the settings on
first use, and tests pass their own :class:`Settings` to ``create_app``.
"""

from __future__ import annotations

import json
from functools import lru_cache
from typing import Annotated, Any, Self

from pydantic import Field, SecretStr, field_validator, model_validator
from pydantic_settings import BaseSettings, NoDecode, SettingsConfigDict

from finaldrive.workers import ExecutorKind

#: Host names a loopback client sends (IPv6 with and without brackets).
LOOPBACK_HOSTS = ("127.0.0.1", "localhost", "[::1]", "::1")
#: Bind addresses meaning every interface: no name to allow by default.
WILDCARD_BINDS = ("0.0.0.0", "::", "[::]")


class Settings(BaseSettings):
    """Every knob of the REST job service and its schedulers (env var = ``FINALDRIVE_`` + upper-case name)."""

    model_config = SettingsConfigDict(env_prefix="FINALDRIVE_", extra="ignore")

    db_url: str = Field("sqlite:///./finaldrive.db", description="SQLAlchemy database URL")
    host: str = Field("127.0.0.1", description="interface `finaldrive serve` binds")
    port: int = Field(8000, ge=0, le=65535, description="port `finaldrive serve` binds")
    executor: ExecutorKind = Field(
        "ray", description="where simulations run (a local Ray by default; RAY_ADDRESS or ray_address joins a cluster)"
    )
    num_workers: int | None = Field(None, ge=1, description="worker processes (process/ray)")
    ray_address: str | None = Field(None, description="Ray cluster address (ray executor)")
    task_cpus: int | None = Field(None, ge=1, description="CPUs each Ray task holds, its designs on as many threads "
                                  "(default: 1 up to 16 CPUs in all; wider beyond, at most 16 and a node's CPUs)")
    batch_size: int | None = Field(None, ge=1, description="designs per worker task")
    api_token: SecretStr | None = Field(None, description="bearer token for every route (reads included); "
                                        "browsers sign in with it (POST /v1/session: an HttpOnly cookie)")
    allowed_hosts: Annotated[list[str], NoDecode] = Field(
        default_factory=lambda: list(LOOPBACK_HOSTS),
        description="Host header names the service answers (ports ignored; comma-separated or a JSON list; "
                    "'*' allows any). Default: the loopback names plus the bind host unless it is 0.0.0.0 or ::")
    max_body_bytes: int = Field(1_048_576, ge=1024, description="request body size limit")
    max_job_evaluations: int = Field(250_000, ge=1, description="largest job accepted")
    max_job_cpu_hours: float = Field(100.0, gt=0, description="largest estimated cost of a job accepted, in "
                                     "CPU-hours of simulation (the estimate is in the job's cost_cpu_s); a running "
                                     "job is stopped (failed) once its simulations have taken this long")
    max_active_jobs: int = Field(1000, ge=1, description="jobs queued, running or interrupted at once; more "
                                 "submissions are refused (429) until some finish")
    max_pending_recordings: int = Field(32, ge=1, description="recordings queued or being produced at once "
                                        "(429 above)")
    max_profiles: int = Field(1000, ge=1, description="road profiles the store keeps (507 above; a profile is at "
                              "most FINALDRIVE_MAX_BODY_BYTES)")
    idempotency_key_hours: float = Field(24.0, gt=0, description="how long an Idempotency-Key replays its job; "
                                         "after that the key may name a new job")
    max_simulation_seconds: float = Field(60.0, gt=0, description="wall-time limit of one simulation; beyond it "
                                          "the evaluation fails with reason 'time limit'")
    lease_seconds: float = Field(15.0, ge=1, description="how long a scheduler's claim on a job lasts without a "
                                 "heartbeat; after it another scheduler may resume the job")
    heartbeat_seconds: float = Field(1.0, gt=0, le=5, description="how often a scheduler renews its leases and "
                                     "looks for cancelled jobs")
    max_jobs: int = Field(32, ge=1, description="jobs one scheduler runs at once")
    max_backlog_rows: int = Field(50_000, ge=1, description="a job's results waiting for the store before its "
                                  "dispatch pauses (what an outage of the store holds in memory a job)")
    writers: int = Field(1, ge=1, le=16, description="writer processes of a scheduler storing results at once "
                         "on PostgreSQL, for a server with cores to spare (SQLite takes one write at a time: one)")
    niceness: int = Field(10, ge=0, le=19, description="OS priority offset of the simulation worker processes "
                          "(the API keeps its core)")
    events_poll_seconds: float = Field(0.5, gt=0, description="SSE progress poll interval")
    status_cache_seconds: float = Field(0.25, ge=0, description="GET /v1/jobs/{id} answers from a snapshot the "
                                        "event hub rebuilds at its ticks when the job changed and, while it runs, "
                                        "when older than this (its clocks); 0: every GET reads the store")
    auto_create_db: bool = Field(True, description="create the schema in an empty database")
    max_streams: int = Field(1000, ge=1, description="event streams open at once (429 above)")
    max_streams_per_client: int = Field(16, ge=1, description="event streams open at once from one client "
                                        "address (429 above; a reverse proxy counts as one client)")
    max_concurrent_renders: int = Field(2, ge=1, description="plots and /points answers built at once; "
                                        "others wait (bounded memory)")
    render_wait_seconds: float = Field(30.0, gt=0, description="how long a plot or /points request waits "
                                       "for a render slot before 503")

    @field_validator("api_token")
    @classmethod
    def _token_not_empty(cls, token: SecretStr | None) -> SecretStr | None:
        if token is not None and not token.get_secret_value().strip():
            raise ValueError("FINALDRIVE_API_TOKEN is empty: set a token or unset the variable")
        return token

    @field_validator("allowed_hosts", mode="before")
    @classmethod
    def _split_hosts(cls, value: Any) -> Any:
        if isinstance(value, str):
            text = value.strip()
            return json.loads(text) if text.startswith("[") else [h.strip() for h in text.split(",") if h.strip()]
        return value

    @model_validator(mode="after")
    def _bind_host_allowed(self) -> Self:
        """By default the bind host is one of the allowed names (unless it binds every interface)."""
        if "allowed_hosts" not in self.model_fields_set and self.host not in WILDCARD_BINDS:
            self.allowed_hosts = [*LOOPBACK_HOSTS, *([self.host] if self.host not in LOOPBACK_HOSTS else [])]
        return self


@lru_cache
def get_settings() -> Settings:
    """Settings from the environment, built once, on first call."""
    return Settings()

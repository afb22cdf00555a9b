"""``finaldrive study paper`` (the paper-study job) and ``finaldrive report paper-study``.

``study paper`` submits one ``paper-study`` job (Table 9 sweep + Table 10 DE on the
paper's 23 roads, 104,190 simulations) to a service (``--server URL``) or runs the same
job in-process (``--local``), and follows its progress. Its Idempotency-Key is derived
from the spec, so running the command again resumes (or shows) the same job.
The web, database and plotting stacks are imported inside the command functions.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import time
from pathlib import Path
from typing import Any

from finaldrive.service.cli.commands import COMMANDS
from finaldrive.service.cli.common import UsageError, parser_options
from finaldrive.service.cli.remote import TERMINAL, client_command


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    from finaldrive.engine import DESettings

    table10 = DESettings.paper()
    study = subparsers.add_parser("study", help=COMMANDS["study"].help, **parser_options())
    paper = study.add_subparsers(dest="study_command", required=True, metavar="STUDY").add_parser(
        "paper", help="the paper's study: Table 9 sweep + Table 10 DE on the 23 roads (one paper-study job)",
        **parser_options())
    where = paper.add_mutually_exclusive_group()
    where.add_argument("--server", metavar="URL", help="submit to a running service (e.g. http://127.0.0.1:8000)")
    where.add_argument("--local", action="store_true", help="run in this process (the default)")
    paper.add_argument("--db", metavar="URL", help="--local: SQLAlchemy URL (default: FINALDRIVE_DB_URL or "
                                                   "sqlite:///./finaldrive.db)")
    paper.add_argument("--executor", choices=("serial", "process", "ray"), default="process",
                       help="--local: where simulations run")
    paper.add_argument("--workers", type=int, help="--local: worker processes / CPUs (default: all cores)")
    paper.add_argument("--roads", default="paper", help="road list")
    paper.add_argument("--grid", default="table9", help="sweep grid")
    paper.add_argument("--np", type=int, default=table10.np, help="DE population size NP")
    paper.add_argument("--iters", type=int, default=table10.iters, help="DE generations after the initial population")
    paper.add_argument("--duration", type=float, default=3.5, help="simulated time [s]")
    paper.add_argument("--method", choices=("fast", "reference"), default="fast", help="simulation method")
    paper.add_argument("--seed", type=int, default=0, help="DE seed (road i uses seed + i)")
    paper.add_argument("--no-wait", action="store_true", help="--server: submit and exit")
    paper.add_argument("--interval", type=float, default=5.0, help="seconds between progress lines")
    paper.set_defaults(run=run_study_paper)

    report = subparsers.add_parser("report", help=COMMANDS["report"].help, **parser_options())
    paper_report = report.add_subparsers(dest="report_command", required=True, metavar="REPORT").add_parser(
        "paper-study", help="docs/paper-study.md (+ .json, figures) from a finished paper-study job",
        **parser_options())
    paper_report.add_argument("job_id", type=int, metavar="JOB_ID", help="the paper-study job")
    paper_report.add_argument("--out", type=Path, default=Path("docs/paper-study.md"), help="markdown file to write")
    source = paper_report.add_mutually_exclusive_group()
    source.add_argument("--db", metavar="URL", help="read the store directly (default: FINALDRIVE_DB_URL or "
                                                    "sqlite:///./finaldrive.db)")
    source.add_argument("--server", metavar="URL", help="read through a running service")
    paper_report.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    paper_report.set_defaults(run=run_report_paper_study)


def study_spec(args: argparse.Namespace) -> dict[str, Any]:
    """The job spec a ``study paper`` invocation submits."""
    return {
        "kind": "paper-study", "roads": [args.roads], "grid": args.grid, "seed": args.seed,
        "de": {"np": args.np, "iters": args.iters},
        "settings": {"duration": args.duration, "method": args.method},
    }


def idempotency_key(spec: dict[str, Any]) -> str:
    digest = hashlib.sha256(json.dumps(spec, sort_keys=True).encode()).hexdigest()
    return f"paper-study-{digest[:20]}"


def _line(job: dict[str, Any], started: float) -> str:
    done, failed, total = job["done"], job["failed"], job["total"]
    eta = job.get("eta_s")
    return (
        f"job {job['id']} {job['state']}: {done + failed:,}/{total:,} ({100 * (done + failed) / max(total, 1):.1f} %), "
        f"failed {failed:,}, cached {job['cached']:,}, {time.monotonic() - started:.0f} s"
        + ("" if eta is None else f", eta {eta:.0f} s")
    )


def run_study_paper(args: argparse.Namespace) -> int:
    spec = study_spec(args)
    if args.server:
        return _run_server(args, spec)
    return _run_local(args, spec)


@client_command
def _run_server(args: argparse.Namespace, spec: dict[str, Any]) -> int:
    from finaldrive.service.client import ClientError, ServiceClient

    with ServiceClient(args.server) as client:
        before = client.jobs(kind="paper-study", limit=500)
        job = client.submit(spec, idempotency_key=idempotency_key(spec))
        existing = any(j["id"] == job["id"] for j in before)
        print(f"job {job['id']} ({'existing' if existing else 'submitted'}): {job['total']:,} evaluations; "
              f"{client.server}/v1/jobs/{job['id']}", flush=True)
        if args.no_wait:
            return 0
        started = time.monotonic()
        while job["state"] not in TERMINAL:
            time.sleep(args.interval)
            try:  # the service may restart meanwhile: the job resumes, keep following it
                job = client.job(job["id"])
            except ClientError as exc:
                print(f"job {job['id']}: {client.server} not answering ({exc}); retrying", flush=True)
                continue
            print(_line(job, started), flush=True)
    return _finish(job, f"--server {args.server}")


def _run_local(args: argparse.Namespace, spec_dict: dict[str, Any]) -> int:
    """Submit to the store and run a scheduler in this process (its main thread) until the job ends."""
    import threading

    from finaldrive.service.config import Settings
    from finaldrive.service.db.engine import display_url
    from finaldrive.service.jobs.plan import PlanError
    from finaldrive.service.jobs.scheduler import run_scheduler
    from finaldrive.service.jobs.submit import submit_job
    from finaldrive.service.schemas import JobSpec
    from finaldrive.service.services import start_services

    overrides = {"db_url": args.db, "executor": args.executor, "num_workers": args.workers}
    settings = Settings(**{k: v for k, v in overrides.items() if v is not None})
    services = start_services(settings)
    try:
        try:
            job, created = submit_job(services.db, JobSpec.model_validate(spec_dict),
                                      idempotency_key=idempotency_key(spec_dict), max_evaluations=10**9,
                                      max_cpu_hours=settings.max_job_cpu_hours)
        except PlanError as exc:
            raise UsageError(exc.msg) from None
        print(f"job {job.id} ({'submitted' if created else 'existing'}) in {display_url(settings.db_url)}: "
              f"{job.total:,} evaluations, executor {settings.executor}", flush=True)
        stop = threading.Event()
        final: dict[str, Any] = {}

        def follow() -> None:
            started = printed = time.monotonic()
            while (body := _local_job(services, job.id))["state"] not in TERMINAL and not stop.is_set():
                if time.monotonic() - printed >= args.interval:
                    print(_line(body, started), flush=True)
                    printed = time.monotonic()
                time.sleep(min(0.2, args.interval))
            final.update(body)
            stop.set()

        threading.Thread(target=follow, name="finaldrive-progress", daemon=True).start()
        run_scheduler(settings, stop, handle_signals=True)
    finally:
        services.close()
    if not final:  # stopped (Ctrl-C) before the job ended: it resumes at the next run
        raise KeyboardInterrupt
    return _finish(final, f"--db {display_url(settings.db_url)}")


def _local_job(services: Any, job_id: int) -> dict[str, Any]:
    from finaldrive.service.api.views import job_out
    from finaldrive.service.db.models import Job
    from finaldrive.service.db.repository import roads_of

    with services.db.read() as session:
        job = session.get(Job, job_id)
        return job_out(session, job, roads_of(session, [job_id])[job_id], detail=False).model_dump(mode="json")


def _finish(job: dict[str, Any], source: str) -> int:
    print(f"job {job['id']} {job['state']}: {job['done']:,} ok, {job['failed']:,} failed, "
          f"elapsed {job.get('elapsed_s') or 0:.1f} s" + (f"; error: {job['error']}" if job.get("error") else ""))
    if job["state"] == "succeeded":
        print(f"report: finaldrive report paper-study {job['id']} --out docs/paper-study.md {source}")
    return 0 if job["state"] == "succeeded" else 1


def run_report_paper_study(args: argparse.Namespace) -> int:
    import httpx

    from finaldrive.service.report import write_paper_study
    from finaldrive.service.report.data import StudyNotFound, from_database, from_server

    try:
        if args.server:
            data = from_server(args.server, args.job_id)
        else:
            from finaldrive.service.config import Settings

            data = from_database(args.db or Settings().db_url, args.job_id)
    except StudyNotFound as exc:
        raise UsageError(str(exc)) from None
    except httpx.HTTPError as exc:
        raise UsageError(f"cannot read job {args.job_id} from {args.server}: {exc}") from None
    if data.state != "succeeded":
        print(f"finaldrive: warning: job {data.job_id} is {data.state}; the report covers what is stored",
              file=sys.stderr)
    files = write_paper_study(data, args.out, figures=not args.no_figures)
    print(f"wrote {files.markdown}, {files.json} and {len(files.figures)} figures")
    return 0

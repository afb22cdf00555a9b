"""What the command groups share: argument helpers, engine inputs from arguments, output.

Engine imports happen inside the functions (the facade is lazy), so ``finaldrive --help``
and the client commands never load the simulation machinery.
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import subprocess

    import numpy as np

    from finaldrive.engine import Design, Road, SimSettings, Vehicle

ROAD_HELP = ("a spec (flat, sine:H:LAMBDA[:PHASE_DEG], bump:H:SIGMA[:MU], metres; the paper's: finaldrive roads) "
             "or profile:FILE.csv (x, y in metres)")


class UsageError(Exception):
    """A bad argument or input file: reported on one line, exit code 2."""


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Appends each option's default to its help, unless the default is None or False."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        default = action.default
        if "%(default)" in text or default is None or default is False or default is argparse.SUPPRESS \
                or not action.option_strings:
            return text
        return f"{text} (default: %(default)s)"


def parser_options() -> dict[str, Any]:
    """Keyword arguments for every (sub)parser: the formatter above."""
    return {"formatter_class": HelpFormatter}


# --- arguments -------------------------------------------------------------------------------

#: --drive's choices, in the order of the vehicle's drive_model values (0, 1).
DRIVES = ("paper", "launch")


def add_design_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--a2-deg", type=float, required=True,
                   help="angle a2 of the engine sprocket axis from the swingarm pivot, in the chassis frame [deg]")
    p.add_argument("--l2-m", type=float, required=True,
                   help="distance L2 from the pivot to the engine sprocket axis [m]")
    p.add_argument("--rws-m", type=float, required=True, help="wheel sprocket pitch radius R_WS [m]")


def add_vehicle_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--vehicle", metavar="FILE",
                   help="vehicle parameter file (JSON shaped like engine/data/vehicle.json); default: the paper's bike")
    p.add_argument("--drive", choices=DRIVES, default=None,
                   help="paper: the paper's constant torque; launch: the engine through the gearbox with traction and "
                        "wheelie limits (docs/engine.md#the-launch-drive); default: the vehicle file's drive_model")


def add_settings_args(p: argparse.ArgumentParser) -> None:
    from finaldrive.engine import SimSettings

    defaults = SimSettings()
    p.add_argument("--duration", type=float, default=defaults.duration, help="simulated time [s]")
    p.add_argument("--method", choices=("fast", "reference"), default=defaults.method,
                   help="fast (validated against the paper's method) or reference (the paper's solver)")
    p.add_argument("--dt", type=float, default=None,
                   help=f"reference: time step [s]; fast: output interval (default {defaults.dt:g})")


def add_de_args(p: argparse.ArgumentParser) -> None:
    """The optimiser's options; defaults and limits are the study layer's (a preset, then the options given)."""
    from finaldrive.engine import DE_HELP, DE_PRESETS, OPTIMISERS

    p.add_argument("--preset", choices=DE_PRESETS, default=None,
                   help="where unset options come from: default (stops once converged; docs/optimisation.md) "
                        "or paper (Table 10: 50 generations of 50); unset: paper for a paper-study, else default")
    p.add_argument("--optimiser", choices=tuple(OPTIMISERS), default=None, help=DE_HELP["optimiser"])
    p.add_argument("--seed", type=int, default=0, help="random seed (run i uses seed + i)")
    for flag, name, kind in _de_options():
        p.add_argument(flag, type=kind, default=None, help=DE_HELP[name])
    p.add_argument("--bounds", metavar="SPEC", default=None,
                   help="search box a2_deg=LO:HI,l2_m=LO:HI,rws_m=LO:HI (any subset; default Table 8: "
                        "a2_deg=0:360,l2_m=0:0.2,rws_m=0.05:0.15); a2 is periodic only over a full 360 deg")


def _de_options() -> list[tuple[str, str, type]]:
    """(flag, DESettings field, type) of the optimiser's options, one for each field of DESettings (a
    method's new setting needs no change here), the flag spelling the field as the API does."""
    import dataclasses

    from finaldrive.engine import DE_INTEGRAL, DESettings

    return [("--" + f.name.replace("_", "-"), f.name, int if f.name in DE_INTEGRAL else float)
            for f in dataclasses.fields(DESettings) if f.name != "optimiser"]


def add_tolerance_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--tolerance-pct", type=float, default=0.1, metavar="PCT",
                   help="near-optimal set: evaluated designs within PCT %% of the best fitness")


def add_json_arg(p: argparse.ArgumentParser, what: str = "print one JSON object (for scripts)") -> None:
    p.add_argument("--json", action="store_true", help=what)


# --- engine inputs from arguments ----------------------------------------------------------

def load_vehicle_arg(path: str | None, drive: str | None = None) -> Vehicle:
    """The vehicle of --vehicle (default: the paper's), with --drive's drive_model if given."""
    from finaldrive.engine import VehicleError, default_vehicle, load_vehicle

    try:
        vehicle = default_vehicle() if path is None else load_vehicle(path)
    except VehicleError as exc:
        raise UsageError(str(exc)) from None
    return vehicle if drive is None else vehicle.replace(drive_model=float(DRIVES.index(drive)))


def compile_first(method: str) -> float | None:
    """Compile the method's kernels before a command's first simulation if this machine has not yet,
    saying so on stderr (the simulation's wall_s then leaves it out); the seconds it took, else None."""
    from finaldrive.engine import compile_engine, is_compiled

    if is_compiled(method):
        return None
    print(f"compiling the engine's {method} method (once on this machine)...", file=sys.stderr)
    seconds = compile_engine((method,), later=())()
    print(f"compiled in {seconds:.0f} s", file=sys.stderr)
    return seconds


def design_from_args(args: argparse.Namespace, vehicle: Vehicle) -> Design:
    """The design of --a2-deg, --l2-m, --rws-m, within the vehicle's limits (else UsageError naming the option)."""
    from finaldrive.engine import Design, DesignError

    try:
        design = Design.from_deg(args.a2_deg, args.l2_m, args.rws_m)
        vehicle.check_design(design)
    except DesignError as exc:
        option = {"a2": "--a2-deg", "l2": "--l2-m"}.get(str(exc).split(" ", 1)[0], "--rws-m")
        raise UsageError(f"{option}: {exc}") from None
    return design


def settings_from_args(args: argparse.Namespace, vehicle: Vehicle, **extra: Any) -> SimSettings:
    """The simulation settings of the options, for ``vehicle`` (a model the fast method alone simulates,
    with --method reference, is a usage error naming the vehicle parameter)."""
    from finaldrive.engine import SimSettings

    changes: dict[str, Any] = {"duration": args.duration, "method": args.method, **extra}
    if args.dt is not None:
        changes["dt"] = args.dt
    try:
        settings = SimSettings(**changes)
        vehicle.check_method(settings.method)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    return settings


def de_options(args: argparse.Namespace) -> dict[str, Any]:
    """The optimiser options given on the command line (--preset included when given)."""
    given = {name: getattr(args, flag[2:].replace("-", "_")) for flag, name, _ in _de_options()}
    given["optimiser"] = args.optimiser
    if args.preset is not None:
        given["preset"] = args.preset
    return {k: v for k, v in given.items() if v is not None}


def de_from_args(args: argparse.Namespace, preset: str = "default") -> tuple[Any, Any]:
    """(Bounds, DESettings) from the optimiser's options over ``preset`` (or --preset); UsageError
    names the option."""
    from finaldrive.engine import Bounds, DESettings, SpaceError

    try:
        bounds = Bounds.parse(args.bounds)
    except SpaceError as exc:
        raise UsageError(f"--bounds: {exc}") from None
    given = de_options(args)
    try:
        de = DESettings.preset(given.pop("preset", preset), **given)
    except SpaceError as exc:
        options = {name: flag for flag, name, _ in _de_options()}
        raise UsageError(f"{options.get(exc.field, '--' + exc.field)}: {exc.msg}") from None
    return bounds, de


def read_profile(path: Path) -> Road:
    """A measured road from a CSV of x, y [m] (an optional header line; # comments)."""
    from finaldrive.service.profiles import ProfileError, road_from_csv

    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise UsageError(f"road profile {str(path)!r}: {getattr(exc, 'strerror', None) or exc}") from None
    try:
        return road_from_csv(text, name=path.name)
    except ProfileError as exc:
        raise UsageError(f"road profile {str(path)!r}: {exc}") from None


def road_list(text: str) -> list[Any]:
    """Named roads from a road list (presets, groups, specs, profile:FILE.csv)."""
    from finaldrive.engine import resolve_roads

    try:
        return resolve_roads(text, lambda name: read_profile(Path(name)))
    except ValueError as exc:
        raise UsageError(str(exc)) from None


def road_from_arg(text: str) -> Road:
    """Exactly one road (see :func:`road_list`)."""
    roads = road_list(text)
    if len(roads) != 1:
        raise UsageError(f"--road takes one road, {text!r} names {len(roads)}")
    road: Road = roads[0].road
    return road


def read_designs_csv(path: str) -> np.ndarray:
    """Rows (a2 [rad], L2 [m], R_WS [m]) from a CSV with header a2_deg,l2_m,rws_m."""
    try:
        text = Path(path).read_text()
    except OSError as exc:
        raise UsageError(f"designs file {path!r}: {exc.strerror or exc}") from None
    reader = csv.DictReader(io.StringIO(text))
    missing = {"a2_deg", "l2_m", "rws_m"} - set(reader.fieldnames or ())
    if missing:
        raise UsageError(f"designs file {path!r}: missing column(s) {', '.join(sorted(missing))}")
    rows = []
    for n, row in enumerate(reader, start=2):
        try:
            rows.append([math.radians(float(row["a2_deg"])), float(row["l2_m"]), float(row["rws_m"])])
        except (TypeError, ValueError):
            raise UsageError(f"designs file {path!r}, line {n}: a2_deg, l2_m and rws_m must be numbers") from None
    import numpy as np

    return np.array(rows, dtype=float).reshape(-1, 3)


def stop_process(proc: subprocess.Popen[bytes], timeout: float) -> None:
    """SIGTERM ``proc`` and wait up to ``timeout`` s for it, then kill it."""
    import signal
    import subprocess

    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def writable(path: str, option: str) -> Path:
    """``path`` if a file can be written there (its folder exists), else UsageError naming ``option``."""
    out = Path(path)
    if not out.parent.is_dir():
        raise UsageError(f"{option} {path!r}: the folder {str(out.parent)!r} does not exist")
    if out.is_dir():
        raise UsageError(f"{option} {path!r}: is a folder")
    return out


# --- output ------------------------------------------------------------------------------------

def print_json(obj: Any) -> None:
    print(json.dumps(obj, indent=2, default=_json_default, allow_nan=False))


def _json_default(o: Any) -> Any:
    if type(o).__module__ == "numpy" and hasattr(o, "item"):   # a numpy scalar (numpy not imported for --help)
        return o.item()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def clean(value: float) -> float | None:
    """JSON has no NaN: failed values are null."""
    return None if not math.isfinite(value) else float(value)

"""Request and response bodies of the REST API (pydantic; defaults from the engine's study layer).

Units: SI, angles of designs in radians except where a name ends in ``_deg``.
"""

from __future__ import annotations

import dataclasses
from datetime import datetime
from typing import TYPE_CHECKING, Annotated, Any, Literal

from pydantic import (
    AllowInfNan,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    Strict,
    StringConstraints,
    create_model,
    model_validator,
)

from finaldrive.engine import (
    DE_HELP,
    DE_INTEGRAL,
    DE_LIMITS,
    DE_OPTIONAL,
    FIELDS,
    OPTIMISERS,
    PROFILE_MAX_POINTS,
    VALUES,
    VEHICLE_VALUE_LIMIT,
    Bounds as StudyBounds,
    DESettings,
    SimSettings,
    SpaceError,
    StudyKind,
)

JobKind = StudyKind
JobStateName = Literal["queued", "running", "succeeded", "failed", "cancelled", "interrupted"]

_STRICT = ConfigDict(extra="forbid")

#: A number in a request: a JSON number, finite (never a string, NaN or Infinity).
Num = Annotated[float, Strict(), AllowInfNan(False)]
#: A whole number in a request: a JSON integer (never a string or 10.0).
Whole = Annotated[int, Strict()]
Name = Annotated[str, StringConstraints(max_length=64)]


_SIM = SimSettings()
_DE = DESettings()
_BOX = StudyBounds()


class SimulationSpec(BaseModel):
    """How each design is simulated (a subset of the engine's SimSettings, same defaults)."""

    model_config = _STRICT

    duration: Num = Field(_SIM.duration, gt=0, le=60, description="simulated time [s]")
    dt: Num = Field(_SIM.dt, ge=1e-6, le=0.01, description="time step [s]")
    method: Literal["reference", "fast"] = Field(
        _SIM.method, description="fast (default, validated against the paper's method) or reference")
    fast_tolerance: Num = Field(_SIM.fast_tolerance, ge=1e-9, le=1e-2, description="fast method: local error "
                                "tolerance of its step control (m, rad; 10x for rates)")


class _DESpecBase(BaseModel):
    """The optimiser's settings (engine.study.space.DESettings): a preset, and the fields to change
    from it. ``default`` stops a run once it has converged; ``paper`` is Table 10. The settings'
    fields (below the class) follow DESettings' own: a method's new setting needs no change here."""

    model_config = _STRICT

    preset: Literal["default", "paper"] | None = Field(
        None, description="where unset fields come from: default (stops once converged) or paper (Table 10); "
                          "unset: paper for a paper-study, default otherwise")
    optimiser: Name = Field(_DE.optimiser, description=DE_HELP["optimiser"],
                            json_schema_extra={"enum": list(OPTIMISERS)})

    def settings(self, preset: str = "default") -> DESettings:
        """The settings: this spec's preset (else ``preset``) with the fields the request set;
        SpaceError naming the field."""
        given = {name: getattr(self, name) for name in self.model_fields_set - {"preset"}}
        return DESettings.preset(self.preset or preset, **given)

    def resolved(self, preset: str) -> DESpec:
        """Every field set to its value (what is stored and hashed)."""
        return DESpec(preset=self.preset or preset, **dataclasses.asdict(self.settings(preset)))


def _setting(name: str) -> tuple[Any, Any]:
    """A DESettings field as a request field: JSON integer or number, its limits, its help."""
    lo, hi = DE_LIMITS[name]
    default = getattr(_DE, name)
    kind: Any = Whole if name in DE_INTEGRAL else Num
    return (kind | None if name in DE_OPTIONAL else kind,
            Field(default, ge=lo, le=hi, description=DE_HELP[name]))


if TYPE_CHECKING:
    class DESpec(_DESpecBase):  # for type checkers; the fields are made below, for pydantic
        pass
else:
    DESpec = create_model("DESpec", __base__=_DESpecBase, __doc__=_DESpecBase.__doc__,  # type: ignore[call-overload]
                          **{f.name: _setting(f.name) for f in dataclasses.fields(DESettings) if f.name != "optimiser"})


Interval = tuple[Num, Num]


class Bounds(BaseModel):
    """DE search box (defaults: the paper's Table 8); each entry is [lower, upper]."""

    model_config = _STRICT

    a2_deg: Interval = Field(_BOX.a2_deg, description="sprocket angle a2 [deg], periodic over a full turn")
    l2_m: Interval = Field(_BOX.l2_m, description="pivot-to-sprocket distance L2 [m]; at most the vehicle's l2_max")
    rws_m: Interval = Field(_BOX.rws_m, description="wheel sprocket radius R_WS [m]; at most the vehicle's "
                            "rt0 - rws_tyre_margin")

    @model_validator(mode="after")
    def _valid(self) -> Bounds:
        try:
            StudyBounds(**self.model_dump())
        except SpaceError as exc:
            raise ValueError(str(exc)) from None
        return self


def _not_huge(value: Any) -> Any:
    """An integer too large for a float is refused with the limit (not as "not a number")."""
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) > VEHICLE_VALUE_LIMIT:
        raise ValueError(f"magnitude must be <= {VEHICLE_VALUE_LIMIT:g}")
    return value


class VehicleValue(BaseModel):
    """One vehicle parameter, as in engine/data/vehicle.json."""

    model_config = _STRICT

    value: Annotated[Num, BeforeValidator(_not_huge)] = Field(ge=-VEHICLE_VALUE_LIMIT, le=VEHICLE_VALUE_LIMIT)
    unit: str = Field("", max_length=40)
    source: str = Field("", max_length=2000)


class VehicleFile(BaseModel):
    """A vehicle file (engine/data/vehicle.json's layout: groups of parameters); the engine checks
    every key and value (magnitude at most 1e10, each parameter's own rule, the design limits)."""

    model_config = _STRICT

    name: str = Field("", max_length=200)
    parameters: dict[Name, dict[Name, VehicleValue]] = Field(max_length=32)


#: A design of a ``designs`` job: [a2_deg, l2_m, rws_m].
DesignRow = tuple[Num, Num, Num]
#: Designs of a ``designs`` job on each road, at most.
MAX_ROAD_DESIGNS = 100


class JobSpec(BaseModel):
    """A job: a sweep over a design grid, a DE (per road, or robust over all roads), a
    paper-study (the sweep and the per-road DE on the same roads, under one job), or explicit
    designs on each road (``designs``: what /best's sensitivity queues)."""

    model_config = _STRICT

    kind: JobKind
    roads: list[Annotated[str, StringConstraints(strip_whitespace=True, min_length=1, max_length=500)]] = Field(
        min_length=1, max_length=64,
        description="specs (flat, sine:H:LAMBDA[:PHASE_DEG], bump:H:SIGMA[:MU]) or groups of the paper's roads "
                    "(paper, sine, bump)",
    )
    grid: str | None = Field(None, max_length=500, description='sweep / paper-study: "table9" or a grid spec')
    bounds: Bounds | None = Field(None, description="de / robust-de / paper-study (default: Table 8)")
    de: DESpec | None = Field(None, description="de / robust-de / paper-study: the optimiser (default: preset "
                                    "default; paper-study: preset paper, Table 10)")
    aggregate: Literal["mean", "worst"] | None = Field(None, description="robust-de only (default mean)")
    designs: list[Annotated[list[DesignRow], Field(min_length=1, max_length=MAX_ROAD_DESIGNS)]] | None = Field(
        None, max_length=64, description="designs only: for each road (in order) its designs, [a2_deg, l2_m, rws_m]")
    seed: Whole = Field(0, ge=0, le=2**32 - 1)
    settings: SimulationSpec = Field(default_factory=SimulationSpec)
    vehicle: VehicleFile | None = Field(None, description="vehicle parameters (default: the paper's)")

    @model_validator(mode="after")
    def _kind_fields(self) -> JobSpec:
        if (self.kind == "designs") != (self.designs is not None):
            raise ValueError("designs: required for (and only for) kind designs")
        if self.kind in ("sweep", "designs"):
            for name in ("bounds", "de", "aggregate", *(("grid",) if self.kind == "designs" else ())):
                if getattr(self, name) is not None:
                    raise ValueError(f"{name}: not allowed for a {self.kind} job")
        elif self.grid is not None and self.kind != "paper-study":
            raise ValueError(f"grid: not allowed for {self.kind}")
        if self.kind in ("de", "paper-study") and self.aggregate is not None:
            raise ValueError("aggregate: only for robust-de")
        if self.de is not None:
            try:
                self.de.settings(self.default_preset)
            except ValueError as exc:
                raise ValueError(f"de: {exc}") from None
        return self

    @property
    def default_preset(self) -> str:
        """The optimiser preset of a spec that names none: Table 10 for the paper study."""
        return "paper" if self.kind == "paper-study" else "default"

    def normalised(self) -> JobSpec:
        """The spec with every default filled in (what is stored and hashed)."""
        fill: dict[str, Any] = {}
        if self.kind in ("sweep", "paper-study"):
            fill["grid"] = self.grid or "table9"
        if self.kind not in ("sweep", "designs"):
            fill["bounds"] = self.bounds or Bounds()
            fill["de"] = (self.de or DESpec()).resolved(self.default_preset)
            if self.kind == "robust-de":
                fill["aggregate"] = self.aggregate or "mean"
        return self.model_copy(update=fill)


class _EvaluationCore(BaseModel):
    id: int
    road_index: int
    road: str
    step: int = Field(description="DE generation (0 = initial population); 0 for sweeps, -1 for a paper-study's sweep")
    candidate: int = Field(description="row in the sweep grid or the DE generation")
    a2_deg: float = Field(description="sprocket angle a2 [deg]")
    l2_m: float = Field(description="pivot-to-sprocket distance L2 [m]")
    rws_m: float = Field(description="wheel sprocket radius R_WS [m]")
    status: Literal["ok", "failed"]
    reason: str
    cached: bool = Field(description="reused from an earlier identical simulation")


def _described(name: str) -> str:
    spec = FIELDS[name]
    return f"{spec.meaning} [{spec.unit}]" if spec.unit else spec.meaning


#: An evaluation: its slot, the design, status, and its result record (finaldrive.engine.VALUES:
#: the outcome and the run's diagnostics; null where the run produced none).
EvaluationOut = create_model(  # type: ignore[call-overload]  # pydantic's stubs miss the (type, Field) form
    "EvaluationOut", __base__=_EvaluationCore,
    **{name: (float | None, Field(None, description=_described(name))) for name in VALUES},
)


class EvaluationPage(BaseModel):
    items: list[EvaluationOut]
    next_cursor: str | None = Field(description="pass as ?cursor= for the next page; null at the end")


class RoadProgress(BaseModel):
    index: int
    name: str
    spec: str
    best: EvaluationOut | None = Field(description="best successful evaluation so far")


class RobustBest(BaseModel):
    aggregate: Literal["mean", "worst"]
    score_m: float | None = Field(description="aggregate fitness of the best design [m]")
    a2_deg: float = Field(description="sprocket angle a2 [deg]")
    l2_m: float = Field(description="pivot-to-sprocket distance L2 [m]")
    rws_m: float = Field(description="wheel sprocket radius R_WS [m]")
    generation: int


class JobOut(BaseModel):
    id: int
    kind: JobKind
    state: JobStateName
    spec: JobSpec
    total: int = Field(description="evaluations planned (DE: upper bound until it finishes)")
    done: int = Field(description="successful evaluations stored")
    failed: int = Field(description="failed evaluations stored")
    cached: int = Field(description="evaluations taken from the result cache")
    progress: float
    created_at: datetime
    started_at: datetime | None
    finished_at: datetime | None
    elapsed_s: float | None
    eta_s: float | None
    error: str | None
    roads: list[RoadProgress]
    robust_best: RobustBest | None = None


class JobPage(BaseModel):
    items: list[JobOut]
    next_cursor: str | None


class GenerationRecord(BaseModel):
    generation: int = Field(description="DE generation (0: the initial population), as evaluations' step")
    n_evals: int = Field(description="evaluations of the run so far")
    n_failed: int = Field(description="failed evaluations in this generation")
    best_fitness_m: float | None = Field(description="best fitness so far [m]")
    mean_fitness_m: float | None = Field(description="mean fitness of the population [m]")


class RunHistory(BaseModel):
    run: int = Field(description="road index (de, paper-study) or 0 (robust-de)")
    road: str | None = Field(description="road name; null for robust-de (all roads)")
    generations: list[GenerationRecord]


class HistoryOut(BaseModel):
    job_id: int
    kind: JobKind
    runs: list[RunHistory]


class BestOut(BaseModel):
    job_id: int
    roads: list[RoadProgress]
    robust_best: RobustBest | None = None
    sharpness: list[SharpnessOut] = Field([], description="per road, then (robust-de) by the aggregate score")
    sensitivity_job: int | None = Field(None, description="sensitivity=true: the job (kind designs) that simulates "
                                        "the finite differences")
    sensitivity_state: JobStateName | None = Field(None, description="sensitivity=true: that job's state (the "
                                                   "sensitivities are there once it has succeeded)")
    band_jobs: dict[str, int] | None = Field(None, description="band=true: the jobs (kind designs) of the band's "
                                             "re-runs, tight and reference")
    band_state: JobStateName | None = Field(None, description="band=true: the least finished of those jobs' states "
                                            "(the bands are there once both have succeeded)")
    model_band_jobs: dict[str, int] | None = Field(None, description="model_band=true: the jobs (kind designs), one "
                                                   "an alternative")
    model_band_state: JobStateName | None = Field(None, description="model_band=true: the least finished of those "
                                                  "jobs' states (the model bands are there once all have succeeded)")


class RoadOut(BaseModel):
    name: str
    spec: str
    kind: str
    description: str
    paper: dict[str, float] | None = Field(description="the paper's optimum on this road")


class RoadProfileIn(BaseModel):
    """A measured road: (x, y) points in metres, x strictly increasing (the road is piecewise linear
    through them and level beyond the ends; x = 0 is the rear tyre's starting contact point)."""

    model_config = _STRICT

    name: str = Field("", max_length=64, description="a label (not part of its identity)")
    points: list[tuple[Num, Num]] = Field(
        min_length=2, max_length=PROFILE_MAX_POINTS, description="[[x, y], ...] [m]")


class RoadProfileOut(BaseModel):
    id: int
    spec: str = Field(description="how a job names it: profile:ID")
    name: str
    content_hash: str = Field(description="sha256 of the points: the profile's identity (and result-cache key)")
    n_points: int
    x_min_m: float
    x_max_m: float
    y_min_m: float
    y_max_m: float
    created_at: datetime


class RoadProfileDetail(RoadProfileOut):
    points: list[tuple[float, float]] = Field(description="[[x, y], ...] [m]")


class RoadProfilePage(BaseModel):
    items: list[RoadProfileOut]
    next_cursor: str | None = Field(description="pass as ?cursor= for the next page; null at the end")


class StoreOut(BaseModel):
    writable: bool = Field(description="a write transaction could start within a second")
    latency_s: float = Field(description="how long the check took [s]")


class SchedulerOut(BaseModel):
    id: str
    host: str
    pid: int
    executor: str
    capacity: int = Field(description="simulation tasks it keeps in flight")
    heartbeat_age_s: float = Field(description="since its last heartbeat, on the database's clock [s]")
    alive: bool = Field(description="its heartbeat is younger than a lease")
    store_error: str | None = Field(None, description="why its last write of results failed (null once one passes "
                                    "again): the store takes small writes but not its results, e.g. a full disk")
    tasks_per_s: float | None = Field(None, description="simulation tasks that came back a second, over its last "
                                      "heartbeat interval (null before its first)")
    evaluations_per_s: float | None = Field(None, description="designs simulated a second, over its last heartbeat "
                                            "interval")
    busy_share: float | None = Field(None, description="share of its executor's workers with a task in flight, "
                                     "time-weighted over its last heartbeat interval (0-1)")
    in_flight_tasks: int | None = Field(None, description="simulation tasks in flight at its last heartbeat")
    backlog_designs: int | None = Field(None, description="designs of its jobs ready and waiting to be dispatched at "
                                        "its last heartbeat")


class HealthOut(BaseModel):
    status: Literal["ok", "unavailable"]
    store: StoreOut
    schedulers: list[SchedulerOut] = Field(description="schedulers that have not stopped")
    schema_revision: str
    engine_version: str
    active_jobs: int | None = Field(description="queued, running and interrupted jobs (null when the store is down)")


class ProblemItem(BaseModel):
    loc: list[str | int]
    msg: str


class Problem(BaseModel):
    """RFC 9457 problem details (media type application/problem+json)."""

    type: str
    title: str
    status: int
    detail: str
    instance: str | None = None
    errors: list[ProblemItem] | None = None


RecordingStatus = Literal["queued", "running", "succeeded", "failed"]


class RecordingDesign(BaseModel):
    """A geometry to record (a2 in degrees)."""

    model_config = _STRICT

    a2_deg: Num = Field(ge=-720, le=720, description="sprocket angle a2 [deg]")
    l2_m: Num = Field(ge=0, le=0.5, description="pivot-to-sprocket distance L2 [m]; at most the vehicle's l2_max")
    rws_m: Num = Field(gt=0, le=0.5, description="wheel sprocket radius R_WS [m]; at most the vehicle's rt0 - "
                                               "rws_tyre_margin")
    label: str | None = Field(None, max_length=80)


class RecordingRequest(BaseModel):
    """A Rerun recording: a job's best design and/or explicit designs, side by side on one road."""

    model_config = _STRICT

    job_id: Whole | None = Field(None, ge=1, le=2**63 - 1,
                                 description="record this job's best design (on `road`) first")
    road: str | None = Field(None, min_length=1, max_length=500,
                             description="road spec or preset; default: the job's first road")
    designs: list[RecordingDesign] = Field(default_factory=list, max_length=4)
    duration: Num = Field(3.5, gt=0, le=10, description="simulated time [s]")
    fps: Literal[10, 20, 25, 50, 100] = Field(50, description="frames per simulated second")

    @model_validator(mode="after")
    def _something(self) -> RecordingRequest:
        if self.job_id is None and not self.designs:
            raise ValueError("give job_id, designs, or both")
        if self.job_id is None and self.road is None:
            raise ValueError("road: required without job_id")
        if len(self.designs) + (self.job_id is not None) > 4:
            raise ValueError("at most 4 geometries per recording")
        return self


class RecordingOut(BaseModel):
    id: int
    status: RecordingStatus
    job_id: int | None
    road: str
    designs: list[RecordingDesign] = Field(description="what is recorded, top to bottom")
    duration: float
    fps: int
    frames: int = Field(description="frames on the sim_time timeline (duration x fps + 1)")
    error: str | None
    file: str | None = Field(description="download path, once succeeded")
    viewer_file: str | None = Field(description="the file as rerun's web viewer loads it, once succeeded (it sends "
                                    "no credentials: with a token set, a link signed for this file, valid an hour)")
    created_at: datetime


class RecordingRun(BaseModel):
    key: str = Field(description="entity name in the recording: g1, g2, ...")
    label: str
    a2_deg: float = Field(description="sprocket angle a2 [deg]")
    l2_m: float = Field(description="pivot-to-sprocket distance L2 [m]")
    rws_m: float = Field(description="wheel sprocket radius R_WS [m]")
    outcome: dict[str, float] = Field(description="the run's outcome (distance_m, fitness_m, exact extremes, "
                                      "energy ledger), units in the keys")
    series: dict[str, list[float]] = Field(description="Fig. 13 series, one value per t_s, units in the keys")


class RecordingSeriesOut(BaseModel):
    recording_id: int
    t_s: list[float] = Field(description="time of each frame [s]")
    runs: list[RecordingRun]


class TravelPointOut(BaseModel):
    """One pose of the rear suspension (chassis at theta0, unloaded tyres on flat ground)."""

    travel_m: float = Field(description="rear axle height above full extension, chassis frame [m]")
    swingarm_angle_deg: float = Field(description="swingarm angle phi - theta in the chassis frame [deg]")
    squat_ratio: float = Field(description="the paper's squat ratio K / tan(tau) at this pose [-]")
    anti_squat_pct: float = Field(description="100 tan(tau) / tan(sigma) (textbook anti-squat) [%]")
    taut_length_m: float = Field(description="the chain's straight upper run, eq. (68) [m]")
    chain_growth_m: float = Field(description="taut run minus its length at full extension [m]")
    centre_distance_m: float = Field(description="engine sprocket axis to rear axle [m]")
    chain_angle_deg: float = Field(description="upper run's angle to the chassis x axis, rear to front [deg]")
    chain_above_pivot_m: float = Field(description="distance of the upper run's line above the swingarm pivot [m]")
    kickback_deg: float = Field(description="rear wheel's backward turn from the chain growth, the engine sprocket "
                                "held: chain_growth_m / R_WS [deg]")
    anti_rise_pct: float = Field(description="100 tan(lambda) / tan(sigma), lambda the slope from the rear contact "
                                 "point to the swingarm pivot (rear brake caliper on the swingarm) [%]")
    spring_length_m: float = Field(description="the rear spring's length, points 3-7 (eq. 13) [m]")
    leverage_ratio: float = Field(description="rear wheel travel per unit of rear spring compression [-]")


class StaticSagOut(TravelPointOut):
    sag_pct: float = Field(description="static sag as a share of the rear wheel travel [%]")


class TravelOut(BaseModel):
    """Kinematics from full extension to full compression of the rear suspension."""

    rear_wheel_travel_m: float = Field(description="rear wheel travel (vehicle rear_wheel_travel) [m]")
    extension_angle_deg: float = Field(description="swingarm angle at full extension (rear spring at s_rs) [deg]")
    compression_angle_deg: float = Field(description="swingarm angle at full compression [deg]")
    cog_height_m: float = Field(description="h of tan(sigma) = h / p [m]")
    wheelbase_m: float = Field(description="p of tan(sigma) = h / p, at the design pose [m]")
    anti_squat_definition: str
    anti_rise_definition: str
    fork_angle_deg: float = Field(description="the fork axis's angle from the vertical at the design pose [deg]")
    anti_dive_pct: float = Field(description="-100 tan(epsilon) / tan(sigma), epsilon = fork_angle_deg (front brake "
                                 "caliper on the fork slider; one value: the fork's axis is fixed in the chassis) [%]")
    anti_dive_definition: str
    chain_pitch_m: float = Field(description="the chain's pitch (vehicle chain_pitch) [m]")
    engine_sprocket_teeth: float = Field(description="N = pi / asin(p / 2 R_ES), not rounded [-]")
    wheel_sprocket_teeth: float = Field(description="N = pi / asin(p / 2 R_WS), not rounded [-]")
    chain_links: float = Field(description="the whole chain's length at the design pose over its pitch [-]")
    curve: list[TravelPointOut] = Field(description="evenly spaced in travel, full extension first")
    design_pose: TravelPointOut = Field(description="the design pose (phi0), where the paper reads SR")
    static_sag: StaticSagOut = Field(description="static equilibrium on flat ground")


class GeometryOut(BaseModel):
    """A design's static final-drive quantities (no simulation)."""

    a2_deg: float = Field(description="engine sprocket angle a2 [deg]")
    l2_m: float = Field(description="pivot to engine sprocket axis L2 [m]")
    rws_m: float = Field(description="wheel sprocket pitch radius R_WS [m]")
    res_m: float = Field(description="engine sprocket pitch radius R_ES = R_WS / ratio [m]")
    squat_ratio: float = Field(description="squat ratio at the design pose [-]")
    chain_length_m: float = Field(description="chain length L, eq. (69) [m]")
    taut_length_m: float = Field(description="taut upper run at static equilibrium on flat ground, eq. (68) [m]")
    engine_sprocket_x_m: float = Field(description="engine sprocket axis from the pivot, chassis x [m]")
    engine_sprocket_y_m: float = Field(description="engine sprocket axis from the pivot, chassis y [m]")
    swingarm_angle_deg: float = Field(description="swingarm (pivot to rear axle) at static equilibrium on flat "
                                      "ground, phi - theta: from the chassis x axis, as a2 [deg]")
    travel_curve: TravelOut | None = Field(None, description="over the rear travel (with travel=true)")


class SensitivityOut(BaseModel):
    """Finite differences through the engine at the best design (engine study.sharpness)."""

    steps: dict[str, float] = Field(description="steps, units in the keys: a2_deg, l2_m, rws_m")
    schemes: dict[str, Literal["central", "forward", "backward"]] = Field(
        description="difference scheme of each variable (one-sided at a limit of the design space)")
    simulations: int
    distance_m: float = Field(description="distance at the best design [m]")
    fitness_m: float = Field(description="fitness at the best design [m]")
    ddistance_da2_m_per_deg: float
    dfitness_da2_m_per_deg: float
    ddistance_dl2_m_per_m: float
    dfitness_dl2_m_per_m: float
    ddistance_drws_m_per_m: float
    dfitness_drws_m_per_m: float


class BandRunOut(BaseModel):
    fitness_m: float | None = None
    distance_m: float | None = None


class BandOut(BaseModel):
    """A design's numerical band (engine.study.band): its fitness and distance re-simulated 100x
    tighter and with the reference method where the vehicle allows it (``failed`` says why not); the
    band the largest change from the job's own run."""

    fitness_m: float | None = Field(None, description="the job's own run [m]")
    distance_m: float | None = None
    band_m: float | None = Field(None, description=_described("band_m"))
    distance_band_m: float | None = Field(None, description=_described("distance_band_m"))
    exceeds_limit: bool | None = Field(None, description=_described("exceeds_limit"))
    runs: dict[str, BandRunOut] = Field({}, description="each run that finished: production, tight, reference")
    failed: dict[str, str] = Field({}, description="each re-run that failed, and why (left out of the band)")


class TieOut(BandOut):
    a2_deg: float
    l2_m: float
    rws_m: float
    tie: bool = Field(description=_described("tie"))


class RankingOut(BaseModel):
    """The designs' results under a model (engine.study.model_band.ranking_change), in the designs' order."""

    fitness_m: list[float | None] = Field(description="each design's fitness [m]; null: its run failed")
    distance_m: list[float | None] = Field(description="each design's distance [m]")
    failed: list[str] = Field(description="each design's failure reason, in the designs' order; empty where it "
                              "succeeded")
    rank_correlation: float | None = Field(description="Spearman's of the fitness with the model as given, over "
                                           "the designs that succeeded in both (null below 3)")
    best: int | None = Field(description="the index of the best design; null: none succeeded")
    same_best: bool = Field(description="the best is the model as given's best")
    largest_change_m: float | None = Field(description=_described("largest_change_m"))


class ModelAlternativeOut(RankingOut):
    what: str = Field(description="what the alternative changes")
    road: str = Field(description="the road it is simulated on")


class ModelBandDesign(BaseModel):
    """One of the designs a model band re-simulates."""

    a2_deg: float = Field(description="sprocket angle a2 [deg]")
    l2_m: float = Field(description="pivot-to-sprocket distance L2 [m]")
    rws_m: float = Field(description="wheel sprocket radius R_WS [m]")


class ModelBandsOut(BaseModel):
    """A road's best distinct designs under the documented modelling alternatives (docs/optimisation.md#model-bands)."""

    designs: list[ModelBandDesign] = Field(description="the designs, best first (the job's own ranking)")
    baseline: RankingOut = Field(description="the job's own results")
    alternatives: dict[str, ModelAlternativeOut]
    skipped: list[str] = Field(description="the alternatives left out on this road")
    skipped_reasons: dict[str, str] = Field(description="why each was left out")


class SharpnessOut(BaseModel):
    """How sharp a best design is: the evaluated designs within a tolerance of the best fitness."""

    road: str | None = Field(description="road name; null: by the robust-de aggregate score")
    tolerance_pct: float = Field(description="tolerance, % of the best fitness")
    tolerance_m: float | None = Field(None, description="tolerance [m]")
    best_fitness_m: float | None = Field(None, description="best fitness (or aggregate score) [m]")
    count: int = Field(description="designs in the near-optimal set")
    evaluated: int = Field(description="successfully evaluated designs")
    ranges: dict[str, list[float]] = Field({}, description="[min, max] over the near-optimal set, units in the keys "
                                               "(a2_deg: the shortest arc, max may exceed 360)")
    explored: dict[str, list[float]] = Field({}, description="[min, max] over every evaluated design")
    verdicts: dict[str, Literal["decided", "loose", "undetermined", "fixed"]] = Field({})
    sentences: list[str] = Field(description="which variables are decided, in words")
    sensitivity: SensitivityOut | None = Field(None, description="with sensitivity=true, single roads")
    numerical_band: BandOut | None = Field(None, description="with band=true, single roads: the best's "
                                           "numerical band")
    ties: list[TieOut] | None = Field(None, description="with band=true, single roads: the best distinct designs "
                                      "(the best first) with their bands, and which tie with the best")
    model_bands: ModelBandsOut | None = Field(None, description="with model_band=true, single roads: the best "
                                              "designs under each modelling alternative")
    final_population: PopulationOut | None = Field(None, description="a DE's last stored population")


class PopulationOut(BaseModel):
    count: int = Field(description="successfully evaluated members")
    ranges: dict[str, list[float]] = Field(description="[min, max] of a2_deg (shortest arc), l2_m, rws_m, fitness_m")

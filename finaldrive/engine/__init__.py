"""finaldrive's simulation engine: the paper's 2D multibody motorcycle, its solvers, and studies.

This module is the engine's one public interface (import contracts in pyproject.toml hold
``finaldrive.workers`` and ``finaldrive.service`` to it): ``simulate`` one design,
``evaluate`` a batch, the values they take and return, the vehicle, roads and the study layer.
Names load on first use, so importing the facade costs nothing until a name is used.
Nothing here reads files or the environment except ``load_vehicle``.
"""

if __name__ != "finaldrive.engine":  # never importable as a top-level `engine` (it would shadow others)
    raise ImportError(f"this is finaldrive.engine; import it by that name, not as {__name__!r}")

import importlib
from typing import TYPE_CHECKING, Any

#: Bumped whenever a change alters simulation results (part of the result-cache key).
ENGINE_VERSION = "0.3.0"

#: Public name -> module that defines it.
_EXPORTS: dict[str, str] = {
    **dict.fromkeys(("STATUS_FAILED", "STATUS_OK", "BatchResult", "Design", "DesignError", "Method", "SimResult",
                     "SimSettings"), "finaldrive.engine.api"),
    **dict.fromkeys(("DIAGNOSTICS", "RECORD", "VALUES", "Value"), "finaldrive.engine.record"),
    **dict.fromkeys(("evaluate", "simulate"), "finaldrive.engine.simulation"),
    **dict.fromkeys(("PROFILE_MAX_POINTS", "Road", "RoadError"), "finaldrive.engine.model.road"),
    "enveloped": "finaldrive.engine.model.road_envelope",
    **dict.fromkeys(("coordinate_index", "point_positions"), "finaldrive.engine.model.coordinates"),
    **dict.fromkeys(("VEHICLE_VALUE_LIMIT", "Vehicle", "VehicleError", "default_vehicle", "load_vehicle",
                     "load_vehicle_dict"), "finaldrive.engine.vehicle"),
    "static_geometry": "finaldrive.engine.geometry",
    **dict.fromkeys(("compile_engine", "compile_progress", "is_compiled"), "finaldrive.engine.precompile"),
    "start_runtime": "finaldrive.engine.jit.kernel",
    **dict.fromkeys(("FIELDS", "Field", "base_of", "design_label", "history_record", "human", "unit_of"),
                    "finaldrive.engine.fields"),
    **dict.fromkeys(("MAX_TRAVEL_POINTS", "TRAVEL_POINTS", "drive_squat", "travel_kinematics"),
                    "finaldrive.engine.travel"),
    "TravelError": "finaldrive.engine.model.rear_travel",
    **dict.fromkeys(("Cost", "estimate_cost"), "finaldrive.engine.cost"),
    **dict.fromkeys(("StaticLoads", "calibration_design", "solve_chassis_cog", "solve_torque", "static_loads"),
                    "finaldrive.engine.calibrate"),
    **dict.fromkeys(("CMAES", "DifferentialEvolution", "OPTIMISERS", "Optimiser", "plain_json", "with_population",
                     "without_population"),
                    "finaldrive.engine.optimize"),
    **dict.fromkeys(("BAND_LIMIT_M", "TIE_CANDIDATES", "TIGHT_FACTOR", "band_of", "band_settings", "best_distinct",
                     "numerical_bands", "reference_refusal", "tie_flags"), "finaldrive.engine.study.band"),
    **dict.fromkeys(("ALTERNATIVES", "Alternative", "model_bands", "ranking_change"),
                    "finaldrive.engine.study.model_band"),
    **dict.fromkeys(("CONCENTRIC_L2_M", "DEFAULT_TOLERANCE_PCT", "MAX_TOLERANCE_PCT", "SENSITIVITY_STEPS", "angle_arc",
                     "finite_differences", "near_mask", "near_optimal", "near_summary", "sensitivities",
                     "sensitivity_sentences", "sensitivity_stencil", "spread", "upper_limits"),
                    "finaldrive.engine.study.sharpness"),
    **dict.fromkeys(("PRESETS", "GROUPS", "NamedRoad", "ProfileResolver", "paper_row", "paper_tables", "preset_group",
                     "resolve_roads"), "finaldrive.engine.study.presets"),
    **dict.fromkeys(("MAX_GRID_DESIGNS", "TABLE9_DEFAULT_RWS_M", "parse_grid", "product_grid", "table9_grid"),
                    "finaldrive.engine.study.sweep"),
    **dict.fromkeys(("DE_HELP", "DE_INTEGRAL", "DE_LIMITS", "DE_OPTIONAL", "DE_PRESETS", "Bounds", "DESettings",
                     "SpaceError"), "finaldrive.engine.study.space"),
    **dict.fromkeys(("AGGREGATES", "Aggregate", "Regret", "aggregate", "best_per_road", "fitness_values", "regret",
                     "score"), "finaldrive.engine.study.scoring"),
    **dict.fromkeys(("DERun", "Request", "SweepRun"), "finaldrive.engine.study.runs"),
    **dict.fromkeys(("PAPER_SWEEP_STEP", "STUDY_KINDS", "SWEEP_RUN", "PlanError", "Run", "StudyKind", "StudyPlan",
                     "plan_study"), "finaldrive.engine.study.plan"),
}

__all__ = ["ENGINE_VERSION", *sorted(_EXPORTS)]


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'finaldrive.engine' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return list(__all__)


if TYPE_CHECKING:  # the same names, for type checkers (explicit re-exports)
    from finaldrive.engine.api import (
        STATUS_FAILED as STATUS_FAILED,
        STATUS_OK as STATUS_OK,
        BatchResult as BatchResult,
        Design as Design,
        DesignError as DesignError,
        Method as Method,
        SimResult as SimResult,
        SimSettings as SimSettings,
    )
    from finaldrive.engine.calibrate import (
        StaticLoads as StaticLoads,
        calibration_design as calibration_design,
        solve_chassis_cog as solve_chassis_cog,
        solve_torque as solve_torque,
        static_loads as static_loads,
    )
    from finaldrive.engine.cost import Cost as Cost, estimate_cost as estimate_cost
    from finaldrive.engine.fields import (
        FIELDS as FIELDS,
        Field as Field,
        base_of as base_of,
        design_label as design_label,
        history_record as history_record,
        human as human,
        unit_of as unit_of,
    )
    from finaldrive.engine.geometry import static_geometry as static_geometry
    from finaldrive.engine.jit.kernel import start_runtime as start_runtime
    from finaldrive.engine.model.coordinates import (
        coordinate_index as coordinate_index,
        point_positions as point_positions,
    )
    from finaldrive.engine.model.rear_travel import TravelError as TravelError
    from finaldrive.engine.model.road import (
        PROFILE_MAX_POINTS as PROFILE_MAX_POINTS,
        Road as Road,
        RoadError as RoadError,
    )
    from finaldrive.engine.model.road_envelope import enveloped as enveloped
    from finaldrive.engine.optimize import (
        CMAES as CMAES,
        OPTIMISERS as OPTIMISERS,
        DifferentialEvolution as DifferentialEvolution,
        Optimiser as Optimiser,
        plain_json as plain_json,
        with_population as with_population,
        without_population as without_population,
    )
    from finaldrive.engine.precompile import (
        compile_engine as compile_engine,
        compile_progress as compile_progress,
        is_compiled as is_compiled,
    )
    from finaldrive.engine.record import (
        DIAGNOSTICS as DIAGNOSTICS,
        RECORD as RECORD,
        VALUES as VALUES,
        Value as Value,
    )
    from finaldrive.engine.simulation import evaluate as evaluate, simulate as simulate
    from finaldrive.engine.study.band import (
        BAND_LIMIT_M as BAND_LIMIT_M,
        TIE_CANDIDATES as TIE_CANDIDATES,
        TIGHT_FACTOR as TIGHT_FACTOR,
        band_of as band_of,
        band_settings as band_settings,
        best_distinct as best_distinct,
        numerical_bands as numerical_bands,
        reference_refusal as reference_refusal,
        tie_flags as tie_flags,
    )
    from finaldrive.engine.study.model_band import (
        ALTERNATIVES as ALTERNATIVES,
        Alternative as Alternative,
        model_bands as model_bands,
        ranking_change as ranking_change,
    )
    from finaldrive.engine.study.plan import (
        PAPER_SWEEP_STEP as PAPER_SWEEP_STEP,
        STUDY_KINDS as STUDY_KINDS,
        SWEEP_RUN as SWEEP_RUN,
        PlanError as PlanError,
        Run as Run,
        StudyKind as StudyKind,
        StudyPlan as StudyPlan,
        plan_study as plan_study,
    )
    from finaldrive.engine.study.presets import (
        GROUPS as GROUPS,
        PRESETS as PRESETS,
        NamedRoad as NamedRoad,
        ProfileResolver as ProfileResolver,
        paper_row as paper_row,
        paper_tables as paper_tables,
        preset_group as preset_group,
        resolve_roads as resolve_roads,
    )
    from finaldrive.engine.study.runs import DERun as DERun, Request as Request, SweepRun as SweepRun
    from finaldrive.engine.study.scoring import (
        AGGREGATES as AGGREGATES,
        Aggregate as Aggregate,
        Regret as Regret,
        aggregate as aggregate,
        best_per_road as best_per_road,
        fitness_values as fitness_values,
        regret as regret,
        score as score,
    )
    from finaldrive.engine.study.sharpness import (
        CONCENTRIC_L2_M as CONCENTRIC_L2_M,
        DEFAULT_TOLERANCE_PCT as DEFAULT_TOLERANCE_PCT,
        MAX_TOLERANCE_PCT as MAX_TOLERANCE_PCT,
        SENSITIVITY_STEPS as SENSITIVITY_STEPS,
        angle_arc as angle_arc,
        finite_differences as finite_differences,
        near_mask as near_mask,
        near_optimal as near_optimal,
        near_summary as near_summary,
        sensitivities as sensitivities,
        sensitivity_sentences as sensitivity_sentences,
        sensitivity_stencil as sensitivity_stencil,
        spread as spread,
        upper_limits as upper_limits,
    )
    from finaldrive.engine.study.space import (
        DE_HELP as DE_HELP,
        DE_INTEGRAL as DE_INTEGRAL,
        DE_LIMITS as DE_LIMITS,
        DE_OPTIONAL as DE_OPTIONAL,
        DE_PRESETS as DE_PRESETS,
        Bounds as Bounds,
        DESettings as DESettings,
        SpaceError as SpaceError,
    )
    from finaldrive.engine.study.sweep import (
        MAX_GRID_DESIGNS as MAX_GRID_DESIGNS,
        TABLE9_DEFAULT_RWS_M as TABLE9_DEFAULT_RWS_M,
        parse_grid as parse_grid,
        product_grid as product_grid,
        table9_grid as table9_grid,
    )
    from finaldrive.engine.travel import (
        MAX_TRAVEL_POINTS as MAX_TRAVEL_POINTS,
        TRAVEL_POINTS as TRAVEL_POINTS,
        drive_squat as drive_squat,
        travel_kinematics as travel_kinematics,
    )
    from finaldrive.engine.vehicle import (
        VEHICLE_VALUE_LIMIT as VEHICLE_VALUE_LIMIT,
        Vehicle as Vehicle,
        VehicleError as VehicleError,
        default_vehicle as default_vehicle,
        load_vehicle as load_vehicle,
        load_vehicle_dict as load_vehicle_dict,
    )

"""The paper's 23 road presets and their reference rows (Tables 11-13)."""

from __future__ import annotations

import pytest

from finaldrive.engine.model.road import Road
from finaldrive.engine.study.presets import PAPER_KEYS, PRESETS, NamedRoad, paper_tables, preset_group, resolve_roads


def test_shipped_tables_hold_the_papers_printed_values() -> None:
    """Spot checks typed from the paper's text, so a damaged data file is caught."""
    t = paper_tables()
    assert (len(t["table11_flat"]), len(t["table12_sine"]), len(t["table13_gaussian"])) == (1, 16, 6)
    assert {k: t["table11_flat"][0][k] for k in ("a2_deg", "L2_m", "R_WS_m", "fitness_m")} == {
        "a2_deg": 195.3, "L2_m": 0.037, "R_WS_m": 0.088, "fitness_m": 20.708}
    g1, g2 = t["table14_geometries"]["geometry1"], t["table14_geometries"]["geometry2"]
    assert (g1["d_m"], g2["d_m"], g1["SR"], g2["SR"], g2["slack_mm"]) == (19.868, 19.497, 1.092, 0.239, 67.27)
    assert t["table10_de"] == {"NP": 50, "F": 0.6, "CP": 0.6, "MP": 0.1, "MR_fraction_of_range": 0.2, "IterMax": 50}
    # Table 12's (0.04 m, 3 m) row, consistent with Table 14's geometry 1 on the same road
    row = next(r for r in t["table12_sine"] if (r["H_y_m"], r["lambda_m"]) == (0.04, 3.0))
    assert row["fitness_m"] == 19.861


def test_23_roads_split_1_16_6_with_unique_names() -> None:
    presets = preset_group("paper")
    assert len(presets) == len(PRESETS) == 23
    kinds = [p.road.kind for p in presets]
    assert (kinds.count("flat"), kinds.count("sine"), kinds.count("bump")) == (1, 16, 6)
    assert len({p.name for p in presets}) == 23
    assert len({p.road for p in presets}) == 23
    assert [p.name for p in preset_group("sine")] == [p.name for p in presets[1:17]]
    assert [p.name for p in preset_group("bump")] == [p.name for p in presets[17:]]


def test_names_and_roads_follow_the_paper() -> None:
    assert PRESETS["flat"].road == Road("flat")
    assert PRESETS["sine:0.04:3"].road == Road("sine", height=0.04, wavelength=3.0)
    assert PRESETS["bump:0.04:0.2:5"].road == Road("bump", height=0.04, sigma=0.2, mu=5.0)
    sines = {(p.road.height, p.road.wavelength) for p in preset_group("sine")}
    assert sines == {(h, lam) for h in (0.01, 0.02, 0.03, 0.04) for lam in (2.0, 3.0, 4.0, 5.0)}
    bumps = {(p.road.height, p.road.sigma, p.road.mu) for p in preset_group("bump")}
    assert bumps == {(h, s, 5.0) for h in (0.02, 0.04) for s in (0.2, 0.5, 1.0)}


def test_specs_parse_back() -> None:
    for preset in PRESETS.values():
        assert Road.parse(preset.spec) == preset.road
        assert resolve_roads(preset.spec) == [preset]


def test_reference_rows_match_tables_11_to_13() -> None:
    tables = paper_tables()
    rows = tables["table11_flat"] + tables["table12_sine"] + tables["table13_gaussian"]
    presets = preset_group("paper")
    for preset, row in zip(presets, rows, strict=True):
        printed = {"a2_deg": row["a2_deg"], "l2_m": row["L2_m"], "rws_m": row["R_WS_m"],
                   "slack_m": row["slack_mm"] / 1000.0, "squat_ratio": row["SR"], "fitness_m": row["fitness_m"]}
        assert preset.paper == printed and tuple(printed) == PAPER_KEYS  # the paper's columns, renamed
        if preset.road.kind == "sine":
            assert (preset.road.height, preset.road.wavelength) == (row["H_y_m"], row["lambda_m"])
        if preset.road.kind == "bump":
            assert (preset.road.height, preset.road.sigma) == (row["H_y_m"], row["sigma_m"])
    assert PRESETS["flat"].paper["fitness_m"] == 20.708
    # the check row of docs/engine.md#reading-notes-extraction-faults
    assert PRESETS["sine:0.04:3"].paper["fitness_m"] == 19.861
    assert PRESETS["sine:0.04:2"].paper["a2_deg"] == 371.0       # printed; wraps to 11 deg
    assert PRESETS["bump:0.04:0.2:5"].paper["fitness_m"] == 20.584


def test_resolve_roads_mixes_groups_names_and_specs_in_order() -> None:
    roads = resolve_roads("flat, sine:0.01:2 ,sine:0.04:3,bump:0.03:0.4:6")
    assert [r.name for r in roads] == ["flat", "sine:0.01:2", "sine:0.04:3", "bump:0.03:0.4:6"]
    assert roads[2].paper is not None and roads[3].paper is None and isinstance(roads[3], NamedRoad)
    assert len(resolve_roads("paper")) == 23
    assert len(resolve_roads("bump,paper,flat")) == 23          # repeats dropped
    assert [r.name for r in resolve_roads("bump,flat")][-1] == "flat"
    assert resolve_roads("SINE-H1CM-L2M") == [PRESETS["sine:0.01:2"]]   # an earlier name: read, not printed
    assert resolve_roads("bump-h4cm-s20cm")[0].name == "bump:0.04:0.2:5"


@pytest.mark.parametrize("text, bad", [
    ("paper,nope", "nope"),
    ("sine:0.01", "sine:0.01"),
    ("flat,bump:0.02:-1", "bump:0.02:-1"),
    ("flat,,sine", "empty"),
    ("", "non-empty"),
])
def test_resolve_roads_errors_name_the_bad_item(text: str, bad: str) -> None:
    with pytest.raises(ValueError, match=bad):
        resolve_roads(text)


def test_unknown_group() -> None:
    with pytest.raises(ValueError, match="gravel"):
        preset_group("gravel")

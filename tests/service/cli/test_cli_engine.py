"""The local engine commands: JSON outputs, batch order, exit code 2 on bad arguments."""

from __future__ import annotations

import json
import subprocess

import pytest

from finaldrive.engine import default_vehicle
from finaldrive.service.cli import main
from tests.service.processes import console_script


def run(argv, capsys):
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


def test_geometry_json(capsys):
    code, out, _ = run(["geometry", "--a2-deg", "0", "--l2-m", "0", "--rws-m", "0.093", "--json"], capsys)
    g = json.loads(out)
    assert code == 0
    assert g["squat_ratio"] == pytest.approx(1.092, abs=0.01)     # Table 14, geometry 1
    assert g["res_m"] == pytest.approx(0.0465)
    assert (g["engine_sprocket_x_m"], g["engine_sprocket_y_m"]) == (0.0, 0.0)
    assert g["chain_length_m"] > g["taut_length_m"] > 0.5


def test_simulate_json_keys_and_series(tmp_path, capsys):
    series = tmp_path / "s.csv"
    code, out, _ = run(["simulate", "--a2-deg", "195.3", "--l2-m", "0.037", "--rws-m", "0.088", "--road", "flat",
                        "--duration", "0.5", "--json", "--series", str(series)], capsys)
    r = json.loads(out)
    assert code == 0
    for key in ("distance_m", "squat_ratio", "slack_m", "fitness_m", "chain_length_m", "status", "reason", "wall_s"):
        assert key in r
    assert r["status"] == "ok" and r["distance_m"] > 0
    lines = series.read_text().splitlines()
    assert lines[0].startswith("t_s,distance_m,pitch_deg,chain_tension_n")
    assert len(lines) == 1 + 51  # header, t = 0 and every 10th of 500 steps


def test_evaluate_keeps_input_order(tmp_path, capsys):
    designs = tmp_path / "d.csv"
    designs.write_text("a2_deg,l2_m,rws_m\n0,0,0.093\n270,0.15,0.05\n195.3,0.037,0.088\n")
    code, out, _ = run(["evaluate", "--designs", str(designs), "--road", "flat", "--duration", "0.3", "--json"], capsys)
    rows = json.loads(out)
    assert code == 0
    got = [v for r in rows for v in (r["a2_deg"], r["l2_m"], r["rws_m"])]
    assert got == pytest.approx([0, 0, 0.093, 270, 0.15, 0.05, 195.3, 0.037, 0.088])
    assert all(r["status"] == "ok" for r in rows)
    designs.write_text("a2_deg,l2_m,rws_m\n0,0,0.093\n0,0.1,0.3\n")
    code, _, err = run(["evaluate", "--designs", str(designs), "--road", "flat", "--json"], capsys)
    assert code == 2 and "line 3: rws = 0.3 m: must be <= 0.2 m" in err


def test_model_band_ranks_the_designs_under_each_alternative(tmp_path, capsys):
    designs = tmp_path / "d.csv"
    designs.write_text("a2_deg,l2_m,rws_m\n0,0,0.093\n270,0.15,0.05\n195.3,0.037,0.088\n")
    argv = ["model-band", "--designs", str(designs), "--road", "sine:0.02:3", "--duration", "0.3"]
    code, out, _ = run([*argv, "--json"], capsys)
    r = json.loads(out)
    assert code == 0 and r["road"] == "sine:0.02:3" and len(r["designs"]) == 3 and r["skipped"] == []
    assert set(r["alternatives"]) == {"tyre_load_range_4800", "drive_half", "drive_double", "drive_launch",
                                      "front_wheel_spin", "chain_elastic", "road_phase_90", "road_phase_180",
                                      "road_enveloped"}
    for alt in r["alternatives"].values():
        assert len(alt["fitness_m"]) == 3 and -1 <= alt["rank_correlation"] <= 1 and alt["what"]
    code, out, _ = run(argv, capsys)
    assert code == 0 and "drive_double" in out and "rank_correlation" in out
    designs.write_text("a2_deg,l2_m,rws_m\n0,0,0.093\n")
    code, _, err = run(["model-band", "--designs", str(designs), "--road", "flat"], capsys)
    assert code == 2 and "at least 2 designs" in err


@pytest.mark.parametrize("argv, fragment", [
    (["simulate", "--a2-deg", "0", "--l2-m", "0", "--rws-m", "0.09", "--road", "cobbles"], "cobbles"),
    (["simulate", "--a2-deg", "0", "--l2-m", "-0.1", "--rws-m", "0.09", "--road", "flat"], "l2"),
    (["simulate", "--a2-deg", "0", "--l2-m", "0", "--rws-m", "0", "--road", "flat"], "rws"),
    (["geometry", "--a2-deg", "abc", "--l2-m", "0", "--rws-m", "0.09"], "a2-deg"),
    (["simulate", "--a2-deg", "0", "--l2-m", "0", "--rws-m", "0.09", "--road", "flat", "--duration", "-1"], "duration"),
    # the vehicle's design limits (issue 14): L2 <= l2_max, R_WS inside the rear tyre
    (["geometry", "--a2-deg", "0", "--l2-m", "5", "--rws-m", "0.09"], "--l2-m: l2 = 5 m: must be <= l2_max = 0.2 m"),
    (["simulate", "--a2-deg", "0", "--l2-m", "0", "--rws-m", "0.5", "--road", "flat"],
     "--rws-m: rws = 0.5 m: must be <= 0.2 m, the rear tyre's radius rt0 = 0.3 m less rws_tyre_margin = 0.1 m"),
    (["sweep", "--road", "flat", "--grid", "a2_deg=0,l2_m=0.3,rws_m=0.09"], "grid: design 0 has l2_m = 0.3 m"),
    (["optimize", "--road", "flat", "--bounds", "rws_m=0.05:0.25"], "bounds.rws_m: upper bound 0.25 m"),
    (["simulate", "--a2-deg", "0", "--l2-m", "0", "--rws-m", "0.09", "--road", "sine:1e308:1e-308"], "within +-0.5 m"),
])
def test_bad_arguments_exit_2_with_one_line(argv, fragment, capsys):
    code, _, err = run(argv, capsys)
    assert code == 2
    assert len(err.strip().splitlines()) == 1
    assert fragment in err


def test_console_script_is_installed():
    exe = console_script("finaldrive")
    out = subprocess.run([exe, "geometry", "--a2-deg", "0", "--l2-m", "0",
                          "--rws-m", "0.093", "--json"], capture_output=True, text=True, check=True)
    assert json.loads(out.stdout)["squat_ratio"] > 1


def test_a_closed_pipe_ends_quietly():
    exe = console_script("finaldrive")
    proc = subprocess.run(f"{exe} roads | head -1", shell=True, capture_output=True, text=True)
    assert proc.stdout.startswith("road")
    assert "Traceback" not in proc.stderr


def test_geometry_travel_json_png_and_road(tmp_path, capsys):
    png = tmp_path / "travel.png"
    code, out, _ = run(["geometry", "--a2-deg", "0", "--l2-m", "0", "--rws-m", "0.093", "--travel", "--points", "5",
                        "--png", str(png), "--road", "flat", "--duration", "0.2", "--json"], capsys)
    g = json.loads(out)
    assert code == 0 and png.read_bytes()[:4] == b"\x89PNG"
    assert len(g["travel_curve"]["curve"]) == 5
    assert g["travel_curve"]["design_pose"]["squat_ratio"] == pytest.approx(g["squat_ratio"], rel=1e-12)
    assert g["drive_squat"]["status"] == "ok" and "squat_mean_m" in g["drive_squat"]


def test_geometry_travel_text_marks_design_and_sag(capsys):
    code, out, _ = run(["geometry", "--a2-deg", "0", "--l2-m", "0", "--rws-m", "0.093", "--travel", "--points", "3"],
                       capsys)
    assert code == 0
    assert "<- design pose" in out and "<- static sag" in out and "anti-squat" in out


@pytest.mark.parametrize("change", [{"chain_compliance": 1.0}, {"chain_runs": 2.0}])
@pytest.mark.parametrize("command", [["simulate", "--a2-deg", "0", "--l2-m", "0", "--rws-m", "0.09"],
                                     ["sweep", "--grid", "a2_deg=0,l2_m=0,rws_m=0.09"], ["optimize"]])
def test_a_fast_only_vehicle_with_the_reference_method_exits_2_naming_the_parameter(change, command, tmp_path,
                                                                                  capsys):
    vehicle = tmp_path / "vehicle.json"
    vehicle.write_text(json.dumps(default_vehicle().replace(**change).to_dict()))
    code, _, err = run([*command, "--road", "flat", "--vehicle", str(vehicle), "--method", "reference"], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert next(iter(change)) in err and "fast method only" in err

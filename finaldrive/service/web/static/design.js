// The design page: one or two designs on a road, simulated by a recording request; their Fig. 13 time
// series (interactive) and the rerun recording of both, side by side, in rerun's web viewer.
import { api, clearProblem, el, localUrl, num, showBanner, showProblem } from "/static/api.js";
import { lineChart } from "/static/charts.js";

const $ = (id) => document.getElementById(id);
const COLOURS = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd"];
const SERIES = [
  ["distance_m", "distance [m]"], ["chain_tension_n", "chain tension [N]"], ["squat_ratio", "squat ratio [-]"],
  ["fz_rear_n", "rear tyre load Fz [N]"], ["fz_front_n", "front tyre load Fz [N]"], ["kappa", "rear slip kappa [-]"],
  ["fx_n", "rear tyre force Fx [N]"],
];
const OUTCOME = [["distance_m", "distance [m]", 4], ["fitness_m", "fitness [m]", 4], ["squat_ratio", "squat ratio", 3],
                 ["slack_m", "slack [m]", 4], ["chain_tension_max_n", "max chain tension [N]", 0],
                 ["fz_rear_max_n", "max rear load [N]", 0]];

// over the rear travel (GET /v1/geometry?travel=true): each chart's field and label; the table's, at a pose
const TRAVEL = [["anti_squat_pct", "anti-squat [%]"], ["anti_rise_pct", "anti-rise [%]"],
                ["kickback_deg", "kickback [deg]"], ["leverage_ratio", "leverage ratio [-]"]];
const TRAVEL_FACTS = [
  [(t) => t.engine_sprocket_teeth, "engine sprocket teeth", 1], [(t) => t.wheel_sprocket_teeth, "wheel sprocket teeth", 1],
  [(t) => t.chain_links, "chain links", 1], [(t) => t.static_sag.anti_squat_pct, "anti-squat at sag [%]", 0],
  [(t) => t.static_sag.anti_rise_pct, "anti-rise at sag [%]", 0], [(t) => t.static_sag.leverage_ratio, "leverage at sag", 2],
  [(t) => t.curve.at(-1).kickback_deg, "kickback, full compression [deg]", 2],
  [(t) => t.fork_angle_deg, "fork angle [deg]", 1], [(t) => t.anti_dive_pct, "anti-dive [%]", 0],
];

function fromQuery() {
  const q = new URLSearchParams(location.search);
  if (q.get("road")) $("road").value = q.get("road");
  for (const k of ["a", "b"]) {
    const v = (q.get(k) ?? "").split(",").map(Number);
    if (v.length === 3 && v.every(Number.isFinite)) [$(`${k}-a2`).value, $(`${k}-l2`).value, $(`${k}-rws`).value] = v;
    if (q.get(`label_${k}`)) $(`${k}-label`).value = q.get(`label_${k}`);
  }
  return q.has("a");
}

function designs() {
  const out = [];
  for (const k of ["a", "b"]) {
    const values = [`${k}-a2`, `${k}-l2`, `${k}-rws`].map((id) => $(id).value.trim());
    if (k === "b" && values.every((v) => v === "")) continue;
    out.push({ a2_deg: Number(values[0] || NaN), l2_m: Number(values[1] || NaN), rws_m: Number(values[2] || NaN),
               label: $(`${k}-label`).value.trim() || k.toUpperCase() });
  }
  return out;
}

const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

// rerun's viewer takes seconds to start (43 MB of wasm, its shaders): it starts with a run, beside the
// simulation, and is handed the recording's bytes through a channel as soon as both are there (the handle the
// service's copy of its page leaves on its window, service/web/viewer.py); without a handle it is loaded again
// with the recording's URL.
const VIEWER = "/viewer/?hide_welcome_screen&persist=0";
let viewerRun = 0; // counts the viewers started: a later one ends the wait for an earlier

function startViewer() {
  viewerRun += 1;
  $("viewer").src = `${VIEWER}&run=${viewerRun}`; // a fresh viewer for each run
  $("viewer-card").hidden = false;
}

function stopViewer() {
  viewerRun += 1;
  $("viewer").src = "about:blank";
  $("viewer-card").hidden = true;
}

async function openInViewer(file) {
  const frame = $("viewer");
  const mine = viewerRun;
  const answer = await fetch(file);
  if (!answer.ok) throw new Error(`the recording's file: ${answer.status}`);
  const bytes = new Uint8Array(await answer.arrayBuffer());
  for (let waited = 0; waited < 120_000 && mine === viewerRun; waited += 100) {
    const handle = frame.contentWindow?.finaldriveViewer;
    if (handle) {
      handle.open_channel("recording", "recording");
      handle.send_rrd_to_channel("recording", bytes);
      return;
    }
    await sleep(100);
  }
  if (mine === viewerRun) frame.src = `${VIEWER}&url=${encodeURIComponent(file)}`;
}

async function run(event) {
  event?.preventDefault();
  clearProblem($("designs"), $("form-error"));
  $("run").disabled = true;
  try {
    const body = { road: $("road").value.trim(), designs: designs(), duration: Number($("duration").value), fps: 50 };
    let rec = await api("/v1/recordings", { method: "POST", body });
    startViewer();
    const started = Date.now();
    while (rec.status === "queued" || rec.status === "running") {
      $("status").textContent = `simulating and recording… ${((Date.now() - started) / 1000).toFixed(0)} s`;
      await sleep(500);
      rec = await api(`/v1/recordings/${rec.id}`);
    }
    if (rec.status !== "succeeded") throw new Error(rec.error || `the recording ${rec.status}`);
    $("status").textContent = `recording #${rec.id}`;
    await show(rec);
  } catch (e) {
    showProblem($("designs"), e.problem ?? { detail: e.message }, $("form-error"));
    $("status").textContent = "";
    stopViewer();
  } finally {
    $("run").disabled = false;
  }
}

async function show(rec) {
  const data = await api(`/v1/recordings/${rec.id}/series`);
  const head = el("tr", {}, el("th", {}, "design"), el("th", { class: "num" }, "a2 [deg]"), el("th", { class: "num" }, "L2 [m]"),
                  el("th", { class: "num" }, "R_WS [m]"), ...OUTCOME.map(([, label]) => el("th", { class: "num" }, label)));
  $("outcome").tHead.replaceChildren(head);
  $("outcome").tBodies[0].replaceChildren(...data.runs.map((r, k) => el("tr", {},
    el("td", {}, el("span", { style: `color:${COLOURS[k]}` }, "■ "), r.label), el("td", { class: "num" }, num(r.a2_deg, 2)),
    el("td", { class: "num" }, num(r.l2_m, 4)), el("td", { class: "num" }, num(r.rws_m, 4)),
    ...OUTCOME.map(([key, , d]) => el("td", { class: "num" }, num(r.outcome[key], d))))));
  $("outcome-card").hidden = false;
  $("series-card").hidden = false;
  const boxes = SERIES.map(() => el("div", { class: "chart-box" }));
  $("series").replaceChildren(...boxes);
  SERIES.forEach(([key, label], i) => lineChart(boxes[i], data.runs.map((r, k) => ({
    name: r.label, x: data.t_s, y: r.series[key], colour: COLOURS[k],
  })), { xLabel: "t [s]", yLabel: label, title: label, height: 220 }));
  await showTravel(data.runs);
  $("download").href = localUrl(`/v1/recordings/${encodeURIComponent(rec.id)}/file`);
  // the file ends in .rrd (how the viewer knows it, loaded with its URL) and is signed when the server has a token
  openInViewer(localUrl(rec.viewer_file)).catch((e) => showBanner(`the viewer: ${e.message}`));
}

async function showTravel(runs) {
  const curves = await Promise.all(runs.map((r) => api(`/v1/geometry?${new URLSearchParams({
    a2_deg: r.a2_deg, l2_m: r.l2_m, rws_m: r.rws_m, travel: "true" })}`)));
  $("travel-table").tHead.replaceChildren(el("tr", {}, el("th", {}, "design"),
    ...TRAVEL_FACTS.map(([, label]) => el("th", { class: "num", style: "white-space: normal" }, label))));
  $("travel-table").tBodies[0].replaceChildren(...curves.map((g, k) => el("tr", {},
    el("td", {}, el("span", { style: `color:${COLOURS[k]}` }, "■ "), runs[k].label),
    ...TRAVEL_FACTS.map(([get, , d]) => el("td", { class: "num" }, num(get(g.travel_curve), d))))));
  const boxes = TRAVEL.map(() => el("div", { class: "chart-box" }));
  $("travel").replaceChildren(...boxes);
  TRAVEL.forEach(([key, label], i) => lineChart(boxes[i], curves.map((g, k) => ({
    name: runs[k].label, x: g.travel_curve.curve.map((c) => 1000 * c.travel_m),
    y: g.travel_curve.curve.map((c) => c[key]), colour: COLOURS[k],
  })), { xLabel: "rear wheel travel [mm]", yLabel: label, title: label, height: 220 }));
  $("travel-card").hidden = false;
}

async function init() {
  const roads = await api("/v1/roads");
  $("road-list").replaceChildren(...roads.map((r) => el("option", { value: r.spec }, r.name)));
  $("designs").addEventListener("submit", run);
  if (fromQuery()) await run();
  document.body.dataset.ready = "1";
}

init().catch((e) => showBanner(`could not load the page: ${e.message}`));

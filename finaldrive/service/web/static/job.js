// The job page: live progress and ETA, the best design per road with its near-optimal set, the interactive
// sweep map, the DE history, a scatter of every evaluation and the evaluations table.
import { api, designParam, duration, el, num, pageLink, progressBar, showBanner, stream } from "/static/api.js";
import { lineChart, polarMap, scatter } from "/static/charts.js";

const $ = (id) => document.getElementById(id);
const jobId = Number(location.pathname.split("/").filter(Boolean).pop());
const TERMINAL = new Set(["succeeded", "failed", "cancelled"]);
const COLUMNS = [
  ["id", "id", 0], ["a2_deg", "a2 [deg]", 2], ["l2_m", "L2 [m]", 4], ["rws_m", "R_WS [m]", 4],
  ["distance_m", "distance [m]", 4], ["fitness_m", "fitness [m]", 4], ["squat_ratio", "squat ratio", 3],
  ["slack_m", "slack [m]", 4], ["step", "step", 0], ["status", "status", null], ["reason", "reason", null],
];
const AXES = [["a2_deg", "a2 [deg]"], ["l2_m", "L2 [m]"], ["rws_m", "R_WS [m]"], ["distance_m", "distance [m]"],
              ["fitness_m", "fitness [m]"], ["squat_ratio", "squat ratio [-]"]];
const PAGE = 25;
let job = null;
let points = null; // columns of the chosen road's evaluations
let best = null;
let banded = false; // the numerical bands were asked for: /best?band=true from then on
let modelBanded = false; // the model bands were asked for: /best?model_band=true from then on
let sort = { key: "fitness_m", desc: true };
let page = 0;

function summary() {
  const rows = [
    ["state", el("span", { class: `state ${job.state}` }, job.state)],
    ["progress", el("span", {}, progressBar(job.progress, job.state), ` ${(100 * job.progress).toFixed(1)} %`)],
    ["evaluations", `${job.done} ok, ${job.failed} failed of ${job.total}${job.cached ? ` (${job.cached} from the cache)` : ""}`],
    ["elapsed", duration(job.elapsed_s)],
    ["ETA", TERMINAL.has(job.state) ? "–" : duration(job.eta_s)],
    ["roads", job.roads.map((r) => r.name).join(", ")],
    ["seed", job.spec.seed],
  ];
  if (job.error) rows.push(["error", job.error]);
  $("summary").replaceChildren(...rows.flatMap(([k, v]) => [el("dt", {}, k), el("dd", { "data-key": k }, v)]));
  $("title").textContent = `Job #${job.id}: ${job.kind}`;
  $("cancel").hidden = TERMINAL.has(job.state);
  document.title = `finaldrive: job ${job.id}`;
}

function bestTable() {
  const sharp = new Map((best?.sharpness ?? []).map((s) => [s.road, s]));
  const rows = [];
  const design = (d) => [num(d.a2_deg, 2), num(d.l2_m, 4), num(d.rws_m, 4)].map((v) => el("td", { class: "num" }, v));
  const link = (d, road) => el("a", { href: pageLink("/design", [["road", road], designParam(d, "a"), ["label_a", `job ${jobId} best`]]) },
                               "design page");
  for (const r of job.roads) {
    const s = sharp.get(r.name);
    rows.push(el("tr", { "data-road": r.name }, el("td", {}, r.name), ...(r.best ? design(r.best) : [el("td", { colspan: 3, class: "muted" }, "no result yet")]),
      el("td", { class: "num" }, num(r.best?.distance_m, 4)), el("td", { class: "num" }, num(r.best?.fitness_m, 4)),
      bandCell(s),
      el("td", { class: "num" }, s ? `${s.count} of ${s.evaluated} within ${s.tolerance_pct} %` : "–"),
      el("td", { class: "muted", style: "white-space: normal" }, ...lines(s ? [...s.sentences, ...tieSentence(s)] : [])),
      el("td", {}, r.best ? link(r.best, r.spec) : "")));
  }
  if (job.robust_best) {
    const rb = job.robust_best;
    const s = sharp.get(null);
    rows.push(el("tr", {}, el("td", {}, `all roads (${rb.aggregate})`), ...design(rb), el("td", {}, ""),
      el("td", { class: "num" }, num(rb.score_m, 4)), el("td", {}, ""), el("td", { class: "num" }, s ? `${s.count} of ${s.evaluated}` : "–"),
      el("td", { class: "muted", style: "white-space: normal" }, ...lines(s ? s.sentences : [])),
      el("td", {}, link(rb, job.roads[0].spec))));
  }
  $("best").tBodies[0].replaceChildren(...rows);
  $("bands").hidden = !TERMINAL.has(job.state) || banded;
  $("model-bands").hidden = !TERMINAL.has(job.state) || modelBanded;
  modelBandsTable();
}

/** Each road's best designs under each modelling alternative (service.api.model_bands), one row an alternative. */
function modelBandsTable() {
  $("model-bands-card").hidden = !modelBanded;
  if (!modelBanded) return;
  const rows = [];
  const left = [];
  for (const s of best?.sharpness ?? []) {
    const bands = s.model_bands;
    if (!bands) continue;
    for (const [name, alt] of Object.entries(bands.alternatives)) {
      const failed = alt.failed.filter(Boolean).length;
      rows.push(el("tr", { "data-road": s.road, "data-alternative": name, title: alt.what },
        el("td", {}, s.road), el("td", {}, name),
        el("td", { class: "num", "data-rho": String(alt.rank_correlation) }, alt.rank_correlation == null ? "–" : num(alt.rank_correlation, 2)),
        el("td", { class: alt.same_best ? "" : "error" }, alt.same_best ? "the same" : alt.best == null ? "none succeeded" : "another"),
        el("td", { class: "num" }, alt.largest_change_m == null ? "–" : num(alt.largest_change_m * 1000, 1)),
        el("td", { class: "muted" }, failed ? `${failed} of ${alt.failed.length}` : "")));
    }
    left.push(...bands.skipped.map((name) => `${s.road}: ${name} (${bands.skipped_reasons[name] ?? ""})`));
  }
  const pending = !TERMINAL.has(best?.model_band_state ?? "queued");
  $("model-bands-table").tBodies[0].replaceChildren(...(rows.length ? rows
    : [el("tr", {}, el("td", { colspan: 6, class: "muted" }, pending ? "simulating…" : "–"))]));
  $("model-bands-note").textContent = left.length ? `Left out: ${left.join("; ")}.` : "";
}

/** Sentences one a line (each is a whole verdict, none ends in a full stop). */
const lines = (sentences) => sentences.map((t) => el("div", {}, t));

/** A road's numerical band (engine.study.band): +-x mm, flagged above 1 mm; pending while its jobs run. */
function bandCell(s) {
  const band = s?.numerical_band;
  if (!band) return el("td", { class: "num muted", "data-band": "" }, banded && best?.band_state !== "succeeded" ? "simulating…" : "–");
  const text = band.band_m == null ? "unknown" : `±${(band.band_m * 1000).toFixed(2)} mm`;
  const failed = Object.entries(band.failed ?? {}).map(([k, v]) => `${k}: ${v}`).join("; ");
  return el("td", { class: band.exceeds_limit ? "num error" : "num", "data-band": String(band.band_m),
                    title: `re-simulated 100x tighter${band.runs?.reference ? " and with the reference method" : ""}${failed ? ` (left out: ${failed})` : ""}` }, text);
}

/** Which of the next best designs tie with the best (fitness closer than their two bands), in words. */
function tieSentence(s) {
  const ties = s.ties ?? [];
  if (ties.length < 2) return [];
  const tied = ties.slice(1).filter((t) => t.tie).length;
  return [`Of the next ${ties.length - 1} best designs, ${tied} tie with the best within their numerical bands.`];
}

/** /best with the simulations asked for so far. */
const bestUrl = () => {
  const asked = [banded && "band=true", modelBanded && "model_band=true"].filter(Boolean);
  return `/v1/jobs/${jobId}/best${asked.length ? `?${asked.join("&")}` : ""}`;
};

/** Ask for the numerical bands or the model bands (the service queues their jobs), then poll until they are there. */
async function ask(what) {
  const wait = () => new Promise((resolve) => setTimeout(resolve, 2000));
  const model = what === "model";
  if (model) modelBanded = true; else banded = true;
  $(model ? "model-bands" : "bands").hidden = true;
  bestTable();
  for (;;) {
    try {
      best = await api(bestUrl());
    } catch (e) {
      if (e.status === 429) { await wait(); continue; } // another /best in flight: as Retry-After asks
      if (model) modelBanded = false; else banded = false;
      showBanner(`${model ? "model" : "numerical"} bands: ${e.message}`, true);
      bestTable();
      return;
    }
    bestTable();
    if (TERMINAL.has(model ? best.model_band_state : best.band_state)) return;
    await wait();
  }
}

const describe = (i) => [
  `a2 = ${num(points.a2_deg[i], 2)} deg, L2 = ${num(points.l2_m[i], 4)} m, R_WS = ${num(points.rws_m[i], 4)} m`,
  `distance = ${num(points.distance_m[i], 4)} m, fitness = ${num(points.fitness_m[i], 4)} m`,
  points.status[i] === "ok" ? "" : `failed${points.reason ? `: ${points.reason[i]}` : ""}`,
].filter(Boolean); // tooltip lines (text)

let map = null;
let swingarmDeg = null; // the swingarm at static sag [deg], in a2's frame: GET /v1/geometry with the job's vehicle

/** The swingarm's direction at static sag on flat ground, for this job's vehicle (the engine's equilibrium), once:
 * at the best design of the road shown first (else its first evaluation); over the paper's whole design space it
 * moves by a hundredth of a degree. */
async function loadSwingarm() {
  const d = job.roads.find((r) => r.name === $("road").value)?.best
    ?? { a2_deg: points.a2_deg[0], l2_m: points.l2_m[0], rws_m: points.rws_m[0] };
  const query = new URLSearchParams({ a2_deg: d.a2_deg, l2_m: d.l2_m, rws_m: d.rws_m, job: jobId });
  try {
    swingarmDeg = (await api(`/v1/geometry?${query}`)).swingarm_angle_deg;
  } catch (e) {
    showBanner(`the swingarm's angle: ${e.message}`);
  }
}

function select(i) {
  const road = job.roads.find((r) => r.name === $("road").value);
  const d = { a2_deg: points.a2_deg[i], l2_m: points.l2_m[i], rws_m: points.rws_m[i] };
  const rows = AXES.map(([k, label]) => [label, num(points[k][i], k === "a2_deg" ? 2 : 4)]);
  rows.unshift(["evaluation", `#${points.id[i]} (${points.status[i]})`]);
  $("selected").replaceChildren(...rows.flatMap(([k, v]) => [el("dt", {}, k), el("dd", {}, v)]));
  $("selected").dataset.evaluation = points.id[i];
  const a = $("open-design");
  const top = road?.best;
  const query = [["road", road?.spec ?? ""], designParam(d, "a"), ["label_a", `evaluation ${points.id[i]}`]];
  if (top) query.push(designParam(top, "b"), ["label_b", `job ${jobId} best`]);
  a.href = pageLink("/design", query);
  a.hidden = false;
}

function drawMap() {
  if (!points?.id.length) {
    $("map").replaceChildren(el("p", { class: "muted" }, "no evaluations on this road yet"));
    return;
  }
  const key = $("value").value;
  const near = nearMask();
  map = polarMap($("map"), { ...points, value: points[key] }, {
    valueLabel: $("value").selectedOptions[0].textContent, near, swingarmDeg, describe,
    onSelect: (i) => (map && select(i)),
  });
  window.fdMap = map; // for the browser tests: positionOf(i), best, layout, swingarm, key
}

function nearMask() {
  const s = (best?.sharpness ?? []).find((x) => x.road === $("road").value);
  if (!s || s.tolerance_m === null || s.best_fitness_m === null) return null;
  return points.fitness_m.map((f) => f !== null && f >= s.best_fitness_m - s.tolerance_m);
}

function drawScatter() {
  if (!points?.id.length) return;
  const x = $("sx").value;
  const y = $("sy").value;
  window.fdScatter = scatter($("scatter"), { // for the browser tests: plot, shown, positionOf(i), x, y
    x: points[x], y: points[y], c: points.fitness_m, xLabel: $("sx").selectedOptions[0].textContent,
    yLabel: $("sy").selectedOptions[0].textContent, cLabel: "fitness [m]", describe, onSelect: select,
  });
}

function filtered() {
  const status = $("status-filter").value;
  const min = $("min-fitness").value === "" ? null : Number($("min-fitness").value);
  const idx = points.id.map((_, i) => i).filter((i) => (!status || points.status[i] === status)
    && (min === null || (points.fitness_m[i] !== null && points.fitness_m[i] >= min)));
  const v = points[sort.key] ?? points.id;
  idx.sort((a, b) => {
    const x = v[a];
    const y = v[b];
    if (x === y) return 0;
    if (x === null || x === undefined) return 1;
    if (y === null || y === undefined) return -1;
    return (x < y ? -1 : 1) * (sort.desc ? -1 : 1);
  });
  return idx;
}

function drawTable() {
  const columns = COLUMNS.filter(([k]) => points && k in points);
  $("evaluations").tHead.replaceChildren(el("tr", {}, ...columns.map(([k, label, digits]) => el("th", {
    class: `sortable${digits !== null ? " num" : ""}`, "data-key": k,
    onclick: () => ((sort = { key: k, desc: sort.key === k ? !sort.desc : true }), (page = 0), drawTable()),
  }, label + (sort.key === k ? (sort.desc ? " ▼" : " ▲") : "")))));
  if (!points) return;
  const idx = filtered();
  const pages = Math.max(1, Math.ceil(idx.length / PAGE));
  page = Math.min(page, pages - 1);
  $("evaluations").tBodies[0].replaceChildren(...idx.slice(page * PAGE, (page + 1) * PAGE).map((i) => el("tr", {
    onclick: () => (map ? map.select(i) : select(i)), style: "cursor: pointer",
  }, ...columns.map(([k, , digits]) => el("td", { class: digits !== null ? "num" : "" },
    digits === null ? (points[k][i] ?? "") : num(points[k][i], digits))))));
  $("page-note").textContent = `page ${page + 1} of ${pages} (${idx.length} evaluations)`;
  $("prev").disabled = page === 0;
  $("next").disabled = page >= pages - 1;
}

async function loadPoints() {
  const road = $("road").value;
  try {
    points = await api(`/v1/jobs/${jobId}/points?road=${encodeURIComponent(road)}`);
  } catch (e) {
    points = null;
    $("points-note").textContent = e.message;
    return;
  }
  $("points-note").textContent = `${points.id.length} evaluations on ${road}`;
  $("csv").href = pageLink(`/v1/jobs/${jobId}/evaluations`, [["format", "csv"], ["limit", "100000"], ["road", road]]);
  if (swingarmDeg === null && points.id.length) await loadSwingarm();
  drawMap();
  drawScatter();
  drawTable();
}

async function loadHistory() {
  if (job.kind === "sweep") return;
  let history;
  try {
    history = await api(`/v1/jobs/${jobId}/history`);
  } catch {
    return; // no generation stored yet
  }
  const run = history.runs.find((r) => r.road === $("road").value) ?? history.runs[0];
  if (!run) return;
  $("history-card").hidden = false;
  const g = run.generations;
  lineChart($("history"), [
    { name: "best fitness", x: g.map((r) => r.generation), y: g.map((r) => r.best_fitness_m), colour: "#1f77b4" },
    { name: "mean fitness", x: g.map((r) => r.generation), y: g.map((r) => r.mean_fitness_m), colour: "#ff7f0e" },
  ], { xLabel: "generation", yLabel: "fitness [m]", title: run.road ?? "all roads", height: 260 });
}

async function loadAll() {
  [job, best] = await Promise.all([api(`/v1/jobs/${jobId}`), api(bestUrl()).catch(() => best)]); // 429: keep the last
  summary();
  bestTable();
  await Promise.all([loadPoints(), loadHistory()]);
}

function live() {
  let refresh = null;
  const source = stream(`/v1/jobs/${jobId}/events`, {
    progress: async () => {
      job = await api(`/v1/jobs/${jobId}`);
      summary();
      // results at most every 3 s, and one load (one /best) in flight: the next waits for the last to answer
      if (!refresh) refresh = setTimeout(async () => { try { await loadAll(); } finally { refresh = null; } }, 3000);
    },
    end: async () => {
      source.close();
      clearTimeout(refresh);
      await loadAll();
    },
  });
}

async function init() {
  job = await api(`/v1/jobs/${jobId}`);
  $("road").replaceChildren(...job.roads.map((r) => el("option", { value: r.name }, r.name)));
  $("sx").replaceChildren(...AXES.map(([k, l]) => el("option", { value: k }, l)));
  $("sy").replaceChildren(...AXES.map(([k, l]) => el("option", { value: k, selected: k === "fitness_m" }, l)));
  $("road").addEventListener("change", () => (loadPoints(), loadHistory()));
  $("bands").addEventListener("click", () => ask("numerical"));
  $("model-bands").addEventListener("click", () => ask("model"));
  $("value").addEventListener("change", drawMap);
  $("sx").addEventListener("change", drawScatter);
  $("sy").addEventListener("change", drawScatter);
  $("status-filter").addEventListener("change", () => ((page = 0), drawTable()));
  $("min-fitness").addEventListener("input", () => ((page = 0), drawTable()));
  $("prev").addEventListener("click", () => (page--, drawTable()));
  $("next").addEventListener("click", () => (page++, drawTable()));
  $("cancel").addEventListener("click", async () => {
    try {
      job = await api(`/v1/jobs/${jobId}/cancel`, { method: "POST" });
      summary();
    } catch (e) {
      showBanner(`cancel failed: ${e.message}`);
    }
  });
  await loadAll();
  if (!TERMINAL.has(job.state)) live();
  document.body.dataset.ready = "1";
}

init().catch((e) => showBanner(e.status === 404 ? `job ${jobId} does not exist` : `could not load the job: ${e.message}`));

// The jobs page: every job with a live progress bar (one SSE stream for all), filters, and the submit form.
import { api, clearProblem, duration, el, num, progressBar, showProblem, stream } from "/static/api.js";

const $ = (id) => document.getElementById(id);
const TERMINAL = new Set(["succeeded", "failed", "cancelled"]);
let cursor = null;
let shown = new Map(); // job id -> row

function bestOf(job) {
  if (job.robust_best) return { fitness: job.robust_best.score_m, distance: null };
  const best = job.roads.map((r) => r.best).filter(Boolean);
  if (!best.length) return { fitness: null, distance: null };
  const top = best.reduce((a, b) => ((b.fitness_m ?? -Infinity) > (a.fitness_m ?? -Infinity) ? b : a));
  return { fitness: top.fitness_m, distance: top.distance_m };
}

function row(job) {
  const best = bestOf(job);
  const roads = job.roads.map((r) => r.name);
  return el("tr", { "data-job": job.id },
    el("td", {}, el("a", { href: `/jobs/${job.id}` }, `#${job.id}`)),
    el("td", {}, job.kind),
    el("td", {}, el("span", { class: `state ${job.state}` }, job.state)),
    el("td", { class: "wrap", title: roads.join(", ") }, roads.length > 3 ? `${roads.slice(0, 3).join(", ")} +${roads.length - 3}` : roads.join(", ")),
    el("td", { class: "progress" }, progressBar(job.progress, job.state)),
    el("td", { class: "num count" }, `${job.done + job.failed} / ${job.total}`),
    el("td", { class: "num" }, num(best.fitness, 4)),
    el("td", { class: "num" }, num(best.distance, 4)),
    el("td", {}, new Date(job.created_at + (job.created_at.endsWith("Z") ? "" : "Z")).toLocaleString()),
    el("td", { class: "num" }, duration(job.elapsed_s)));
}

async function load(more = false) {
  const params = new URLSearchParams({ limit: "50" });
  if ($("filter-state").value) params.set("state", $("filter-state").value);
  if ($("filter-kind").value) params.set("kind", $("filter-kind").value);
  if (more && cursor) params.set("cursor", cursor);
  const page = await api(`/v1/jobs?${params}`);
  const body = $("jobs").tBodies[0];
  if (!more) (body.replaceChildren(), (shown = new Map()));
  for (const job of page.items) {
    const tr = row(job);
    shown.set(job.id, tr);
    body.append(tr);
  }
  if (!body.children.length) body.append(el("tr", {}, el("td", { colspan: 10, class: "muted" }, "no jobs yet")));
  cursor = page.next_cursor;
  $("older").hidden = !cursor;
}

let reloadTimer = null;
function reloadSoon() {
  clearTimeout(reloadTimer);
  reloadTimer = setTimeout(() => load().catch(() => {}), 400);
}

function live() {
  const source = stream("/v1/events", {
    jobs: (changes) => {
      $("live").textContent = "live";
      for (const c of changes) {
        const tr = shown.get(c.id);
        if (!tr) {
          reloadSoon(); // a job this page does not show yet
          continue;
        }
        const state = tr.querySelector(".state");
        if (state.textContent !== c.state || TERMINAL.has(c.state)) reloadSoon(); // best and elapsed change too
        tr.querySelector(".progress").replaceChildren(progressBar(c.progress, c.state));
        tr.querySelector(".count").textContent = `${c.done + c.failed} / ${c.total}`;
      }
    },
  });
  source.onerror = () => ($("live").textContent = "reconnecting…");
  source.onopen = () => ($("live").textContent = "live");
}

// ---- the submit form ----
async function defaults() {
  const schema = await api("/openapi.json");
  const s = schema.components.schemas;
  const fill = (id, value) => value != null && ($(id).placeholder = value);
  const b = s.Bounds.properties;
  ["a2", "l2", "rws"].forEach((k) => {
    const d = b[{ a2: "a2_deg", l2: "l2_m", rws: "rws_m" }[k]].default;
    fill(`${k}-lo`, d?.[0]);
    fill(`${k}-hi`, d?.[1]);
  });
  fill("np", s.DESpec.properties.np.default);
  for (const name of s.DESpec.properties.optimiser.enum ?? []) $("optimiser").append(el("option", {}, name));
  for (const name of s.DESpec.properties.preset.anyOf?.[0]?.enum ?? s.DESpec.properties.preset.enum ?? []) $("preset").append(el("option", {}, name));
  fill("iters", s.DESpec.properties.iters.default);
  fill("duration", s.SimulationSpec.properties.duration.default);
  // FastAPI names a model's request schema "JobSpec-Input" where its JSON schema differs from the
  // response's (it does with the lowest FastAPI and pydantic pyproject.toml allows), "JobSpec" otherwise
  const spec = s.JobSpec ?? s["JobSpec-Input"];
  for (const name of spec.properties.kind.enum ?? s.JobKind?.enum ?? []) $("filter-kind").append(el("option", {}, name));
  for (const name of s.JobOut.properties.state.enum ?? s.JobStateName?.enum ?? []) $("filter-state").append(el("option", {}, name));
}

async function roadChoices() {
  const presets = await api("/v1/roads");
  $("presets").replaceChildren(...presets.map((r, i) => el("label", { title: r.description },
    el("input", { type: "checkbox", value: r.name, checked: i === 0 }), ` ${r.name}`)));
  const profiles = await api("/v1/roads/profiles?limit=100");
  $("profiles").replaceChildren(...profiles.items.map((p) => el("label", { title: `${p.n_points} points` },
    el("input", { type: "checkbox", value: p.spec }), ` ${p.spec}${p.name ? ` (${p.name})` : ""}`)));
}

async function uploadProfile(file) {
  $("profile-error").textContent = "";
  try {
    const name = file.name.replace(/\.[^.]*$/, "").slice(0, 64);
    const profile = await api(`/v1/roads?name=${encodeURIComponent(name)}`, { method: "POST", body: await file.text(),
                                                                              headers: { "Content-Type": "text/csv" } });
    await roadChoices();
    const box = [...$("profiles").querySelectorAll("input")].find((i) => i.value === profile.spec);
    if (box) box.checked = true;
  } catch (e) {
    const where = e.problem?.errors?.map((x) => `${x.loc.slice(1).join(".")}: ${x.msg}`).join("; ");
    $("profile-error").textContent = where || e.message;
  }
}

function numberOr(id) {
  const v = $(id).value.trim();
  return v === "" ? undefined : Number(v);
}

function spec() {
  const kind = $("kind").value;
  const roads = [...document.querySelectorAll("#presets input:checked, #profiles input:checked")].map((i) => i.value);
  roads.push(...$("road-specs").value.split(",").map((s) => s.trim()).filter(Boolean));
  const body = { kind, roads, seed: numberOr("seed") ?? 0, settings: { method: $("method").value } };
  if (numberOr("duration") !== undefined) body.settings.duration = numberOr("duration");
  if ((kind === "sweep" || kind === "paper-study") && $("grid").value.trim()) body.grid = $("grid").value.trim();
  if (kind !== "sweep") {
    const bounds = {};
    for (const [k, name] of [["a2", "a2_deg"], ["l2", "l2_m"], ["rws", "rws_m"]]) {
      const lo = numberOr(`${k}-lo`);
      const hi = numberOr(`${k}-hi`);
      if (lo !== undefined || hi !== undefined) bounds[name] = [lo ?? Number($(`${k}-lo`).placeholder), hi ?? Number($(`${k}-hi`).placeholder)];
    }
    if (Object.keys(bounds).length) body.bounds = bounds;
    const de = {};
    if ($("optimiser").value) de.optimiser = $("optimiser").value;
    if ($("preset").value) de.preset = $("preset").value;
    if (numberOr("np") !== undefined) de.np = numberOr("np");
    if (numberOr("iters") !== undefined) de.iters = numberOr("iters");
    if (Object.keys(de).length) body.de = de;
    if (kind === "robust-de") body.aggregate = $("aggregate").value;
  }
  return body;
}

function kindChanged() {
  const kind = $("kind").value;
  document.querySelectorAll(".for-grid").forEach((e) => (e.hidden = !(kind === "sweep" || kind === "paper-study")));
  document.querySelectorAll(".for-de").forEach((e) => (e.hidden = kind === "sweep"));
  document.querySelectorAll(".for-robust").forEach((e) => (e.hidden = kind !== "robust-de"));
}

async function submit(event) {
  event.preventDefault();
  clearProblem($("submit"), $("form-error"));
  $("submit-button").disabled = true;
  try {
    const job = await api("/v1/jobs", { method: "POST", body: spec() });
    await load();
    const tr = shown.get(job.id);
    if (tr) tr.classList.add("new");
  } catch (e) {
    showProblem($("submit"), e.problem ?? { detail: e.message }, $("form-error"));
  } finally {
    $("submit-button").disabled = false;
  }
}

$("kind").addEventListener("change", kindChanged);
$("submit").addEventListener("submit", submit);
$("profile-file").addEventListener("change", (e) => e.target.files[0] && uploadProfile(e.target.files[0]));
$("filter-state").addEventListener("change", () => load());
$("filter-kind").addEventListener("change", () => load());
$("older").addEventListener("click", () => load(true));
kindChanged();
await Promise.all([defaults(), roadChoices(), load()]);
live();
document.body.dataset.ready = "1";

// The /v1 API as the pages use it: JSON requests, problem documents, SSE, and DOM built from text only.
// When the server has a token, the session is an HttpOnly cookie set by POST /v1/session (the sign-in page):
// no script here can read it; the browser sends it on the page's own requests, writes included (the server
// takes it for a write only from this origin).

export async function signOut() {
  await fetch("/v1/session", { method: "DELETE", credentials: "same-origin" });
  location.reload();
}

/** An API error: HTTP status and the problem document (RFC 9457) when there is one. */
export class ApiError extends Error {
  constructor(status, problem) {
    super(problem?.detail || problem?.title || `HTTP ${status}`);
    this.status = status;
    this.problem = problem;
  }
}

export async function api(path, { method = "GET", body, headers = {} } = {}) {
  const init = { method, headers: { Accept: "application/json", ...headers }, credentials: "same-origin" };
  if (body !== undefined) {
    if (typeof body === "string") init.body = body;
    else {
      init.body = JSON.stringify(body);
      init.headers["Content-Type"] = "application/json";
    }
  }
  const response = await fetch(path, init);
  const text = await response.text();
  let data = null;
  try {
    data = text ? JSON.parse(text) : null;
  } catch {
    data = { detail: text };
  }
  if (!response.ok) {
    if (response.status === 401) showBanner("The service needs its token: sign in again.", true);
    throw new ApiError(response.status, data);
  }
  return data;
}

/** Server-sent events from ``path``: handlers by event name; reconnects as EventSource does. */
export function stream(path, handlers) {
  const source = new EventSource(path, { withCredentials: true });
  for (const [name, fn] of Object.entries(handlers)) {
    source.addEventListener(name, (e) => fn(JSON.parse(e.data)));
  }
  return source;
}

export function showBanner(text, signIn = false) {
  let el = document.getElementById("banner");
  if (!el) {
    el = document.createElement("div");
    el.id = "banner";
    el.className = "banner";
    document.body.prepend(el);
  }
  el.textContent = text + " ";
  if (signIn) {
    const a = document.createElement("a");
    a.href = "#";
    a.textContent = "Sign in";
    a.onclick = (e) => (e.preventDefault(), signOut());
    el.append(a);
  }
}

// ---- a form's validation messages ----
export function clearProblem(form, general) {
  form.querySelectorAll(".field-error").forEach((e) => e.remove());
  form.querySelectorAll(".invalid").forEach((e) => e.classList.remove("invalid"));
  general.textContent = "";
}

/** The element of ``form`` that shows an error at ``path``: the deepest [data-field] matching it, refined by a
 * message that names a member (as the bounds' "a2_deg: lower bound ..." does). */
function fieldOf(form, path, msg) {
  const named = /^(\w+):/.exec(msg)?.[1];
  for (let n = path.length; n > 0; n--) {
    const key = path.slice(0, n).join(".");
    const target = (named && form.querySelector(`[data-field="${CSS.escape(`${key}.${named}`)}"]`))
      || form.querySelector(`[data-field="${CSS.escape(key)}"]`);
    if (target) return target;
  }
  return null;
}

/** Put each of a problem's validation messages next to the field its loc names; the rest in ``general``. */
export function showProblem(form, problem, general) {
  clearProblem(form, general);
  const rest = [];
  for (const err of problem?.errors ?? [{ loc: [], msg: problem?.detail ?? "the request failed" }]) {
    const path = err.loc[0] === "body" ? err.loc.slice(1) : err.loc;
    const msg = err.msg.replace(/^Value error, /, "");
    const target = fieldOf(form, path, msg);
    if (!target) {
      rest.push(`${path.join(".") || "request"}: ${msg}`);
      continue;
    }
    target.querySelectorAll("input, select, textarea").forEach((i) => i.classList.add("invalid"));
    const box = target.closest("div[data-field]") ?? target;
    box.append(el("span", { class: "field-error", role: "alert", "data-loc": path.join(".") }, `${path.join(".")}: ${msg}`));
  }
  general.textContent = rest.join("; ");
}

// ---- formatting ----
export function num(value, digits = 3) {
  return value === null || value === undefined || !Number.isFinite(value) ? "–" : value.toFixed(digits);
}

export function duration(seconds) {
  if (seconds === null || seconds === undefined || !Number.isFinite(seconds)) return "–";
  if (seconds < 90) return `${seconds.toFixed(0)} s`;
  if (seconds < 5400) return `${(seconds / 60).toFixed(1)} min`;
  return `${(seconds / 3600).toFixed(1)} h`;
}

// ---- safe DOM building: text nodes, attributes, links that can only be http(s) ----
const URL_ATTRIBUTES = new Set(["href", "src", "action", "formaction", "xlink:href"]);

/** ``value`` when it is an http(s) URL or a path (resolved on this page), else null: a link built from data
 * is never ``javascript:``, ``data:`` or ``blob:``. */
export function safeUrl(value) {
  try {
    const { protocol } = new URL(String(value), location.href);
    return protocol === "http:" || protocol === "https:" ? String(value) : null;
  } catch {
    return null;
  }
}

/** The absolute URL of ``path`` on this origin; throws for anything that would leave it. */
export function localUrl(path) {
  const url = new URL(String(path), location.origin);
  if (url.origin !== location.origin) throw new Error(`not a path of this server: ${path}`);
  return url.href;
}

/** A link to ``path`` with the query ``pairs`` ([[key, value], ...]), URL-encoded. */
export function pageLink(path, pairs) {
  return `${path}?${new URLSearchParams(pairs)}`;
}

/** An element: ``attrs`` set as attributes (``on*``: listeners; URL attributes through safeUrl), ``children``
 * appended as nodes or text, never parsed as HTML. */
export function el(tag, attrs = {}, ...children) {
  const node = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (k === "class") node.className = v;
    else if (k.startsWith("on")) node.addEventListener(k.slice(2), v);
    else if (v === null || v === undefined || v === false) continue;
    else if (URL_ATTRIBUTES.has(k)) {
      const url = safeUrl(v);
      if (url !== null) node.setAttribute(k, url);
    } else node.setAttribute(k, v === true ? "" : v);
  }
  for (const c of children.flat()) node.append(c instanceof Node ? c : document.createTextNode(String(c)));
  return node;
}

export function progressBar(fraction, state) {
  const pct = Math.max(0, Math.min(1, fraction || 0)) * 100;
  return el("div", { class: `bar state-${state}`, role: "progressbar", "aria-valuenow": pct.toFixed(0),
                     "aria-valuemin": "0", "aria-valuemax": "100" },
            el("div", { class: "fill", style: `width:${pct.toFixed(1)}%` }));
}

/** The design page's query pair for design ``d`` as ``prefix`` ("a" or "b"). */
export function designParam(d, prefix) {
  return [prefix, [d.a2_deg, d.l2_m, d.rws_m].map((v) => +v.toPrecision(6)).join(",")];
}

// The /v1 API as the pages use it: the session's token, JSON requests, problem documents, SSE.
// The token lives in a session cookie (finaldrive_token, set by the sign-in page): the browser sends it
// on the page's own GETs, streams, images and the viewer's download; POSTs carry it as a Bearer header.

export const TOKEN_COOKIE = "finaldrive_token";

export function token() {
  const hit = document.cookie.split("; ").find((c) => c.startsWith(TOKEN_COOKIE + "="));
  return hit ? decodeURIComponent(hit.slice(TOKEN_COOKIE.length + 1)) : null;
}

export function signOut() {
  document.cookie = `${TOKEN_COOKIE}=; path=/; max-age=0; SameSite=Strict`;
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
  const t = token();
  if (t && method !== "GET") init.headers.Authorization = `Bearer ${t}`;
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
    const target = (named && form.querySelector(`[data-field="${key}.${named}"]`))
      || form.querySelector(`[data-field="${key}"]`);
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

export function el(tag, attrs = {}, ...children) {
  const node = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (k === "class") node.className = v;
    else if (k.startsWith("on")) node.addEventListener(k.slice(2), v);
    else if (v !== null && v !== undefined && v !== false) node.setAttribute(k, v === true ? "" : v);
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

export function designQuery(d, prefix) {
  return `${prefix}=${[d.a2_deg, d.l2_m, d.rws_m].map((v) => +v.toPrecision(6)).join(",")}`;
}

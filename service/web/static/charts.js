// Small interactive charts for the dashboard, drawn with canvas and SVG (no plotting library):
// the polar sweep map (Figs. 9-11), line charts (DE history, Fig. 13 series) and a scatter of evaluations.

const VIRIDIS = [[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98], [253, 231, 37]];

/** A colour for ``t`` in [0, 1] on viridis. */
export function viridis(t) {
  const x = Math.max(0, Math.min(1, t)) * (VIRIDIS.length - 1);
  const i = Math.min(VIRIDIS.length - 2, Math.floor(x));
  const f = x - i;
  const c = VIRIDIS[i].map((v, k) => Math.round(v + f * (VIRIDIS[i + 1][k] - v)));
  return `rgb(${c[0]},${c[1]},${c[2]})`;
}

export function extent(values) {
  let lo = Infinity;
  let hi = -Infinity;
  for (const v of values) if (v !== null && Number.isFinite(v)) (lo = Math.min(lo, v)), (hi = Math.max(hi, v));
  return lo <= hi ? [lo, hi === lo ? lo + 1e-12 : hi] : [0, 1];
}

/** About ``n`` round tick values over [lo, hi]. */
export function ticks(lo, hi, n = 5) {
  const step0 = (hi - lo) / Math.max(1, n);
  const mag = 10 ** Math.floor(Math.log10(step0 || 1));
  const step = [1, 2, 2.5, 5, 10].map((m) => m * mag).find((s) => s >= step0) || mag * 10;
  const out = [];
  for (let v = Math.ceil(lo / step) * step; v <= hi + step * 1e-9; v += step) out.push(+v.toPrecision(12));
  return out;
}

function canvasIn(container, height) {
  container.replaceChildren();
  const canvas = document.createElement("canvas");
  const width = container.clientWidth || 600;
  const ratio = window.devicePixelRatio || 1;
  canvas.width = width * ratio;
  canvas.height = height * ratio;
  canvas.style.width = `${width}px`;
  canvas.style.height = `${height}px`;
  const ctx = canvas.getContext("2d");
  ctx.scale(ratio, ratio);
  container.append(canvas);
  const tip = document.createElement("div");
  tip.className = "tooltip";
  tip.hidden = true;
  container.append(tip);
  return { canvas, ctx, width, height, tip };
}

/** Show ``lines`` in the tooltip, one a row; a line is text or a list of nodes and text (never HTML). */
function showTip(tip, x, y, lines) {
  tip.replaceChildren(...lines.map((line) => {
    const row = document.createElement("div");
    row.append(...[line].flat());
    return row;
  }));
  tip.style.left = `${x + 12}px`;
  tip.style.top = `${y + 12}px`;
  tip.hidden = false;
}

/** Hover (a tooltip) and click (``pick``) on the nearest of ``indices`` within ``radius`` px of the pointer. */
function pickable(canvas, tip, indices, position, radius, describe, pick) {
  const nearest = (mx, my) => {
    let hit = null;
    let d2 = radius ** 2;
    for (const i of indices) {
      const [x, y] = position(i);
      const d = (x - mx) ** 2 + (y - my) ** 2;
      if (d < d2) (d2 = d), (hit = i);
    }
    return hit;
  };
  const at = (e) => {
    const r = canvas.getBoundingClientRect();
    return [e.clientX - r.left, e.clientY - r.top];
  };
  canvas.addEventListener("mousemove", (e) => {
    const [mx, my] = at(e);
    const i = nearest(mx, my);
    if (i === null) tip.hidden = true;
    else showTip(tip, mx, my, describe(i));
    canvas.style.cursor = i === null ? "default" : "pointer";
  });
  canvas.addEventListener("mouseleave", () => (tip.hidden = true));
  canvas.addEventListener("click", (e) => {
    const i = nearest(...at(e));
    if (i !== null) pick(i);
  });
}

function colourBar(ctx, x, y, h, lo, hi, label) {
  for (let i = 0; i < h; i++) {
    ctx.fillStyle = viridis(1 - i / h);
    ctx.fillRect(x, y + i, 14, 1);
  }
  ctx.fillStyle = "#222";
  ctx.font = "11px sans-serif";
  ctx.textAlign = "left";
  for (const t of ticks(lo, hi, 4)) ctx.fillText(t.toPrecision(4), x + 18, y + h - ((t - lo) / (hi - lo)) * h + 4);
  ctx.fillText(label, x - 4, y - 8);
}

/**
 * The polar map of a sweep (a2 = 0 forward, to the right; counter-clockwise; radius L2).
 * ``data``: columns a2_deg, l2_m, rws_m, and ``value`` (null: failed). Several R_WS at one (a2, L2)
 * show the highest value. ``near``: optional booleans (outlined). Returns {positionOf(i), select(i)}.
 */
export function polarMap(container, data, { valueLabel = "value [m]", near = null, onSelect = () => {},
                                            describe = () => [] } = {}) {
  const { canvas, ctx, width, height, tip } = canvasIn(container, 460);
  const n = data.a2_deg.length;
  const keep = new Map(); // (a2, l2) -> index with the highest value
  for (let i = 0; i < n; i++) {
    const key = `${data.a2_deg[i].toFixed(6)}|${data.l2_m[i].toFixed(6)}`;
    const j = keep.get(key);
    const v = data.value[i];
    if (j === undefined || (v !== null && (data.value[j] === null || v > data.value[j]))) keep.set(key, i);
  }
  const shown = [...keep.values()];
  const [lo, hi] = extent(shown.map((i) => data.value[i]));
  const rMax = Math.max(1e-3, ...data.l2_m) * 1.08;
  const cx = (width - 90) / 2;
  const cy = height / 2;
  const scale = (Math.min(width - 90, height) / 2 - 24) / rMax;
  const pos = (i) => {
    const a = (data.a2_deg[i] * Math.PI) / 180;
    return [cx + scale * data.l2_m[i] * Math.cos(a), cy - scale * data.l2_m[i] * Math.sin(a)];
  };
  const a2s = [...new Set(shown.map((i) => +data.a2_deg[i].toFixed(6)))].sort((a, b) => a - b);
  const l2s = [...new Set(shown.map((i) => +data.l2_m[i].toFixed(6)))].sort((a, b) => a - b);
  const grid = a2s.length > 2 && l2s.length > 1 && shown.length >= 0.5 * a2s.length * l2s.length;
  const da = grid ? (((a2s.at(-1) - a2s[0]) / (a2s.length - 1)) * Math.PI) / 180 : 0;
  const dl = grid ? (l2s.at(-1) - l2s[0]) / (l2s.length - 1) : 0;
  let best = -1;
  for (const i of shown) if (data.value[i] !== null && (best < 0 || data.value[i] > data.value[best])) best = i;
  let selected = null;

  function draw() {
    ctx.clearRect(0, 0, width, height);
    ctx.strokeStyle = "#ccc";
    ctx.fillStyle = "#666";
    ctx.font = "11px sans-serif";
    for (const r of ticks(0, rMax / 1.08, 4).filter((r) => r > 0)) {
      ctx.beginPath();
      ctx.arc(cx, cy, r * scale, 0, 2 * Math.PI);
      ctx.stroke();
      ctx.fillText(`${(r * 1000).toFixed(0)} mm`, cx + r * scale * 0.71 + 3, cy - r * scale * 0.71);
    }
    for (let a = 0; a < 360; a += 30) {
      const t = (a * Math.PI) / 180;
      ctx.beginPath();
      ctx.moveTo(cx, cy);
      ctx.lineTo(cx + rMax * scale * Math.cos(t), cy - rMax * scale * Math.sin(t));
      ctx.stroke();
      ctx.fillText(`${a}°`, cx + (rMax * scale + 10) * Math.cos(t) - 10, cy - (rMax * scale + 10) * Math.sin(t) + 4);
    }
    for (const i of shown) {
      const v = data.value[i];
      ctx.fillStyle = v === null ? "#e33" : viridis((v - lo) / (hi - lo));
      if (grid) {
        const a = (data.a2_deg[i] * Math.PI) / 180;
        const r0 = Math.max(0, data.l2_m[i] - dl / 2) * scale;
        const r1 = (data.l2_m[i] + dl / 2) * scale;
        ctx.beginPath();
        ctx.arc(cx, cy, r1, -(a + da / 2), -(a - da / 2));
        ctx.arc(cx, cy, r0, -(a - da / 2), -(a + da / 2), true);
        ctx.closePath();
        ctx.fill();
      } else {
        const [x, y] = pos(i);
        ctx.beginPath();
        ctx.arc(x, y, 4, 0, 2 * Math.PI);
        ctx.fill();
      }
    }
    if (near) {
      ctx.strokeStyle = "#d62728";
      ctx.lineWidth = 1.2;
      for (const i of shown) {
        if (!near[i]) continue;
        const [x, y] = pos(i);
        ctx.beginPath();
        ctx.arc(x, y, 5, 0, 2 * Math.PI);
        ctx.stroke();
      }
      ctx.lineWidth = 1;
    }
    ctx.fillStyle = "#000";
    ctx.beginPath();
    ctx.arc(cx, cy, 4, 0, 2 * Math.PI);
    ctx.fill();
    ctx.fillText("pivot", cx + 6, cy + 14);
    if (best >= 0) star(...pos(best));
    if (selected !== null) {
      const [x, y] = pos(selected);
      ctx.strokeStyle = "#ff7f0e";
      ctx.lineWidth = 3;
      ctx.beginPath();
      ctx.arc(x, y, 9, 0, 2 * Math.PI);
      ctx.stroke();
      ctx.lineWidth = 1;
    }
    colourBar(ctx, width - 70, 40, height - 90, lo, hi, valueLabel);
  }

  function star(x, y) {
    ctx.fillStyle = "#fff";
    ctx.strokeStyle = "#000";
    ctx.beginPath();
    for (let k = 0; k < 10; k++) {
      const r = k % 2 ? 4 : 10;
      const t = -Math.PI / 2 + (k * Math.PI) / 5;
      ctx.lineTo(x + r * Math.cos(t), y + r * Math.sin(t));
    }
    ctx.closePath();
    ctx.fill();
    ctx.stroke();
  }

  pickable(canvas, tip, shown, pos, 14, describe, (i) => api.select(i));
  const api = {
    best,
    positionOf: (i) => pos(i),
    select(i) {
      selected = i;
      draw();
      onSelect(i);
    },
  };
  draw();
  return api;
}

/**
 * A line chart in SVG. ``series``: [{name, x, y, colour}]; hover shows each series' value at x.
 */
export function lineChart(container, series, { xLabel = "", yLabel = "", height = 220, title = "" } = {}) {
  container.replaceChildren();
  const width = container.clientWidth || 500;
  const m = { l: 64, r: 12, t: title ? 40 : 24, b: 36 }; // title, then the legend, above the plot
  const [x0, x1] = extent(series.flatMap((s) => s.x));
  const [y0, y1] = extent(series.flatMap((s) => s.y));
  const pad = (y1 - y0) * 0.05;
  const X = (v) => m.l + ((v - x0) / (x1 - x0)) * (width - m.l - m.r);
  const Y = (v) => height - m.b - ((v - (y0 - pad)) / (y1 - y0 + 2 * pad)) * (height - m.t - m.b);
  const ns = "http://www.w3.org/2000/svg";
  const svg = document.createElementNS(ns, "svg");
  svg.setAttribute("width", width);
  svg.setAttribute("height", height);
  svg.setAttribute("class", "chart");
  const add = (tag, attrs, text) => {
    const node = document.createElementNS(ns, tag);
    for (const [k, v] of Object.entries(attrs)) node.setAttribute(k, v);
    if (text !== undefined) node.textContent = text;
    svg.append(node);
    return node;
  };
  if (title) add("text", { x: m.l, y: 14, class: "title" }, title);
  for (const t of ticks(y0 - pad, y1 + pad, 4)) {
    add("line", { x1: m.l, x2: width - m.r, y1: Y(t), y2: Y(t), class: "grid" });
    add("text", { x: m.l - 6, y: Y(t) + 4, "text-anchor": "end" }, +t.toPrecision(4));
  }
  for (const t of ticks(x0, x1, 6)) add("text", { x: X(t), y: height - m.b + 16, "text-anchor": "middle" }, +t.toPrecision(4));
  add("text", { x: (m.l + width) / 2, y: height - 4, "text-anchor": "middle", class: "label" }, xLabel);
  add("text", { x: 12, y: (m.t + height - m.b) / 2, transform: `rotate(-90 12 ${(m.t + height - m.b) / 2})`,
                "text-anchor": "middle", class: "label" }, yLabel);
  for (const s of series) {
    const pts = [];
    s.x.forEach((x, i) => s.y[i] !== null && Number.isFinite(s.y[i]) && pts.push(`${X(x).toFixed(1)},${Y(s.y[i]).toFixed(1)}`));
    add("polyline", { points: pts.join(" "), fill: "none", stroke: s.colour, "stroke-width": 1.6, class: "series" });
  }
  series.forEach((s, k) => {
    add("rect", { x: m.l + 8 + k * 150, y: m.t - 18, width: 10, height: 10, fill: s.colour });
    add("text", { x: m.l + 22 + k * 150, y: m.t - 9, class: "legend" }, s.name);
  });
  const cursor = add("line", { y1: m.t, y2: height - m.b, class: "cursor", visibility: "hidden" });
  container.append(svg);
  const tip = document.createElement("div");
  tip.className = "tooltip";
  tip.hidden = true;
  container.append(tip);
  svg.addEventListener("mousemove", (e) => {
    const r = svg.getBoundingClientRect();
    const mx = e.clientX - r.left;
    const xv = x0 + ((mx - m.l) / (width - m.l - m.r)) * (x1 - x0);
    const rows = series.map((s) => {
      let k = 0;
      for (let i = 1; i < s.x.length; i++) if (Math.abs(s.x[i] - xv) < Math.abs(s.x[k] - xv)) k = i;
      const square = document.createElement("span");
      square.style.color = s.colour;
      square.textContent = "■";
      return [square, ` ${s.name}: ${s.y[k] === null ? "–" : (+s.y[k]).toPrecision(5)}`];
    });
    cursor.setAttribute("x1", mx);
    cursor.setAttribute("x2", mx);
    cursor.setAttribute("visibility", "visible");
    showTip(tip, mx, e.clientY - r.top, [`${xLabel}: ${xv.toPrecision(4)}`, ...rows]);
  });
  svg.addEventListener("mouseleave", () => ((tip.hidden = true), cursor.setAttribute("visibility", "hidden")));
  return svg;
}

/** A scatter plot on canvas: points (x, y) coloured by c; hover describes, click selects. */
export function scatter(container, { x, y, c, xLabel, yLabel, cLabel, describe = () => [], onSelect = () => {} }) {
  const { canvas, ctx, width, height, tip } = canvasIn(container, 340);
  const m = { l: 64, r: 90, t: 12, b: 40 };
  const ok = x.map((v, i) => v !== null && y[i] !== null && Number.isFinite(v) && Number.isFinite(y[i]));
  const [x0, x1] = extent(x.filter((_, i) => ok[i]));
  const [y0, y1] = extent(y.filter((_, i) => ok[i]));
  const [c0, c1] = extent(c);
  const X = (v) => m.l + ((v - x0) / (x1 - x0)) * (width - m.l - m.r);
  const Y = (v) => height - m.b - ((v - y0) / (y1 - y0)) * (height - m.t - m.b);
  ctx.font = "11px sans-serif";
  ctx.strokeStyle = "#ddd";
  ctx.fillStyle = "#444";
  for (const t of ticks(y0, y1, 4)) {
    ctx.beginPath();
    ctx.moveTo(m.l, Y(t));
    ctx.lineTo(width - m.r, Y(t));
    ctx.stroke();
    ctx.textAlign = "right";
    ctx.fillText(+t.toPrecision(4), m.l - 6, Y(t) + 4);
  }
  ctx.textAlign = "center";
  for (const t of ticks(x0, x1, 6)) ctx.fillText(+t.toPrecision(4), X(t), height - m.b + 16);
  ctx.fillText(xLabel, (m.l + width - m.r) / 2, height - 6);
  ctx.save();
  ctx.translate(14, (m.t + height - m.b) / 2);
  ctx.rotate(-Math.PI / 2);
  ctx.fillText(yLabel, 0, 0);
  ctx.restore();
  for (let i = 0; i < x.length; i++) {
    if (!ok[i]) continue;
    ctx.fillStyle = c[i] === null ? "#e33" : viridis((c[i] - c0) / (c1 - c0));
    ctx.fillRect(X(x[i]) - 2, Y(y[i]) - 2, 4, 4);
  }
  colourBar(ctx, width - 70, 30, height - 90, c0, c1, cLabel);
  const indices = x.map((_, i) => i).filter((i) => ok[i]);
  pickable(canvas, tip, indices, (i) => [X(x[i]), Y(y[i])], 10, describe, onSelect);
}

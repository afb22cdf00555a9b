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

/** The smallest and largest of ``values``, nulls and non-finite ones left out ([Infinity, -Infinity]: none). */
function range(values) {
  let lo = Infinity;
  let hi = -Infinity;
  for (const v of values) if (v !== null && Number.isFinite(v)) (lo = Math.min(lo, v)), (hi = Math.max(hi, v));
  return [lo, hi];
}

export function extent(values) {
  const [lo, hi] = range(values);
  return lo <= hi ? [lo, hi === lo ? lo + 1e-12 : hi] : [0, 1];
}

/** A round step for about ``n`` ticks over [lo, hi]. */
function tickStep(lo, hi, n) {
  const step0 = (hi - lo) / Math.max(1, n);
  const mag = 10 ** Math.floor(Math.log10(step0 || 1));
  return [1, 2, 2.5, 5, 10].map((m) => m * mag).find((s) => s >= step0) || mag * 10;
}

/** About ``n`` round tick values over [lo, hi]. */
export function ticks(lo, hi, n = 5) {
  const step = tickStep(lo, hi, n);
  const out = [];
  for (let v = Math.ceil(lo / step) * step; v <= hi + step * 1e-9; v += step) out.push(+v.toPrecision(12));
  return out;
}

/**
 * A linear axis over ``values`` (nulls and non-finite ones left out): its domain widened to the round ticks that
 * enclose every value, so that no value lies beyond the first or last tick; a single value gets a span around it.
 */
export function niceAxis(values, n = 5) {
  let [lo, hi] = range(values);
  if (lo > hi) (lo = 0), (hi = 1);
  if (hi - lo <= 1e-12 * Math.max(Math.abs(lo), Math.abs(hi))) {
    const half = Math.abs(lo) / 20 || 0.5;
    lo -= half;
    hi += half;
  }
  const step = tickStep(lo, hi, n);
  const first = Math.floor(lo / step + 1e-9); // 0.3 / 0.1 is 2.9999999999999996
  const count = Math.ceil(hi / step - 1e-9) - first;
  const marks = Array.from({ length: count + 1 }, (_, k) => +((first + k) * step).toPrecision(12));
  return { lo: Math.min(lo, marks[0]), hi: Math.max(hi, marks[count]), ticks: marks };
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
  ctx.textBaseline = "alphabetic";
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

/** Whether boxes {x, y, w, h} overlap. */
function overlaps(a, b) {
  return a.x < b.x + b.w && b.x < a.x + a.w && a.y < b.y + b.h && b.y < a.y + a.h;
}

/** The box of ``text`` drawn at (x, y) in ``ctx``'s font, alignment and a middle baseline. */
function textBox(ctx, text, x, y) {
  const w = ctx.measureText(text).width;
  const left = ctx.textAlign === "right" ? x - w : ctx.textAlign === "center" ? x - w / 2 : x;
  return { x: left, y: y - 7, w, h: 14 };
}

/** Smallest angle between two directions [deg]. */
function angleApart(a, b) {
  const d = Math.abs((((a - b) % 360) + 360) % 360);
  return Math.min(d, 360 - d);
}

/**
 * The polar map of a sweep around the swingarm pivot (a2 = 0 forward, to the right; counter-clockwise; radius
 * L2). ``data``: columns a2_deg, l2_m, rws_m, and ``value`` (null: failed). Several R_WS at one (a2, L2) show
 * the highest value. ``near``: optional booleans (outlined). ``swingarmDeg``: the swingarm's direction from the
 * pivot to the rear axle in a2's frame, drawn as a line (null: not drawn). A key under the map names the pivot
 * and the markers, out of the data's way. Returns {best, positionOf(i), select(i), layout, swingarm, key}.
 */
export function polarMap(container, data, { valueLabel = "value [m]", near = null, swingarmDeg = null,
                                            onSelect = () => {}, describe = () => [] } = {}) {
  const MAP = 460; // the map's height; the key below it
  const { canvas, ctx, width, height, tip } = canvasIn(container, MAP + 44);
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
  const a2s = [...new Set(shown.map((i) => +data.a2_deg[i].toFixed(6)))].sort((a, b) => a - b);
  const l2s = [...new Set(shown.map((i) => +data.l2_m[i].toFixed(6)))].sort((a, b) => a - b);
  const grid = a2s.length > 2 && l2s.length > 1 && shown.length >= 0.5 * a2s.length * l2s.length;
  const da = grid ? (((a2s.at(-1) - a2s[0]) / (a2s.length - 1)) * Math.PI) / 180 : 0;
  const dl = grid ? (l2s.at(-1) - l2s[0]) / (l2s.length - 1) : 0;
  // the outermost data (a cell's outer edge, or a point and its marker) reaches the rim, never beyond it
  const rData = Math.max(1e-3, l2s.at(-1) + dl / 2);
  const cx = (width - 90) / 2;
  const cy = MAP / 2;
  const radius = Math.min(width - 90, MAP) / 2 - 30;
  const scale = (radius - (grid ? 0 : 6)) / rData;
  const pos = (i) => {
    const a = (data.a2_deg[i] * Math.PI) / 180;
    return [cx + scale * data.l2_m[i] * Math.cos(a), cy - scale * data.l2_m[i] * Math.sin(a)];
  };
  const ray = (deg, r) => [cx + r * Math.cos((deg * Math.PI) / 180), cy - r * Math.sin((deg * Math.PI) / 180)];
  let best = -1;
  for (const i of shown) if (data.value[i] !== null && (best < 0 || data.value[i] > data.value[best])) best = i;
  // the rings' labels along the direction farthest from the swingarm and the best design (mid-way between spokes)
  const avoid = [swingarmDeg, best >= 0 ? data.a2_deg[best] : null].filter((a) => a !== null);
  const ringDeg = [45, 135, 225, 315, 15, 75, 105, 165, 195, 255, 285, 345].reduce((b, a) =>
    Math.min(...avoid.map((v) => angleApart(a, v))) > Math.min(...avoid.map((v) => angleApart(b, v))) ? a : b);
  const rings = ticks(0, rData, 5).filter((r) => r > 0 && r * scale <= radius);
  const swingarm = swingarmDeg === null ? null : { deg: swingarmDeg, from: [cx, cy], to: ray(swingarmDeg, radius + 6) };
  let selected = null;
  let key = [];

  function draw() {
    ctx.clearRect(0, 0, width, height);
    ctx.textBaseline = "middle";
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
    // the grid over the data: rings, and spokes from the innermost ring out (the pivot's surroundings stay clear)
    ctx.strokeStyle = "rgba(40, 40, 40, 0.28)";
    ctx.lineWidth = 1;
    for (const r of rings) {
      ctx.beginPath();
      ctx.arc(cx, cy, r * scale, 0, 2 * Math.PI);
      ctx.stroke();
    }
    const inner = (rings[0] ?? rData) * scale;
    for (let a = 0; a < 360; a += 30) {
      ctx.beginPath();
      ctx.moveTo(...ray(a, inner));
      ctx.lineTo(...ray(a, radius));
      ctx.stroke();
    }
    ctx.strokeStyle = "#888";
    ctx.beginPath();
    ctx.arc(cx, cy, radius, 0, 2 * Math.PI);
    ctx.stroke();
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
    const taken = []; // boxes of the labels outside the rim
    if (swingarm) {
      swingarmLine(swingarm.from, swingarm.to);
      const c = Math.cos((swingarm.deg * Math.PI) / 180);
      ctx.font = "bold 12px sans-serif";
      ctx.fillStyle = "#111";
      ctx.textAlign = c > 0.3 ? "left" : c < -0.3 ? "right" : "center";
      const [x, y] = ray(swingarm.deg, radius + 16);
      ctx.fillText("swingarm", x, y);
      taken.push(textBox(ctx, "swingarm", x, y));
    }
    ctx.font = "11px sans-serif";
    ctx.fillStyle = "#555";
    ctx.textAlign = "center";
    for (let a = 0; a < 360; a += 30) {
      const [x, y] = ray(a, radius + 14);
      if (!taken.some((b) => overlaps(b, textBox(ctx, `${a}°`, x, y)))) ctx.fillText(`${a}°`, x, y);
    }
    for (const r of rings) {
      if (r * scale < 28) continue; // no label in the crowd around the pivot
      const [x, y] = ray(ringDeg, r * scale);
      const text = `${+(r * 1000).toPrecision(6)} mm`;
      const b = textBox(ctx, text, x, y);
      ctx.fillStyle = "rgba(255, 255, 255, 0.85)";
      ctx.fillRect(b.x - 3, b.y - 1, b.w + 6, b.h + 2);
      ctx.fillStyle = "#222";
      ctx.fillText(text, x, y);
    }
    if (best >= 0) star(...pos(best));
    pivot(cx, cy); // above a design at L2 = 0 (its star too): the star stays visible around it
    if (selected !== null) ring(...pos(selected), 9, "#ff7f0e", 3);
    colourBar(ctx, width - 70, 40, MAP - 90, lo, hi, valueLabel);
    key = drawKey();
  }

  /** The key under the map, item after item (wrapping): a symbol and its text; returns their text boxes. */
  function drawKey() {
    const items = [["pivot", "swingarm pivot (L2 = 0)", pivot]];
    if (swingarm) {
      items.push(["swingarm", `swingarm at static sag (${swingarm.deg.toFixed(1)}°)`,
                  (x, y) => swingarmLine([x - 8, y], [x + 8, y])]);
    }
    if (best >= 0) items.push(["best", `highest ${valueLabel.replace(/ \[.*\]$/, "")}`, star]);
    if (near) items.push(["near", "near-optimal set", (x, y) => ring(x, y, 5, "#d62728", 1.2)]);
    if (shown.some((i) => data.value[i] === null)) items.push(["failed", "failed", (x, y) => dot(x, y, "#e33")]);
    items.push(["selected", "selected", (x, y) => ring(x, y, 7, "#ff7f0e", 3)]);
    ctx.font = "12px sans-serif";
    ctx.textAlign = "left";
    ctx.textBaseline = "middle";
    let x = 12;
    let y = MAP + 12;
    const boxes = [];
    for (const [name, text, symbol] of items) {
      const w = 24 + ctx.measureText(text).width;
      if (x > 12 && x + w > width - 12) (x = 12), (y += 20);
      symbol(x + 8, y);
      ctx.fillStyle = "#222";
      ctx.fillText(text, x + 22, y);
      boxes.push({ name, box: textBox(ctx, text, x + 22, y) });
      x += w + 18;
    }
    return boxes;
  }

  function swingarmLine([x0, y0], [x1, y1]) {
    ctx.strokeStyle = "#111";
    ctx.lineWidth = 3;
    ctx.lineCap = "butt";
    ctx.beginPath();
    ctx.moveTo(x0, y0);
    ctx.lineTo(x1, y1);
    ctx.stroke();
    ctx.lineWidth = 1;
  }

  /** The pivot: a white disc ringed in black with a black centre, above the data, the swingarm and the star. */
  function pivot(x, y) {
    ring(x, y, 5, "#000", 1.5, "#fff");
    dot(x, y, "#000", 1.8);
  }

  function ring(x, y, r, colour, lineWidth, fill = null) {
    ctx.beginPath();
    ctx.arc(x, y, r, 0, 2 * Math.PI);
    if (fill) (ctx.fillStyle = fill), ctx.fill();
    ctx.strokeStyle = colour;
    ctx.lineWidth = lineWidth;
    ctx.stroke();
    ctx.lineWidth = 1;
  }

  function dot(x, y, colour, r = 4) {
    ctx.fillStyle = colour;
    ctx.beginPath();
    ctx.arc(x, y, r, 0, 2 * Math.PI);
    ctx.fill();
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
    /** for the browser tests: what was drawn where */
    layout: { cx, cy, radius, scale, grid, shown, cell: grid ? { da: (da * 180) / Math.PI, dl } : null },
    swingarm,
    get key() {
      return key;
    },
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

/**
 * A scatter plot on canvas: points (x, y) coloured by c; hover describes, click selects. Each axis spans round
 * ticks around its values and the points keep a margin inside the frame, so every point lies within its axes.
 * Returns {plot: the frame {left, top, right, bottom}, shown: the indices drawn, positionOf(i), x, y: the axes}.
 */
export function scatter(container, { x, y, c, xLabel, yLabel, cLabel, describe = () => [], onSelect = () => {} }) {
  const { canvas, ctx, width, height, tip } = canvasIn(container, 340);
  const m = { l: 64, r: 90, t: 12, b: 40 };
  const inset = 6; // px between the frame and the first and last tick: a marker at the domain's end stays inside
  const plot = { left: m.l, top: m.t, right: width - m.r, bottom: height - m.b };
  const ok = x.map((v, i) => v !== null && y[i] !== null && Number.isFinite(v) && Number.isFinite(y[i]));
  const shown = x.map((_, i) => i).filter((i) => ok[i]);
  const ax = niceAxis(shown.map((i) => x[i]), 6);
  const ay = niceAxis(shown.map((i) => y[i]), 4);
  const [c0, c1] = extent(shown.map((i) => c[i]));
  const X = (v) => plot.left + inset + ((v - ax.lo) / (ax.hi - ax.lo)) * (plot.right - plot.left - 2 * inset);
  const Y = (v) => plot.bottom - inset - ((v - ay.lo) / (ay.hi - ay.lo)) * (plot.bottom - plot.top - 2 * inset);
  ctx.font = "11px sans-serif";
  ctx.strokeStyle = "#e5e8eb";
  ctx.fillStyle = "#444";
  ctx.textAlign = "right";
  for (const t of ay.ticks) {
    ctx.beginPath();
    ctx.moveTo(plot.left, Y(t));
    ctx.lineTo(plot.right, Y(t));
    ctx.stroke();
    ctx.fillText(+t.toPrecision(4), plot.left - 6, Y(t) + 4);
  }
  ctx.textAlign = "center";
  for (const t of ax.ticks) ctx.fillText(+t.toPrecision(4), X(t), plot.bottom + 16);
  ctx.strokeStyle = "#999";
  ctx.strokeRect(plot.left + 0.5, plot.top + 0.5, plot.right - plot.left - 1, plot.bottom - plot.top - 1);
  ctx.fillText(xLabel, (plot.left + plot.right) / 2, height - 6);
  ctx.save();
  ctx.translate(14, (plot.top + plot.bottom) / 2);
  ctx.rotate(-Math.PI / 2);
  ctx.fillText(yLabel, 0, 0);
  ctx.restore();
  for (const i of shown) {
    ctx.fillStyle = c[i] === null ? "#e33" : viridis((c[i] - c0) / (c1 - c0));
    ctx.fillRect(X(x[i]) - 2, Y(y[i]) - 2, 4, 4);
  }
  colourBar(ctx, width - 70, 30, height - 90, c0, c1, cLabel);
  const positionOf = (i) => [X(x[i]), Y(y[i])];
  pickable(canvas, tip, shown, positionOf, 10, describe, onSelect);
  return { plot, shown, positionOf, x: ax, y: ay };
}

// Plotly wrappers: one look for every chart, and a CSV of what each chart shows.

export const COLORS = { tracker: "#d9480f", fixed: "#1c7ed6", sun: "#f5a400", gain: "#2b8a3e", grey: "#868e96" };

const CONFIG = {
  responsive: true,
  displaylogo: false,
  modeBarButtonsToRemove: ["lasso2d", "select2d", "autoScale2d"],
  toImageButtonOptions: { format: "png", scale: 2 },
};

let plotlyPromise = null;

/** Load Plotly (preloaded by index.html) once; resolves with it. Called after the first requests. */
export function loadPlotly() {
  if (!plotlyPromise) {
    plotlyPromise = new Promise((resolve, reject) => {
      if (window.Plotly) { resolve(window.Plotly); return; }
      const script = document.createElement("script");
      script.src = document.getElementById("plotly-preload")?.getAttribute("href") || "/vendor/plotly.min.js";
      script.onload = () => { performance.mark("heliotwin:plotly-ready"); resolve(window.Plotly); };
      script.onerror = () => reject(new Error("could not load /vendor/plotly.min.js"));
      document.head.appendChild(script);
    });
  }
  return plotlyPromise;
}

const chartData = new Map(); // chart element id → { columns, rows, filename }

export function baseLayout(extra = {}) {
  return {
    margin: { l: 60, r: 60, t: 10, b: 46 },
    font: { family: "system-ui, -apple-system, Segoe UI, Roboto, sans-serif", size: 12, color: "#1d2733" },
    paper_bgcolor: "rgba(0,0,0,0)",
    plot_bgcolor: "rgba(0,0,0,0)",
    hovermode: "x unified",
    legend: { orientation: "h", y: 1.02, yanchor: "bottom", x: 0, font: { size: 11 } },
    xaxis: { gridcolor: "#e9edf1", zeroline: false },
    yaxis: { gridcolor: "#e9edf1", zeroline: false, rangemode: "tozero" },
    ...extra,
  };
}

/** Below this width [px] a chart is drawn for a phone (docs/dashboard.md, "Phone width"). */
export const NARROW_PX = 560;
const APPROX_CHAR_PX = 6.5; // an 11 px sans-serif character, on average
const layouts = new Map(); // chart element id → the layout its page asked for, before fitWidth

/** Break a title into lines of at most `maxChars` at spaces (Plotly's <br>); a word longer
 * than that stays whole. */
export function wrapTitle(text, maxChars) {
  if (typeof text !== "string" || text.length <= maxChars || text.includes("<br>")) return text;
  const lines = [];
  let line = "";
  for (const word of text.split(" ")) {
    if (line && line.length + 1 + word.length > maxChars) { lines.push(line); line = word; }
    else line = line ? `${line} ${word}` : word;
  }
  lines.push(line);
  return lines.join("<br>");
}

/** The page's layout fitted to a chart `width` × `height` px wide: every axis grows the margins
 * for its tick labels and title (`automargin`: they were cut at the card's edge, or drawn over
 * each other); narrower than NARROW_PX (a phone) the margins start small, an x axis of numbers
 * or dates has a tick every ~48 px at most (`nticks`; a category axis keeps every category),
 * its labels level or turned upright (`autotickangles`), never slanted over each other, the fonts are a size smaller and a title longer than its axis
 * is broken into lines. */
export function fitWidth(layout, width, height, traces = []) {
  const out = { ...layout };
  const narrow = width > 0 && width < NARROW_PX;
  const m = layout.margin || {};
  if (narrow && !layout.polar) { // a polar chart's labels grow no margin: it keeps its own
    out.margin = { ...m, l: Math.min(m.l ?? 60, 8), r: Math.min(m.r ?? 60, 8), b: Math.min(m.b ?? 46, 8) };
  }
  if (narrow) {
    out.font = { ...layout.font, size: 11 };
    if (layout.legend) out.legend = { ...layout.legend, font: { ...layout.legend.font, size: 10 } };
  }
  const plotW = Math.max(width - 70, 100);
  for (const key of Object.keys(out)) {
    if (!/^[xy]axis\d*$/.test(key) || !out[key]) continue;
    const ax = { automargin: true, ...out[key] };
    if (narrow) {
      const span = ax.domain ? ax.domain[1] - ax.domain[0] : 1;
      const length = key[0] === "x" ? plotW * span : Math.max(height - 130, 80) * span;
      if (ax.title?.text) ax.title = { ...ax.title, text: wrapTitle(ax.title.text, Math.floor(length / APPROX_CHAR_PX)) };
      ax.tickfont = { size: 10, ...ax.tickfont };
      if (key[0] === "x") {
        if (!isCategoryAxis(key, ax, traces)) { // nticks would drop categories
          ax.nticks = Math.min(ax.nticks || Infinity, Math.max(3, Math.floor(plotW * span / 48)));
        }
        ax.autotickangles = ax.autotickangles || [0, 90];
      }
    }
    out[key] = ax;
  }
  return out;
}

/** Whether Plotly makes x axis `key` a category axis: its `type`, else the first value of
 * its first trace (a string that is neither a number nor a date, as Plotly's autotype). */
function isCategoryAxis(key, ax, traces) {
  if (ax.type) return ax.type === "category" || ax.type === "multicategory";
  const id = key === "xaxis" ? "x" : `x${key.slice(5)}`;
  const trace = traces.find((t) => (t.xaxis || "x") === id && Array.isArray(t.x) && t.x.length);
  const v = trace?.x.find((x) => x !== null && x !== undefined);
  return typeof v === "string" && v.trim() !== "" && !Number.isFinite(Number(v)) && !/^\d{4}-\d{2}/.test(v);
}

function sizeOf(el) {
  const w = el.clientWidth || el.closest("main")?.clientWidth || window.innerWidth;
  return [w, el.clientHeight || 320];
}

/** Draw (or redraw in place) a chart; `table` is what its CSV button downloads. */
export async function draw(id, traces, layout, table) {
  const Plotly = await loadPlotly();
  const el = document.getElementById(id);
  if (!el) return;
  el.querySelector(":scope > .empty")?.remove();
  layouts.set(id, layout);
  const [w, hgt] = sizeOf(el);
  el.dataset.fitWidth = String(w < NARROW_PX);
  await Plotly.react(el, traces, fitWidth(layout, w, hgt, traces), CONFIG);
  if (!performance.getEntriesByName("heliotwin:first-chart").length) performance.mark("heliotwin:first-chart", { detail: id });
  if (table) chartData.set(id, table);
  el.dataset.points = String(traces.reduce((n, t) => n + (t.y || t.r || []).filter((v) => v != null).length, 0));
}

/** Fit a drawn chart again to its width when it crossed NARROW_PX (a phone turned, a window
 * resized, a chart drawn on a hidden page and then shown); else only resize it. */
function refit(el) {
  const layout = layouts.get(el.id);
  const [w, hgt] = sizeOf(el);
  if (layout && el.clientWidth && el.dataset.fitWidth !== String(w < NARROW_PX)) {
    el.dataset.fitWidth = String(w < NARROW_PX);
    window.Plotly.react(el, el.data, fitWidth(layout, w, hgt, el.data), CONFIG);
  } else {
    window.Plotly.Plots.resize(el);
  }
}

let resizeTimer = null;
window.addEventListener("resize", () => {
  clearTimeout(resizeTimer);
  resizeTimer = setTimeout(() => {
    if (!window.Plotly) return;
    for (const el of document.querySelectorAll(".js-plotly-plot")) if (el.offsetParent !== null) refit(el);
  }, 150);
});

/** Replace a chart with a short message (no data, or an error). */
export function showEmpty(id, message) {
  const el = document.getElementById(id);
  if (!el) return;
  if (window.Plotly && el.classList.contains("js-plotly-plot")) window.Plotly.purge(el);
  el.innerHTML = "";
  const div = document.createElement("div");
  div.className = "empty";
  div.textContent = message;
  el.appendChild(div);
  el.dataset.points = "0";
  chartData.delete(id);
  layouts.delete(id);
}

function csvCell(v) {
  if (v === null || v === undefined || (typeof v === "number" && !Number.isFinite(v))) return "";
  const s = String(v);
  return /[",\n]/.test(s) ? `"${s.replace(/"/g, '""')}"` : s;
}

export function toCsv(columns, rows) {
  return [columns.join(","), ...rows.map((r) => r.map(csvCell).join(","))].join("\n") + "\n";
}

export function downloadText(filename, text, type = "text/csv") {
  const url = URL.createObjectURL(new Blob([text], { type }));
  const a = document.createElement("a");
  a.href = url;
  a.download = filename;
  document.body.appendChild(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(url), 1000);
}

/** Wire every `button.csv[data-chart]` to download its chart's table. */
export function wireCsvButtons(root = document) {
  root.addEventListener("click", (ev) => {
    const btn = ev.target.closest("button.csv[data-chart]");
    if (!btn) return;
    const table = chartData.get(btn.dataset.chart);
    if (!table) {
      btn.textContent = "no data";
      setTimeout(() => { btn.textContent = "CSV"; }, 1500);
      return;
    }
    downloadText(table.filename, toCsv(table.columns, table.rows));
  });
}

/** Keep charts sized to their cards when a hidden page becomes visible. */
export function resizeVisible(root) {
  if (!window.Plotly) return;
  for (const el of root.querySelectorAll(".js-plotly-plot")) refit(el);
}

/** A round tick step (1, 2, 2.5 or 5 × 10^k) that cuts `span` into about `target` intervals. */
export function roundStep(span, target = 5) {
  if (!(span > 0) || !Number.isFinite(span)) return 1;
  const raw = span / target;
  const p = 10 ** Math.floor(Math.log10(raw));
  const m = raw / p;
  return p * (m <= 1 ? 1 : m <= 2 ? 2 : m <= 2.5 ? 2.5 : m <= 5 ? 5 : 10);
}

/** Axis settings for `values` (nulls and non-finite ignored) from zero to a round value above
 * the largest — below zero only when a value is negative — with round ticks (0, 10, 20 …,
 * never 33.1, 33.6): a ±0.5 % wobble then looks like what it is. Spread into a Plotly axis. */
export function zeroBasedAxis(values, target = 5) {
  const v = values.filter((x) => typeof x === "number" && Number.isFinite(x));
  let lo = Math.min(0, ...v);
  let hi = Math.max(0, ...v);
  if (hi - lo <= 0) hi = lo + 1;
  const step = roundStep(hi - lo, target);
  lo = Math.floor(lo / step + 1e-9) * step;
  hi = Math.ceil(hi / step - 1e-9) * step;
  let decimals = 0; // as many as the step needs: 0.25 → 2, 0.2 → 1, 5 → 0
  while (decimals < 6 && Math.abs(Math.round(step * 10 ** decimals) - step * 10 ** decimals) > 1e-9) decimals += 1;
  return { range: [lo, hi], tick0: 0, dtick: step, tickformat: `.${decimals}f`, autorange: false };
}

/** A per-period series split into whole periods and partial ones: `partial[i]` true moves
 * point i out of `whole` (null there, so lines break) into `part`, whose values are clamped
 * into `range` (the axis is set from whole periods only) — `part.value` keeps the true ones
 * for the hover. Partial periods are then drawn apart, faint, and never set the axis. */
export function splitPartial(x, y, partial, range = null) {
  const whole = { x, y: y.map((v, i) => (partial[i] ? null : v)) };
  const part = { x: [], y: [], value: [], clipped: [] };
  y.forEach((v, i) => {
    if (!partial[i] || v === null || v === undefined) return;
    const c = range ? Math.min(Math.max(v, range[0]), range[1]) : v;
    part.x.push(x[i]); part.y.push(c); part.value.push(v); part.clipped.push(c !== v);
  });
  return { whole, part };
}

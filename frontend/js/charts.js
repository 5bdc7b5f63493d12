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

/** Draw (or redraw in place) a chart; `table` is what its CSV button downloads. */
export async function draw(id, traces, layout, table) {
  const Plotly = await loadPlotly();
  const el = document.getElementById(id);
  if (!el) return;
  el.querySelector(":scope > .empty")?.remove();
  await Plotly.react(el, traces, layout, CONFIG);
  if (!performance.getEntriesByName("heliotwin:first-chart").length) performance.mark("heliotwin:first-chart", { detail: id });
  if (table) chartData.set(id, table);
  el.dataset.points = String(traces.reduce((n, t) => n + (t.y || t.r || []).filter((v) => v != null).length, 0));
}

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
  for (const el of root.querySelectorAll(".js-plotly-plot")) window.Plotly.Plots.resize(el);
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

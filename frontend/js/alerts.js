// Overview: the alerts card — the selected site's active alerts (silent loggers, diagnosis
// faults, low performance ratio; GET /api/v1/alerts), the recently cleared ones under a fold,
// and what the service checks. Refreshed every 30 s while the overview is shown (not in a
// hidden tab), at once when the site changes.
import { api } from "./api.js";
import { KIND_WORDS as FAULT_WORDS } from "./diagnosis.js";
import { fmtDateTime } from "./time.js";
import { h, num } from "./ui.js";

const POLL_MS = 30000;
const CLEARED_SHOWN = 10;
const KIND_WORDS = {
  logger_silent: "Logger silent",
  fault: "Fault",
  low_performance_ratio: "Low performance ratio",
};
const WEBHOOK_WORDS = { queued: "webhook: sending…", delivered: "webhook: delivered", failed: "webhook: failed",
  dropped: "webhook: dropped (queue full)" };

let st = null;
let controller = null;
const $ = (id) => document.getElementById(id);

/** "Fault: tracker stuck" — the alert's kind in words. */
export function alertTitle(a) {
  const kind = KIND_WORDS[a.kind] || a.kind;
  return a.fault_kind ? `${kind}: ${FAULT_WORDS[a.fault_kind] || a.fault_kind}` : kind;
}

function item(a, tz) {
  const active = a.state === "active";
  return h("li", { class: `alert ${active ? "active" : "cleared"}`, "data-testid": "alert",
    "data-kind": a.kind, "data-state": a.state, "data-id": a.id },
  h("div", { class: "alert-head" },
    h("span", { class: `dot ${active ? "bad" : "ok"}`, "aria-hidden": "true" }),
    h("strong", {}, alertTitle(a)),
    h("span", { class: "alert-array" }, a.array),
    h("span", { class: "muted", title: `raised ${fmtDateTime(tz, a.raised_at)}` }, `since ${fmtDateTime(tz, a.since)}`),
    WEBHOOK_WORDS[a.webhook_status] ? h("span", { class: `muted webhook ${a.webhook_status}` }, WEBHOOK_WORDS[a.webhook_status]) : null),
  h("div", { class: "alert-detail", "data-testid": "alert-detail" }, a.detail),
  active ? null : h("div", { class: "muted" }, `cleared ${fmtDateTime(tz, a.cleared_at)}: ${a.cleared_detail || ""}`));
}

/** 30 → "30", 0.05 → "0.05". */
const plain = (v) => num(v, Number.isInteger(v) ? 0 : 2);

function rulesText(ev) {
  if (!ev || !ev.enabled) return "alert evaluation is off (HELIOTWIN_ALERTS)";
  const parts = [`checked every ${plain(ev.interval_s)} s`, `logger silent ${plain(ev.silent_min)} min`];
  if (ev.diagnosis_days > 0) {
    parts.push(`PR under ${num(ev.pr_below, 2)}`, `faults of confidence ≥ ${num(ev.fault_confidence_min, 2)}`);
  }
  const w = ev.webhook;
  parts.push(w ? `webhook ${w.url}: ${w.delivered} delivered, ${w.failed} failed, ${w.dropped} dropped` : "no webhook");
  return parts.join(" · ");
}

function render(active, cleared, tz) {
  const n = active.counts.active;
  $("alerts-title").textContent = n ? `Alerts — ${n} active` : "Alerts";
  $("alerts-card").classList.toggle("has-active", n > 0);
  $("alerts-rules").textContent = rulesText(active.evaluator);
  $("alerts-active").replaceChildren(...(active.alerts.length ? active.alerts.map((a) => item(a, tz))
    : [h("li", { class: "muted", "data-testid": "alerts-none" }, "No active alerts.")]));
  const total = cleared.counts.cleared;
  $("alerts-cleared-summary").textContent = total
    ? `Recently cleared (${Math.min(total, CLEARED_SHOWN)} of ${total})` : "Recently cleared (none)";
  $("alerts-cleared").replaceChildren(...cleared.alerts.map((a) => item(a, tz)));
}

/** Load the selected site's alerts (two reads: every active one, the latest cleared). */
export async function load() {
  if (!st?.site || !$("alerts-card")) return;
  controller?.abort();
  controller = new AbortController();
  const { signal } = controller;
  const site = st.site.site_id;
  try {
    const [active, cleared] = await Promise.all([
      api("/api/v1/alerts", { params: { site_id: site, state: "active", limit: 1000 }, signal }),
      api("/api/v1/alerts", { params: { site_id: site, state: "cleared", limit: CLEARED_SHOWN }, signal }),
    ]);
    if (signal.aborted || st.site.site_id !== site) return;
    render(active, cleared, st.tz);
    document.body.dataset.alertsLoaded = site;
  } catch (err) {
    if (err.name === "AbortError") return;
    $("alerts-active").replaceChildren(h("li", { class: "error" }, `Alerts unavailable: ${err.message}`));
  }
}

function tick() {
  if (document.hidden || st.page !== "overview") return;
  load();
}

/** Wire the card once: first load, the 30 s refresh, site changes. */
export function init(state) {
  st = state;
  if (!$("alerts-card")) return;
  setInterval(tick, POLL_MS);
  document.addEventListener("visibilitychange", tick);
  // main.js updates the shared state in its own listeners, registered before these
  $("site-select").addEventListener("change", () => load());
  window.addEventListener("hashchange", () => { if (st.page === "overview") load(); });
  load();
}

// Overview: the alerts card — the selected site's active alerts (silent loggers, diagnosis
// faults, low performance ratio; GET /api/v1/alerts), those nobody has acknowledged first,
// each with an "Acknowledge" button (POST /api/v1/alerts/{id}/acknowledge with the token
// typed into the card's form, kept there for the page's life as the other pages' token
// fields), the acknowledged ones shown calmer with who, when and their note; the recently
// cleared ones under a fold, and what the service checks. Refreshed every 30 s while the
// overview is shown (not in a hidden tab), at once when the site changes.
import { api, storedToken } from "./api.js";
import { fmtDateTime } from "./time.js";
import { h, num } from "./ui.js";

const POLL_MS = 30000;
const CLEARED_SHOWN = 10;
const WEBHOOK_WORDS = { queued: "webhook: sending…", delivered: "webhook: delivered", failed: "webhook: failed",
  dropped: "webhook: dropped (queue full)" };

let st = null;
let controller = null;
const shownAlerts = new Map(); // id → the active alert drawn, for the form
const $ = (id) => document.getElementById(id);

/** "Acknowledged by Ana (night shift), 5 Dec 09:12: sent Luis to the drive". */
function ackText(a, tz) {
  return `Acknowledged by ${a.acknowledged_by}, ${fmtDateTime(tz, a.acknowledged_at)}`
    + (a.acknowledged_note ? `: ${a.acknowledged_note}` : "");
}

function item(a, tz) {
  const active = a.state === "active";
  const acked = Boolean(a.acknowledged_at);
  const dot = !active ? "ok" : acked ? "ack" : "bad";
  return h("li", { class: `alert ${active ? "active" : "cleared"}${acked ? " acknowledged" : ""}`,
    "data-testid": "alert", "data-kind": a.kind, "data-state": a.state, "data-id": a.id,
    "data-acknowledged": String(acked) },
  h("div", { class: "alert-head" },
    h("span", { class: `dot ${dot}`, "aria-hidden": "true" }),
    h("strong", {}, a.title),
    h("span", { class: "alert-array" }, a.array),
    h("span", { class: "muted", title: `raised ${fmtDateTime(tz, a.raised_at)}` }, `since ${fmtDateTime(tz, a.since)}`),
    WEBHOOK_WORDS[a.webhook_status] ? h("span", { class: `muted webhook ${a.webhook_status}` }, WEBHOOK_WORDS[a.webhook_status]) : null,
    active && !acked ? h("button", { type: "button", class: "alert-ack-button", "data-testid": "alert-ack",
      "data-id": a.id, title: "Say you have seen it and are taking it on (needs a token)" }, "Acknowledge") : null),
  h("div", { class: "alert-detail", "data-testid": "alert-detail" }, a.detail),
  acked ? h("div", { class: "alert-ack-by", "data-testid": "alert-ack-by" }, ackText(a, tz)) : null,
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

/** "Alerts — 2 unacknowledged · 1 acknowledged": what still needs someone comes first. */
function titleText(counts) {
  const open = counts.active_unacknowledged;
  const taken = counts.active - open;
  const parts = [open ? `${open} unacknowledged` : null, taken ? `${taken} acknowledged` : null].filter(Boolean);
  return parts.length ? `Alerts — ${parts.join(" · ")}` : "Alerts";
}

function render(active, cleared, tz) {
  const open = active.counts.active_unacknowledged;
  $("alerts-title").textContent = titleText(active.counts);
  $("alerts-card").classList.toggle("has-active", open > 0);
  $("alerts-card").classList.toggle("has-acknowledged", open === 0 && active.counts.active > 0);
  $("alerts-rules").textContent = rulesText(active.evaluator);
  // the unacknowledged first (newest raised first within each: the API's order)
  const shown = [...active.alerts].sort((a, b) => Boolean(a.acknowledged_at) - Boolean(b.acknowledged_at));
  $("alerts-active").replaceChildren(...(shown.length ? shown.map((a) => item(a, tz))
    : [h("li", { class: "muted", "data-testid": "alerts-none" }, "No active alerts.")]));
  shownAlerts.clear();
  for (const a of active.alerts) shownAlerts.set(a.id, a);
  followForm(active.alerts);
  const total = cleared.counts.cleared;
  $("alerts-cleared-summary").textContent = total
    ? `Recently cleared (${Math.min(total, CLEARED_SHOWN)} of ${total})` : "Recently cleared (none)";
  $("alerts-cleared").replaceChildren(...cleared.alerts.map((a) => item(a, tz)));
}

// -- acknowledging ----------------------------------------------------------------------------
// One form under the list (not inside an alert: the 30 s refresh redraws the list, and would
// take the note being typed with it); it says which alert it is for.

const form = () => $("alerts-ack");

function status(text, kind = "") {
  $("alerts-ack-status").textContent = text;
  $("alerts-ack-status").className = `alerts-ack-status ${kind}`;
}

function closeForm(text = "", kind = "") {
  form().hidden = true;
  delete form().dataset.alertId;
  status(text, kind);
}

function openForm(a) {
  const f = form();
  f.dataset.alertId = a.id;
  f.dataset.site = a.site_id;
  f.dataset.title = a.title;
  $("alerts-ack-what").textContent = `Acknowledge “${a.title}” on the ${a.array} array (since ${fmtDateTime(st.tz, a.since)}):`;
  f.hidden = false;
  status("");
  $("alerts-ack-note").focus();
}

/** After a refresh: the form's alert taken by a colleague or cleared meanwhile closes it. */
function followForm(alerts) {
  const id = Number(form().dataset.alertId || 0);
  if (!id || form().hidden) return;
  if (form().dataset.site !== st.site?.site_id) { closeForm(); return; }
  const a = alerts.find((x) => x.id === id);
  if (!a) closeForm(`“${form().dataset.title}” was cleared meanwhile: nothing to acknowledge.`);
  else if (a.acknowledged_at) closeForm(`“${form().dataset.title}” was acknowledged meanwhile by ${a.acknowledged_by}.`);
}

async function send(ev) {
  ev.preventDefault();
  const id = form().dataset.alertId;
  const title = form().dataset.title;
  // the card's field, else the header's token (HELIOTWIN_READ_REQUIRE_TOKEN), if any
  const token = $("alerts-ack-token").value.trim() || storedToken();
  if (!token) {
    status("Acknowledging needs a token: paste into “Token” a site-scope token of this site named after you "
      + "(heliotwin token create --site ID --scope site --label \"Your name\") or the admin token.", "error");
    return;
  }
  const note = $("alerts-ack-note").value.trim();
  $("alerts-ack-send").disabled = true;
  try {
    const a = await api(`/api/v1/alerts/${encodeURIComponent(id)}/acknowledge`,
      { method: "POST", json: note ? { note } : {}, token });
    // the form may show another alert by now (opened while this one was sent): leave it be
    if (form().dataset.alertId === id) {
      $("alerts-ack-note").value = "";
      closeForm(`“${title}” acknowledged by ${a.acknowledged_by}.`);
    } else {
      status(`“${title}” acknowledged by ${a.acknowledged_by}.`);
    }
    await load();
  } catch (err) {
    if (form().dataset.alertId !== id) {  // the form shows another alert now: say it there
      status(`“${title}” not acknowledged: ${err.message}`, "error");
      await load();
      return;
    }
    if (err.status !== 409) { status(`Not acknowledged: ${err.message}`, "error"); return; }
    closeForm(`Not acknowledged: ${err.message}`, "error"); // cleared meanwhile: the list moves on
    await load();
  } finally {
    $("alerts-ack-send").disabled = false;
  }
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
  $("alerts-active").addEventListener("click", (ev) => {
    const button = ev.target.closest("[data-testid=alert-ack]");
    if (!button) return;
    const a = shownAlerts.get(Number(button.dataset.id));
    if (a) openForm(a);
  });
  form().addEventListener("submit", send);
  $("alerts-ack-cancel").addEventListener("click", () => closeForm());
  setInterval(tick, POLL_MS);
  document.addEventListener("visibilitychange", tick);
  // main.js updates the shared state in its own listeners, registered before these
  $("site-select").addEventListener("change", () => { closeForm(); load(); });
  window.addEventListener("hashchange", () => { if (st.page === "overview") load(); });
  load();
}

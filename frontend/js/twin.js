// 3D twin: the viser scene (served by the backend on its own port) in an iframe.
//
// Every tab is its own viewer: the iframe's viser client connects to a websocket URL whose
// path says what to show (backend/twin/scene.py): /site/<id>/viewer/<key> for the selected
// site, or /plant/<id>/strategy/<s>/time/<ISO> for a plant of trackers (#twin?plant=…,
// linked from the Plant page). <key> is this tab's viewer key, kept in sessionStorage.
import { api } from "./api.js";

const enc = encodeURIComponent;
const VIEWER_KEY = "heliotwin.viewer";
let loaded = false;
let plants = null;

/** This tab's viewer key (PUT /api/v1/twin3d/replay {"viewer"} replays a run in it alone). */
export function viewerKey() {
  let key = sessionStorage.getItem(VIEWER_KEY);
  if (!key) {
    key = `v${Date.now().toString(36)}${Math.random().toString(36).slice(2, 10)}`;
    sessionStorage.setItem(VIEWER_KEY, key);
  }
  return key;
}

// The port the browser reaches viser on (HELIOTWIN_VISER_PUBLIC_PORT: a container's published
// port, a proxy), else the one it listens on; always on the host name the page came from.
function viserBase(state) {
  const port = state.meta?.viser_public_port || state.meta?.viser_port || 8080;
  return { http: `${location.protocol}//${location.hostname}:${port}/`,
    ws: `${location.protocol === "https:" ? "wss" : "ws"}://${location.hostname}:${port}` };
}

/** What the 3D page shows: the hash's plant view (#twin?plant=&strategy=&time=) or the site. */
function selection(state) {
  const q = new URLSearchParams(location.hash.split("?")[1] || "");
  const plant = q.get("plant");
  if (plant) return { plant, strategy: q.get("strategy") || "sun", time: q.get("time") };
  return { site: state.site?.site_id || state.meta?.default_site || "" };
}

function viewPath(sel) {
  if (sel.plant) {
    const t = sel.time && !Number.isNaN(Date.parse(sel.time)) ? `/time/${new Date(sel.time).toISOString()}` : "";
    return `/plant/${enc(sel.plant)}/strategy/${enc(sel.strategy)}${t}`;
  }
  return `/site/${enc(sel.site)}/viewer/${viewerKey()}`;
}

/** The viser page for a selection (its client connects to the ?websocket= URL). */
export function twinUrl(state, sel = selection(state)) {
  const base = viserBase(state);
  return `${base.http}?websocket=${enc(base.ws + viewPath(sel))}`;
}

function explain(message) {
  const wrap = document.querySelector(".twin-frame-wrap");
  wrap.querySelector("iframe")?.remove();
  const p = wrap.querySelector("p.muted") || document.createElement("p");
  p.className = "muted";
  p.style.padding = "24px";
  p.textContent = message;
  wrap.append(p);
}

async function fillViews(state) {
  const select = document.getElementById("twin-view");
  if (!select) return;
  if (plants === null) {
    try { plants = await api("/api/v1/plants"); } catch { plants = []; }
  }
  const sel = selection(state);
  select.innerHTML = "";
  select.add(new Option(`Site: ${state.site?.name || sel.site || "default"}`, "site"));
  for (const p of plants) select.add(new Option(`Plant: ${p.name || p.plant_id} (${p.trackers} trackers)`, `plant:${p.plant_id}`));
  select.value = sel.plant ? `plant:${sel.plant}` : "site";
}

function render(state) {
  const url = twinUrl(state);
  document.getElementById("twin-open").href = url;
  const frame = document.getElementById("twin-frame");
  if (frame && frame.getAttribute("src") !== url) frame.src = url;
  document.body.dataset.twinView = viewPath(selection(state));
  fillViews(state);
}

export async function init(state) {
  loaded = true;
  const link = document.getElementById("twin-open");
  if (state.meta?.viser_enabled === false) {
    link.hidden = true;
    explain("The 3D twin is switched off on this service (HELIOTWIN_VISER=false).");
    return;
  }
  const probe = viserBase(state).http;
  try {
    await fetch(probe, { mode: "no-cors", cache: "no-store" }); // is viser listening?
  } catch {
    explain(`The 3D twin does not answer at ${probe}: is the service's viser scene running?`);
    return;
  }
  document.getElementById("twin-view")?.addEventListener("change", (ev) => {
    const v = ev.target.value;
    location.hash = v.startsWith("plant:") ? `#twin?plant=${enc(v.slice(6))}` : "#twin";
  });
  // Loaded only when the page is first opened: the WebGL scene costs CPU.
  render(state);
}

export function show(state) {
  if (!loaded) init(state);
  else if (state.meta?.viser_enabled !== false) render(state);
}

/** The dashboard's site changed: a site viewer follows it (a new viewer for the new site). */
export function siteChanged(state, visible) {
  if (loaded && visible && state.meta?.viser_enabled !== false) render(state); // else at show()
}

// Dashboard shell: site picker, hash navigation between pages, shared state.
import { getMeta, getSites, storedToken, storeToken } from "./api.js";
import { loadPlotly, resizeVisible, wireCsvButtons } from "./charts.js";
import { localDate, zoneLabel } from "./time.js";
import { banner } from "./ui.js";
import * as overview from "./overview.js";
import * as simulation from "./simulation.js";
import * as sky from "./sky.js";
import * as twin from "./twin.js";
import * as plant from "./plant.js";
import * as sites from "./sites.js";
import * as diagnosis from "./diagnosis.js";
import * as alerts from "./alerts.js";
import * as pointing from "./pointing.js";

const PAGES = { overview, simulation, sky, twin, plant, pointing, sites };

/** Shared state every page reads: the site, its zone, the selected day, server meta. */
export const state = {
  sites: [],
  site: null,
  tz: "UTC",
  day: null,
  meta: {},
  page: null,
};

const started = new Set();

function pageFromHash() {
  const name = (location.hash || "#overview").slice(1).split("?")[0];
  return PAGES[name] ? name : "overview";
}

/** Parameters after the page in the hash: #overview?site=tehuantepec&day=2026-11-20. */
function hashParams() {
  return new URLSearchParams((location.hash.split("?")[1]) || "");
}

function showPage(name) {
  state.page = name;
  for (const sec of document.querySelectorAll("section.page")) sec.hidden = sec.dataset.page !== name;
  for (const a of document.querySelectorAll(".tabs a")) a.classList.toggle("active", a.dataset.page === name);
  const mod = PAGES[name];
  if (!started.has(name)) {
    started.add(name);
    mod.init(state);
  } else {
    mod.show?.(state);
  }
  for (const [other, m] of Object.entries(PAGES)) if (other !== name) m.hide?.(state);
  resizeVisible(document.getElementById(`page-${name}`));
}

function setSite(siteId) {
  state.site = state.sites.find((s) => s.site_id === siteId) || state.sites[0] || null;
  state.tz = state.site?.timezone || "UTC";
  state.day = localDate(state.tz);
  document.getElementById("site-tz").textContent = zoneLabel(state.tz);
  document.getElementById("site-select").title = state.site ? `site id ${state.site.site_id}` : "";
  document.getElementById("site-select").value = state.site?.site_id || "";
  localStorage.setItem("heliotwin.site", state.site?.site_id || "");
}

/** Show the header's token field (HELIOTWIN_READ_REQUIRE_TOKEN) with the server's message. */
function askToken(message) {
  document.getElementById("read-token-form").hidden = false;
  document.getElementById("read-token-msg").textContent = message || "";
  document.getElementById("read-token").focus();
}

/** The header's token: stored for this tab (api.js) and the page reloaded with it, so every
 *  page starts over reading with it; "Forget token" drops it. A 401 of a read (a token
 *  revoked or expired meanwhile) shows the field again with the server's message. */
function wireToken() {
  const form = document.getElementById("read-token-form");
  const forget = document.getElementById("read-token-forget");
  forget.hidden = !storedToken();
  form.addEventListener("submit", (event) => {
    event.preventDefault();
    const token = document.getElementById("read-token").value.trim();
    if (!token) { askToken("Paste a token first."); return; }
    storeToken(token);
    location.reload();
  });
  forget.addEventListener("click", () => { storeToken(""); location.reload(); });
  window.addEventListener("heliotwin:unauthorized", (event) => {
    if (state.meta.read_require_token || storedToken()) askToken(event.detail);
  });
}

async function boot() {
  wireCsvButtons();
  wireToken();
  const select = document.getElementById("site-select");
  const [sitesRes, metaRes] = await Promise.allSettled([getSites(), getMeta()]);
  if (metaRes.status === "fulfilled") state.meta = metaRes.value || {};
  if (sitesRes.status === "rejected" && sitesRes.reason.status === 401) {
    // reads need a token (meta.read_require_token) and none, or a bad one, was sent; a bad
    // one is said as such ("unknown write token" alone left a reader guessing)
    const detail = sitesRes.reason.body?.detail || sitesRes.reason.message;
    askToken(storedToken() ? `The token you gave was refused (${detail}): paste a valid one — any site's `
      + "token (heliotwin token create --site ID) or the admin token — or Forget token." : detail);
    return;
  }
  if (sitesRes.status === "rejected") {
    banner(`Could not load the sites: ${sitesRes.reason.message}`, "error");
    return;
  }
  state.sites = sitesRes.value; // list[SiteRead]
  if (!state.sites.length) {
    banner("The service has no sites configured (data/sites/).", "error");
    return;
  }
  for (const s of state.sites) {
    const opt = new Option(s.name || s.site_id, s.site_id);
    opt.title = s.site_id;
    select.add(opt);
  }
  const saved = hashParams().get("site") || localStorage.getItem("heliotwin.site");
  const known = (id) => state.sites.some((s) => s.site_id === id);
  setSite(known(saved) ? saved : known(state.meta.default_site) ? state.meta.default_site : state.sites[0].site_id);
  const day = hashParams().get("day");
  if (day && /^\d{4}-\d{2}-\d{2}$/.test(day) && day <= state.day) state.day = day;
  select.addEventListener("change", () => {
    setSite(select.value);
    // the address follows on every page (only the Overview's said the new site: a reload
    // of #sky?site=old went back to the old one)
    const q = hashParams();
    q.set("site", select.value);
    history.replaceState(null, "", `#${state.page}?${q}`);
    for (const [name, m] of Object.entries(PAGES)) if (started.has(name)) m.siteChanged?.(state, name === state.page);
  });
  window.addEventListener("hashchange", () => {
    // an address edited in an open tab is followed: its site first, then its page
    const site = hashParams().get("site");
    if (site && site !== state.site?.site_id && known(site)) {
      setSite(site);
      for (const [name, m] of Object.entries(PAGES)) if (started.has(name)) m.siteChanged?.(state, false);
    }
    showPage(pageFromHash());
  });
  showPage(pageFromHash());
  diagnosis.init(state);
  alerts.init(state);
  loadPlotly(); // after the page has sent its requests: Plotly's start-up overlaps the answers
}

boot().catch((err) => banner(`Dashboard failed to start: ${err.message}`, "error")).finally(loadPlotly);

// Sites: create or edit a site config (docs/sites.md) — PUT /api/v1/sites/{site_id} with a token.
import { api } from "./api.js";
import { h, sayInvalid } from "./ui.js";

let st = null;
// a new site is being written ("New site from the selected one"): saving it must not
// replace a site that has its id (PUT creates or replaces; the page overwrote one unasked)
let creating = false;
const $ = (id) => document.getElementById(id);
const FIELDS = [["site-id", "site_id"], ["site-name", "name"], ["site-lat", "latitude_deg"],
  ["site-lon", "longitude_deg"], ["site-alt", "altitude_m"], ["site-tz-input", "timezone"],
  ["site-stamped", "readings_stamped"]];

function result(text, kind = "ok") {
  $("site-result").replaceChildren(h("p", { class: kind === "ok" ? "ok" : "error" }, text));
}

// What a site's place decides (sim.sites.CLIMATE_KEYS, FIXED_SURFACE_KEYS): a new site does not
// copy them; the service fills them in from its place when it is saved, marked "assumed".
const CLIMATE_KEYS = ["temp_air_c", "wind_speed_m_s"];
// the ground's height there (sim.sites.relocated_config drops it too): a copy kept the
// selected site's, 50 m of Tehuantepec for a site at 558 m (a tester's finding)
const ALTITUDE_KEY = "altitude_m";
const FIXED_SURFACE_KEYS = ["surface_tilt_deg", "surface_azimuth_deg"];
const TRACKER_PLACE_KEYS = ["azimuth_min_deg", "azimuth_max_deg"];

const valueAt = (config, path) => path.split(".").reduce((v, k) => (v == null ? v : v[k]), config);

/** The config's "assumed" keys (SiteConfig.assumed): values the place gave, not a survey. */
function showAssumed(config, pending = []) {
  const marks = Object.entries(config.assumed || {});
  const items = marks.map(([k, why]) => h("li", {}, h("code", {}, k), ` = ${valueAt(config, k)} — assumed: ${why}`));
  for (const k of pending) items.push(h("li", {}, h("code", {}, k), " — from the place when saved (marked assumed)"));
  $("site-assumed").replaceChildren(...(items.length
    ? [h("p", { class: "warning" }, "Not measured at this site — check these and set the site's own values:"), h("ul", {}, items)]
    : []));
}

function fill(config, pending = []) {
  for (const [id, key] of FIELDS) $(id).value = config[key] ?? "";
  $("site-json").value = JSON.stringify(config, null, 2);
  showAssumed(config, pending);
}

async function loadSelected() {
  if (!st.site) return;
  creating = false;  // editing the selected site: saving replaces it, as asked
  try {
    fill(await api(`/api/v1/sites/${encodeURIComponent(st.site.site_id)}/config`));
    $("site-result").replaceChildren();
    document.body.dataset.sitesLoaded = st.site.site_id; // the form holds this site's config
  } catch (err) {
    result(`Could not read the config: ${err.message}`, "error");
  }
}

/** The JSON of the text area with the form's fields written into it. */
function configFromForm() {
  let config;
  try {
    config = JSON.parse($("site-json").value || "{}");
  } catch (err) {
    throw new Error(`Full config: not valid JSON (${err.message})`);
  }
  for (const [id, key] of FIELDS) {
    const el = $(id);
    if (el.value === "") delete config[key]; // the format's default (docs/site.schema.json)
    else config[key] = el.type === "number" ? Number(el.value) : el.value;
  }
  return config;
}

/** The JSON box follows the form as it is typed in (a box that is not valid JSON is left alone). */
function formToJson() {
  try {
    $("site-json").value = JSON.stringify(configFromForm(), null, 2);
  } catch { /* the message comes on save */ }
}

/** The form follows the JSON box when it is edited. */
function jsonToForm() {
  try {
    const config = JSON.parse($("site-json").value || "{}");
    for (const [id, key] of FIELDS) $(id).value = config[key] ?? "";
  } catch { /* the message comes on save */ }
}

async function save(ev) {
  ev.preventDefault();
  let config;
  try {
    config = configFromForm();
  } catch (err) {
    result(err.message, "error");
    return;
  }
  const siteId = config.site_id || "";
  result("Saving…");
  if (creating && st.sites.some((s) => s.site_id === siteId)) {
    result(`Not saved: a site with id ${siteId} exists already; give the new site another id `
      + "(or select that site in the header to edit it).", "error");
    return;
  }
  try {
    const body = await api(`/api/v1/sites/${encodeURIComponent(siteId)}`, {
      method: "PUT", json: config, token: $("site-token").value.trim() || undefined,
    });
    fill(await api(`/api/v1/sites/${encodeURIComponent(siteId)}/config`));
    result(`${body.created ? "Created" : "Saved"} site ${siteId} (${body.origin} file); `
      + `${body.twin_readings_dropped} cached twin readings dropped. Reloading the dashboard on it…`);
    setTimeout(() => { location.hash = `#overview?site=${encodeURIComponent(siteId)}`; location.reload(); }, 800);
  } catch (err) {
    result(`Not saved: ${err.message}`, "error");
  }
}

function newSite() {
  let config;
  try {
    config = configFromForm();
  } catch (err) {  // the JSON box: said here, not as an uncaught error
    result(err.message, "error");
    return;
  }
  creating = true;
  config.site_id = "";
  config.name = "";
  config.source = "";
  config.notes = "";
  const pending = [ALTITUDE_KEY, ...CLIMATE_KEYS];
  for (const key of [ALTITUDE_KEY, ...CLIMATE_KEYS, "assumed"]) delete config[key];
  for (const [name, arr] of Object.entries(config.arrays || {})) {
    if (arr.mount !== "fixed") continue;
    for (const key of FIXED_SURFACE_KEYS) delete arr[key];
    pending.push(...FIXED_SURFACE_KEYS.map((k) => `arrays.${name}.${k}`));
  }
  // the azimuth joint's range faces the new place's equator (sim.sites.TRACKER_PLACE_KEYS)
  for (const key of TRACKER_PLACE_KEYS) if (config.tracker) delete config.tracker[key];
  pending.push(...TRACKER_PLACE_KEYS.map((k) => `tracker.${k}`));
  fill(config, pending);
  $("site-id").focus();
  result("A copy of the selected site's tracker and arrays: give it an id and a place, then save with the admin "
    + "token (HELIOTWIN_ADMIN_TOKEN). Its altitude (unless you type one), fixed tilt, the tracker's azimuth "
    + "range, air temperature and wind come from the new place.");
}

export function init(state) {
  st = state;
  $("site-form").addEventListener("submit", save);
  sayInvalid($("site-form"), (message) => result(`Not saved: ${message}`, "error"));
  $("site-new").addEventListener("click", newSite);
  for (const [id] of FIELDS) $(id).addEventListener("input", formToJson);
  $("site-json").addEventListener("change", jsonToForm);
  // which token scope edits a site (backend/auth.py): a logger's "ingest" token is refused
  $("site-token").placeholder = "site-scope or admin token";
  $("site-token").title = "A 'site'-scope token of this site (heliotwin token create --site ID --scope site) "
    + "or the admin token (HELIOTWIN_ADMIN_TOKEN). A field logger's 'ingest' token writes readings only.";
  loadSelected();
}

export function show(state) {
  st = state;
}

export function siteChanged(state, visible) {
  st = state;
  if (visible || $("site-json").value) loadSelected();
}

// Sites: create or edit a site config (docs/sites.md) — PUT /api/v1/sites/{site_id} with a token.
import { api } from "./api.js";
import { h } from "./ui.js";

let st = null;
const $ = (id) => document.getElementById(id);
const FIELDS = [["site-id", "site_id"], ["site-name", "name"], ["site-lat", "latitude_deg"],
  ["site-lon", "longitude_deg"], ["site-alt", "altitude_m"], ["site-tz-input", "timezone"]];

function result(text, kind = "ok") {
  $("site-result").replaceChildren(h("p", { class: kind === "ok" ? "ok" : "error" }, text));
}

function fill(config) {
  for (const [id, key] of FIELDS) $(id).value = config[key] ?? "";
  $("site-json").value = JSON.stringify(config, null, 2);
}

async function loadSelected() {
  if (!st.site) return;
  try {
    fill(await api(`/api/v1/sites/${encodeURIComponent(st.site.site_id)}/config`));
    $("site-result").replaceChildren();
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
    if (el.value === "") continue;
    config[key] = el.type === "number" ? Number(el.value) : el.value;
  }
  return config;
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
  const config = configFromForm();
  config.site_id = "";
  config.name = "";
  config.source = "";
  config.notes = "";
  fill(config);
  $("site-id").focus();
  result("A copy of the selected site: give it an id and a place, then save with the admin token.");
}

export function init(state) {
  st = state;
  $("site-form").addEventListener("submit", save);
  $("site-new").addEventListener("click", newSite);
  loadSelected();
}

export function show(state) {
  st = state;
}

export function siteChanged(state, visible) {
  st = state;
  if (visible || $("site-json").value) loadSelected();
}

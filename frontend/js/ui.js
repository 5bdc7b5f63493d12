// Small DOM helpers shared by the pages.

export function banner(message, kind = "warn") {
  const el = document.getElementById("banner");
  if (!message) { el.hidden = true; return; }
  el.textContent = message;
  el.className = `banner ${kind === "error" ? "error" : ""}`;
  el.hidden = false;
}

/** Create an element: h("td", {class: "x"}, "text", child). */
export function h(tag, attrs = {}, ...children) {
  const el = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs || {})) {
    if (v === undefined || v === null || v === false) continue;
    if (k === "class") el.className = v;
    else if (k === "text") el.textContent = v;
    else el.setAttribute(k, v === true ? "" : v);
  }
  for (const c of children.flat()) {
    if (c === null || c === undefined || c === false) continue;
    el.append(c instanceof Node ? c : String(c));
  }
  return el;
}

/** A number with fixed decimals, or an em dash when missing. */
export function num(v, digits = 0) {
  if (typeof v !== "number" || !Number.isFinite(v)) return "—";
  const shown = Math.abs(v) * 10 ** digits < 0.5 ? 0 : v; // what rounds to zero has no sign ("-0.00")
  return shown.toLocaleString(undefined, { minimumFractionDigits: digits, maximumFractionDigits: digits });
}

/** Energy in Wh shown as kWh above 1 kWh. */
export function energy(wh) {
  if (typeof wh !== "number" || !Number.isFinite(wh)) return "—";
  if (Math.abs(wh) >= 1e6) return `${num(wh / 1e6, 2)} MWh`;
  return Math.abs(wh) >= 1000 ? `${num(wh / 1000, Math.abs(wh) >= 1e5 ? 1 : 2)} kWh` : `${num(wh, 0)} Wh`;
}

export function pct(v, digits = 1) {
  if (typeof v !== "number" || !Number.isFinite(v)) return "—";
  return `${v > 0 ? "+" : ""}${num(v, digits)} %`;
}

/** One status tile. */
export function tile(label, value, sub, level) {
  return h("div", { class: `tile ${level || ""}`, "data-testid": "tile" },
    h("div", { class: "label" }, label),
    h("div", { class: "value" }, value),
    sub ? h("div", { class: "sub" }, sub) : null);
}

/** Keep the site and day in the address, so a reload or a shared link shows the same view. */
export function remember(state, page) {
  const q = new URLSearchParams({ site: state.site?.site_id || "", day: state.day || "" });
  history.replaceState(null, "", `#${page}?${q}`);
}

/** A form's message follows every submit, also one the browser's own validation blocks (a
 * required field empty, a pattern or range not met): that fires no `submit` event, so the
 * message of the previous submit stayed beside the browser's bubble as if it were this
 * one's. `say` gets the first invalid field's label and the browser's reason instead. */
export function sayInvalid(form, say) {
  let told = false; // `invalid` fires once per invalid field of one submit: the first is said
  form.addEventListener("invalid", (ev) => {
    if (told) return;
    told = true;
    setTimeout(() => { told = false; }, 0);
    const el = ev.target;
    const label = el.getAttribute("aria-label") || el.closest("label")?.firstChild?.textContent?.trim() || el.name || el.id;
    const hint = el.validity.patternMismatch && el.title ? ` (${el.title})` : "";
    say(`${label}: ${el.validationMessage}${hint}`);
  }, true); // `invalid` does not bubble: caught on its way down
}

/** The run's weather warning (a file off the sun's time, sim.weather_clock) as a tile across
 * the row, or nothing. */
export function weatherWarning(summary) {
  if (!summary.weather_warning) return [];
  const t = tile("Weather off the sun's time", `${num(summary.weather_shift_min, 0)} min`, summary.weather_warning, "warn");
  t.classList.add("wide");
  t.dataset.testid = "weather-warning";
  return [t];
}

/** The run's sky: clear sky, or the weather file's station and its distance from the
 * `place` ("site" or "plant") it ran at, or measured weather's span (and its distance, for
 * a file that says where it is from: an NSRDB year). */
export function skyTile(summary, station, place) {
  if (!station) return tile("Sky", summary.sky === "weather" ? "weather" : "clear sky", "Ineichen clear sky with Linke turbidity");
  if (station.format === "measured") {
    const far = station.distance_km == null ? "" : ` · ${num(station.distance_km, 0)} km from the ${place}`;
    return tile("Sky", "measured weather", `${station.name || "file"} · ${station.stamped.replace("_", " ")} stamps · ${station.start.slice(0, 16)} → ${station.end.slice(0, 16)} UTC${far}`);
  }
  return tile("Sky", `${station.format.toUpperCase()} typical year`,
    `${station.name || "station"} (${num(station.latitude_deg, 2)}°, ${num(station.longitude_deg, 2)}°) · ${num(station.distance_km, 0)} km from the ${place}`);
}

/** The wind stow's cost beside the gain (sim/stow.py), for a site or plant that stows;
 * nothing otherwise. */
export function stowTile(summary) {
  if (summary.stow_wind_speed_m_s === undefined || summary.stow_wind_speed_m_s === null) return [];
  const over = `wind over ${num(summary.stow_wind_speed_m_s, 1)} m/s`;
  const t = summary.stow_min === null
    ? tile("Wind stow", "—", `no wind speed in this run's sky; stows at ${over}`)
    : summary.stow_loss_wh < 0 // under cloud a flat panel sees more of the sky than one facing a low sun
      ? tile("Wind stow", energy(-summary.stow_loss_wh), `gained, not lost, in ${num(summary.stow_min, 0)} daylight minutes flat: a cloudy sky's light is best caught flat · ${over}`)
      : tile("Wind stow", energy(summary.stow_loss_wh), `lost in ${num(summary.stow_min, 0)} daylight minutes flat · ${over}`);
  t.dataset.testid = "stow-tile";
  return [t];
}

// Sky camera: upload frames, find the sun, compare with the ephemeris, calibrate a fisheye.
import { api, storedToken } from "./api.js";
import { COLORS, baseLayout, draw, showEmpty } from "./charts.js";
import { addDays, fmtDateTime, localDate, localMidnightMs, localWallMs, toLocalWall } from "./time.js";
import { banner, h, num } from "./ui.js";

let st = null;
let files = []; // [{file, input (datetime-local), url, width, height}]

const $ = (id) => document.getElementById(id);
const DEG = Math.PI / 180;

let namesRead = Promise.resolve(); // the file-name times being fetched for the chosen files

function offsetString(minutes) {
  const sign = minutes < 0 ? "-" : "+";
  const a = Math.abs(minutes);
  return `${sign}${String(Math.floor(a / 60)).padStart(2, "0")}:${String(a % 60).padStart(2, "0")}`;
}

/** Where a row's zone comes from: its file name (which wins), or the "Times … are in" selector. */
function rowZone(row) {
  if (row.zoneError && !row.input.value) return { source: "none", label: `no time: ${row.zoneError}` };
  if (row.offsetH !== null && row.offsetH !== undefined && row.fromName) {
    return { source: "name", label: `UTC${offsetString(row.offsetH * 60)}, from the file name` };
  }
  if ($("sky-name-tz").value === "site") return { source: "site", label: `the site's time (${st.tz})` };
  return { source: "utc", label: "UTC" };
}

/** The ISO timestamp (with offset) a row's datetime-local input stands for. */
function rowTimestamp(row) {
  const wall = row.input.value;
  if (!wall) return null;
  const full = wall.length === 16 ? `${wall}:00` : wall;
  const zone = rowZone(row).source;
  let offMin;
  if (zone === "name") offMin = row.offsetH * 60;
  else if (zone === "site") offMin = (Date.parse(`${full}Z`) - localWallMs(st.tz, full)) / 60000;
  else offMin = 0;
  return `${full}${offsetString(offMin)}`;
}

/** Each row says which zone its time is read in, and the UTC instant that makes. */
function refreshZones() {
  for (const row of files) {
    const ts = rowTimestamp(row);
    row.zone.textContent = `in ${rowZone(row).label}${ts ? ` → ${new Date(ts).toISOString().slice(0, 19)}Z` : ""}`;
  }
}

function readSize(url) {
  return new Promise((resolve, reject) => {
    const img = new Image();
    img.onload = () => resolve(img);
    img.onerror = () => reject(new Error("not an image the browser can show"));
    img.src = url;
  });
}

function renderFileList() {
  const box = $("sky-file-list");
  box.innerHTML = "";
  for (const row of files) {
    row.input.addEventListener("input", () => { row.fromName = false; refreshZones(); });
    row.zone = h("span", { class: "muted zone", "data-testid": "sky-row-zone" });
    box.append(h("div", { class: "row" }, h("span", { class: "name", title: row.file.name }, row.file.name), row.input, row.zone));
  }
  refreshZones();
  if (files.length) box.append(h("div", { class: "muted" }, "Time of each frame (needed for the ephemeris and for calibration). A time typed by hand is read in the selector's zone."));
}

/** The times the chosen files' names carry, read by the server (GET /api/v1/vision/frame-times,
 * backend/vision/frames.py: the rule detection and the CLI apply), written into each row. */
async function readNameTimes(rows) {
  if (!rows.length) return;
  const q = new URLSearchParams();
  for (const row of rows) q.append("filename", row.file.name);
  try {
    const res = await api(`/api/v1/vision/frame-times?${q}`);
    res.frames.forEach((t, i) => {
      const row = rows[i];
      row.zoneError = t.zone_error || null;  // a zone the name states but cannot be read exactly
      if (!t.wall_time || row.input.value) return; // a time typed meanwhile wins
      row.input.value = t.wall_time;
      row.offsetH = t.utc_offset_h;
      row.fromName = true;
    });
  } catch (err) {
    $("sky-status").textContent = `Could not read the times in the file names: ${err.message}`;
  }
  refreshZones();
}

function onFiles() {
  for (const f of files) URL.revokeObjectURL(f.url);
  files = [...$("sky-files").files].map((file) => {
    const input = h("input", { type: "datetime-local", step: "1", "aria-label": `time of ${file.name}` });
    return { file, input, url: URL.createObjectURL(file), offsetH: null, fromName: false };
  });
  renderFileList();
  namesRead = readNameTimes(files);
}

async function cameraParams(form) {
  const cam = $("sky-camera").value;
  const calibration = $("sky-calibration").value;
  if (calibration) {
    form.append("calibration_id", calibration);
    return { camera: "fisheye", calibration_id: calibration };
  }
  form.append("camera", cam);
  const box = document.querySelector(`.cam-params[data-camera="${cam}"]`);
  const params = { camera: cam };
  for (const el of box.querySelectorAll("input, select")) {
    if (el.value === "") continue;
    form.append(el.name, el.value);
    params[el.name] = el.tagName === "SELECT" ? el.value : Number(el.value);
  }
  return params;
}

function placeParams(form) {
  if ($("sky-place").value === "calibration") return; // the service takes the calibration's
  if ($("sky-place").value === "site") {
    form.append("site_id", st.site.site_id);
    return;
  }
  for (const name of ["latitude_deg", "longitude_deg", "elevation_m"]) {
    const el = document.querySelector(`#sky-coords [name="${name}"]`);
    if (el.value !== "") form.append(name, el.value);
  }
}

function drawMarker(ctx, x, y, color, radius, cross) {
  ctx.strokeStyle = color;
  ctx.lineWidth = Math.max(2, radius / 5);
  ctx.beginPath();
  ctx.arc(x, y, radius, 0, 2 * Math.PI);
  ctx.stroke();
  if (cross) {
    ctx.beginPath();
    ctx.moveTo(x - radius * 1.8, y); ctx.lineTo(x - radius * 0.4, y);
    ctx.moveTo(x + radius * 0.4, y); ctx.lineTo(x + radius * 1.8, y);
    ctx.moveTo(x, y - radius * 1.8); ctx.lineTo(x, y - radius * 0.4);
    ctx.moveTo(x, y + radius * 0.4); ctx.lineTo(x, y + radius * 1.8);
    ctx.stroke();
  }
}

function resultCard(row, img, res, params) {
  const canvas = h("canvas", { "data-testid": "sky-canvas" });
  // the server's image size when this browser cannot draw the file (img null: no picture)
  const [width, height] = img ? [img.naturalWidth, img.naturalHeight] : res.image_size_px;
  const scale = Math.min(1, 900 / Math.max(width, height));
  canvas.width = Math.round(width * scale);
  canvas.height = Math.round(height * scale);
  const ctx = canvas.getContext("2d");
  if (img) ctx.drawImage(img, 0, 0, canvas.width, canvas.height);
  const radius = Math.max(8, canvas.width / 28);
  // SunDetectionRead: the ephemeris (with time and place) and, for a fisheye, its pixel
  // through the same camera model (null below the horizon)
  const centroid = res.centroid_px;
  const eph = res.ephemeris;
  const ephPx = eph?.centroid_px ?? null;
  if (res.camera === "pinhole") { // the reference pixel typed in the form, else the centre
    const rx = params.reference_x_px ?? (width - 1) / 2;
    const ry = params.reference_y_px ?? (height - 1) / 2;
    ctx.setLineDash([4, 4]);
    drawMarker(ctx, rx * scale, ry * scale, "#1971c2", radius * 0.6, true);
    ctx.setLineDash([]);
  }
  if (ephPx) drawMarker(ctx, ephPx[0] * scale, ephPx[1] * scale, "#1971c2", radius, false);
  if (res.sun_found && centroid) drawMarker(ctx, centroid[0] * scale, centroid[1] * scale, "#ff6b00", radius * 0.7, true);

  const rows = [];
  const kv = (k, v) => rows.push(h("tr", {}, h("th", {}, k), h("td", {}, v)));
  kv("Sun found", res.sun_found ? `yes (confidence ${num(res.confidence, 2)})` : `no (confidence ${num(res.confidence, 2)})`);
  if (!res.sun_found && res.reason) kv("Why not", res.reason);  // the service's words
  if (centroid) kv("Centroid [px]", `${num(centroid[0], 1)}, ${num(centroid[1], 1)}`);
  if (typeof res.azimuth_deg === "number") kv("Detected az / el [°]", `${num(res.azimuth_deg, 2)} / ${num(res.elevation_deg, 2)}`);
  if (eph) kv("Ephemeris az / el [°]", `${num(eph.azimuth_deg, 2)} / ${num(eph.elevation_deg, 2)}`);
  const sep = res.error?.separation_deg;
  if (typeof sep === "number") kv("Error vs ephemeris [°]", num(sep, 2));
  const pe = res.pointing_error_deg;
  if (pe) kv("Pointing error [°] (right, up)", `${num(pe[0], 3)}, ${num(pe[1], 3)}`);
  if (typeof res.pointing_error_mrad === "number") kv("Pointing error [mrad]", num(res.pointing_error_mrad, 2));
  const derived = res.camera_derived;
  if (derived) kv("Scale [px/°]", `${num(derived.px_per_deg, 3)} — derived: ${derived.how}; ${derived.warning}`);
  if (res.method) kv("Method", res.method);
  if (res.timestamp_source && res.timestamp_source !== "given") kv("Time from", res.timestamp_source);
  if (!img) kv("Picture", "this browser cannot draw the file; the markers are on a blank canvas");
  const warnings = res.warnings.map((w) => h("p", { class: "warning", "data-testid": "sky-warning" }, `⚠ ${w}`));
  const ts = rowTimestamp(row);
  // in the zone the sky map's day is drawn in: the site's, or UTC for typed coordinates
  // (their time was shown as raw ISO)
  const zone = trajectoryZone();
  const when = ts ? `  · ${fmtDateTime(zone, ts)} (${zone})` : "";
  return h("article", { class: "card sky-result", "data-testid": "sky-result", "data-sun-found": String(Boolean(res.sun_found)) },
    h("header", {}, h("h2", { title: row.file.name }, row.file.name)),
    canvas,
    h("div", { class: "legend" }, h("span", { class: "det" }, "✛ detected sun"), "  ",
      h("span", { class: "eph" }, res.camera === "pinhole" ? "┼ reference pixel (dashed)" : "○ ephemeris sun"), when),
    warnings,
    h("table", { class: "kv" }, rows));
}

function errorCard(row, message) {
  return h("article", { class: "card sky-result", "data-testid": "sky-result" },
    h("header", {}, h("h2", {}, row.file.name)), h("p", { class: "error" }, message));
}

async function detectAll(ev) {
  ev.preventDefault();
  if (!files.length) {
    $("sky-status").textContent = "Choose one or more images first.";
    return;
  }
  const out = $("sky-results");
  out.innerHTML = "";
  $("sky-detect").disabled = true;
  await namesRead;
  let done = 0;
  let failed = 0;
  let firstAnalysed = null;  // the day the map shows: of a frame the service took
  for (const row of files) {
    $("sky-status").textContent = `detecting ${++done} of ${files.length}…`;
    const form = new FormData();
    form.append("file", row.file, row.file.name);
    let params;
    try {
      params = await cameraParams(form);
    } catch (err) {
      out.append(errorCard(row, `Calibration unavailable: ${err.message}`));
      failed += 1;
      continue;
    }
    placeParams(form);
    const ts = rowTimestamp(row);
    if (ts) form.append("timestamp", ts);
    let res;
    try { // the server's answer first: its 413/415/422 says what is wrong with the file
      res = await api("/api/v1/vision/sun", { method: "POST", form, token: skyToken(true) });
    } catch (err) {
      out.append(errorCard(row, `Not analysed — ${err.message}`));
      failed += 1;
      continue;
    }
    let img = null;
    try {
      img = await readSize(row.url);
    } catch { /* analysed by the server, but this browser cannot draw it: the card says so */ }
    out.append(resultCard(row, img, res, params));
    firstAnalysed = firstAnalysed || res.timestamp || null;
  }
  const ok = files.length - failed;
  $("sky-status").textContent = failed
    ? `${ok} of ${files.length} image(s) analysed, ${failed} failed (see the red cards).`
    : `${ok} image(s) analysed.`;
  $("sky-detect").disabled = false;
  if (firstAnalysed) $("sky-day").value = localDate(trajectoryZone(), Date.parse(firstAnalysed));
  loadTrajectory();
}

async function calibrate() {
  await namesRead;
  const timed = files.filter((r) => rowTimestamp(r));
  if (timed.length < 3) {
    $("sky-status").textContent = "Calibration needs at least 3 images, each with its time.";
    return;
  }
  const form = new FormData();
  for (const r of timed) {
    form.append("files", r.file, r.file.name);
    form.append("timestamps", rowTimestamp(r));
  }
  placeParams(form);
  const projection = $("sky-calibration-projection").value; // "auto": the frames choose
  form.append("projection", projection);
  form.append("east", "auto"); // fit the mirror too
  const name = $("sky-calibration-name").value.trim();
  if (name) form.append("name", name);
  $("sky-calibrate").disabled = true;
  $("sky-status").textContent = projection === "auto"
    ? `fitting a camera to ${timed.length} frames (the projection they support)…`
    : `fitting ${/^[aeiou]/i.test(projection) ? "an" : "a"} ${projection} camera to ${timed.length} frames…`;
  const box = $("sky-calibration-result");
  box.innerHTML = "";
  try {
    const res = await api("/api/v1/vision/calibrations", { method: "POST", form, token: skyToken(true) });
    const fitted = res; // FittedCalibrationRead: the camera's fields at the top level too
    const show = [["calibration_id", "Calibration id", 0], ["projection", "Projection"], ["cx_px", "Centre x [px]", 1],
      ["cy_px", "Centre y [px]", 1], ["px_per_deg", "Scale [px/°]", 3], ["north_offset_deg", "North offset [°]", 2],
      ["east", "East"], ["n_frames", "Frames used", 0], ["rms_px", "Residual RMS [px]", 2], ["max_px", "Residual max [px]", 2],
      ["rms_deg", "Residual RMS, in-sample [°]", 3], ["n_outliers", "Outlier frames (left out)", 0],
      ["loo_rms_deg", "Each frame held out in turn, RMS [°]", 3],
      ["sky_uncertainty_deg", "Direction uncertainty over the sky, worst 1σ [°]", 2]];
    const rows = show.filter(([k]) => fitted[k] !== undefined && fitted[k] !== null)
      .map(([k, label, d]) => h("tr", {}, h("th", {}, label), h("td", {}, typeof fitted[k] === "number" ? num(fitted[k], d ?? 3) : String(fitted[k]))));
    if (fitted.model_selection?.length) { // each model's held-out RMS: why this one was kept
      const models = fitted.model_selection.map((m) => `${m.projection}${m.n_radial ? ` + ${m.n_radial} radial` : ""} ${num(m.loo_rms_deg, 3)}°`);
      rows.push(h("tr", {}, h("th", {}, "Models compared, each frame held out [°]"), h("td", {}, models.join(" · "))));
    }
    for (const k of ["projection", "px_per_deg", "cx_px", "cy_px", "north_offset_deg", "east"]) {
      const field = document.querySelector(`.cam-params[data-camera="fisheye"] [name="${k}"]`);
      if (field && fitted[k] !== undefined && fitted[k] !== null) {
        field.value = typeof fitted[k] === "number" ? String(Number(fitted[k].toFixed(4))) : fitted[k];
      }
    }
    const frames = res.frames.map((f) => h("tr", {},
      h("td", { title: f.filename }, f.filename), h("td", {}, f.sun_found ? "yes" : "no"), h("td", {}, f.used ? "yes" : (f.outlier ? "outlier" : "no")),
      h("td", {}, num(f.residual_px, 1)), h("td", {}, num(f.residual_deg, 2))));
    box.append(h("article", { class: "card", "data-testid": "calibration-result" },
      h("header", {}, h("h2", {}, `Fitted ${fitted.projection ?? ""} camera`)),
      ...(fitted.warnings ?? []).map((w) => h("p", { class: "warning", "data-testid": "calibration-warning" }, `⚠ ${w}`)),
      h("div", { class: "grid two-even" },
        h("table", { class: "kv" }, rows),
        frames.length ? h("table", { class: "kv frames" },
          h("tr", {}, h("th", {}, "Frame"), h("th", {}, "Sun"), h("th", {}, "Used"), h("th", {}, "Residual [px]"), h("th", {}, "[°]")),
          frames) : null)));
    if (res.calibration_id !== undefined) {
      const sel = $("sky-calibration");
      sel.add(new Option(`${calibrationLabel(res)} (just fitted)`, res.calibration_id));
      calibrationNames.set(String(res.calibration_id), res.name);
      sel.value = String(res.calibration_id);
      sel.dispatchEvent(new Event("change"));
    }
    $("sky-status").textContent = "Calibrated: detection now uses this calibration (see Calibration).";
  } catch (err) {
    box.append(h("article", { class: "card" }, h("p", { class: "error" }, `Calibration failed: ${err.message}`)));
    $("sky-status").textContent = "";
  } finally {
    $("sky-calibrate").disabled = false;
  }
}

/** The sky map's day runs midnight to midnight in the site's zone, or in UTC for a free place. */
function trajectoryZone() {
  return $("sky-place").value === "site" ? st.tz : "UTC";
}

/** Time-axis range around the detections, at least an hour wide (one frame gives no span). */
function paddedRange(isos, tz) {
  const ms = isos.map((t) => Date.parse(t));
  const lo = Math.min(...ms);
  const hi = Math.max(...ms);
  const pad = Math.max(30 * 60000, (hi - lo) * 0.05);
  return [toLocalWall(tz, lo - pad), toLocalWall(tz, hi + pad)];
}

async function loadTrajectory() {
  if (!st.site) return;
  const day = $("sky-day").value || st.day;
  const tz = trajectoryZone();
  const start = new Date(localMidnightMs(tz, day)).toISOString();
  const end = new Date(localMidnightMs(tz, addDays(day, 1))).toISOString();
  const params = { start, end };
  if ($("sky-place").value === "site") params.site_id = st.site.site_id;
  let list = [];
  try {
    list = (await api("/api/v1/vision/detections", { params })).detections;
    // a typed place shows the free places' detections: what its Clear deletes (without
    // a site_id the service lists every place's, and the sites' stayed drawn after Clear)
    if (!params.site_id) list = list.filter((d) => d.site_id === null);
  } catch (err) {
    showEmpty("chart-sky-track", `Detections unavailable: ${err.message}`);
    showEmpty("chart-sky-error", "");
    return;
  }
  const found = list.filter((d) => d.camera === "fisheye" && d.sun_found && typeof d.azimuth_deg === "number"
    && typeof d.timestamp === "string");
  if (!found.length) {
    showEmpty("chart-sky-track", "No fisheye detections stored for this day.");
    showEmpty("chart-sky-error", "Upload timestamped all-sky frames to see the error through the day.");
    return;
  }
  const ts = (d) => d.timestamp;
  const ephAz = (d) => d.ephemeris?.azimuth_deg ?? null; // StoredDetectionRead: with time and place
  const ephEl = (d) => d.ephemeris?.elevation_deg ?? null;
  const label = found.map((d) => toLocalWall(tz, ts(d)).slice(11, 16));
  await draw("chart-sky-track", [
    { type: "scatterpolar", r: found.map((d) => 90 - d.elevation_deg), theta: found.map((d) => d.azimuth_deg), text: label,
      mode: "markers", name: "detected", marker: { color: "#ff6b00", size: 8, symbol: "cross" }, hovertemplate: "%{text}: az %{theta:.1f}°, zenith %{r:.1f}°" },
    { type: "scatterpolar", r: found.map((d) => 90 - (ephEl(d) ?? NaN)), theta: found.map((d) => ephAz(d) ?? null), text: label,
      mode: "markers", name: "ephemeris (SPA)", marker: { color: COLORS.fixed, size: 9, symbol: "circle-open" }, hovertemplate: "%{text}: az %{theta:.1f}°, zenith %{r:.1f}°" },
  ], baseLayout({
    // room for the compass labels beside the circle and the legend above "N 0°" (a polar
    // chart grows no margin for them: at 390 px "W 270°" was cut and the legend lay over N)
    margin: { l: 52, r: 52, t: 64, b: 30 }, hovermode: "closest",
    legend: { orientation: "h", yref: "container", y: 1, yanchor: "top", x: 0 },
    polar: { radialaxis: { range: [0, 90], tickvals: [30, 60, 90], ticksuffix: "°", angle: 45, tickfont: { size: 10 } },
      angularaxis: { rotation: 90, direction: "clockwise", tickvals: [0, 90, 180, 270], ticktext: ["N 0°", "E 90°", "S 180°", "W 270°"] } },
  }), {
    columns: ["ts_utc", "local_time", "azimuth_deg", "elevation_deg", "ephemeris_azimuth_deg", "ephemeris_elevation_deg"],
    rows: found.map((d) => [ts(d), toLocalWall(tz, ts(d)), d.azimuth_deg, d.elevation_deg, ephAz(d), ephEl(d)]),
    filename: `sky_detections_${day}.csv`,
  });
  const errs = found.map((d) => d.error?.separation_deg ?? null); // the service's, on the sphere
  const groups = new Map(); // calibration → indices; doubtful ones (warnings) on their own
  found.forEach((d, i) => {
    const key = d.warnings.length ? "doubtful" : calibrationLegend(d.calibration_id);
    if (!groups.has(key)) groups.set(key, []);
    groups.get(key).push(i);
  });
  const palette = ["#ff6b00", "#1971c2", "#2f9e44", "#9c36b5", "#e8590c", "#0c8599"];
  const traces = [...groups].map(([key, idx], k) => ({
    x: idx.map((i) => toLocalWall(tz, ts(found[i]))), y: idx.map((i) => errs[i]), type: "scatter", mode: "markers",
    name: key === "doubtful" ? "doubtful (place or time?)" : key,
    text: idx.map((i) => found[i].warnings.join("; ")),
    marker: key === "doubtful" ? { color: "#868e96", size: 8, symbol: "x" } : { color: palette[k % palette.length], size: 7 },
    hovertemplate: "%{y:.2f}° %{text}" }));
  await draw("chart-sky-error", traces,
  baseLayout({ xaxis: { type: "date", title: { text: `Time (${tz})` }, gridcolor: "#e9edf1", range: paddedRange(found.map(ts), tz) },
    yaxis: { title: { text: "Detected − ephemeris [°]" }, rangemode: "tozero", gridcolor: "#e9edf1" },
    showlegend: true, legend: { orientation: "h", y: 1.12 } }));
}

const calibrationNames = new Map(); // calibration id → its name, for the charts' legends

function calibrationLabel(c) {
  const id = c.calibration_id;
  const when = c.created_at ? ` · ${fmtDateTime(st.tz, c.created_at)}` : "";
  return `#${id} ${c.name || c.projection || ""} · ${num(c.rms_px, 1)} px RMS${when}`;
}

function calibrationLegend(id) {
  if (id === null || id === undefined) return "typed parameters";
  const name = calibrationNames.get(String(id));
  return name ? `#${id} ${name}` : `#${id}`;
}

/** The token of a vision request: the "Write token" field's; empty, the header's stored
 *  token (HELIOTWIN_READ_REQUIRE_TOKEN) for a deletion, which needs one anyway, and for an
 *  upload only where the service requires one (HELIOTWIN_VISION_REQUIRE_TOKEN): an analysis
 *  without one stays anonymous, and the admin token, which vision refuses, is not sent. */
function skyToken(upload) {
  const own = $("sky-token").value.trim();
  if (own) return own;
  return !upload || st.meta?.vision_require_token ? storedToken() : "";
}

async function deleteCalibration() {
  const sel = $("sky-calibration");
  const id = sel.value;
  if (!id) return;
  if (!skyToken(false)) {
    $("sky-status").textContent = "Deleting needs a token: paste into “Write token” a site-scope token of the site "
      + "(heliotwin token create --site ID --scope site), any site's write token for a free place, or the admin token.";
    return;
  }
  if (!confirm(`Delete calibration ${calibrationLegend(id)} and the detections made with it?`)) return;
  try {
    const res = await api(`/api/v1/vision/calibrations/${encodeURIComponent(id)}`, { method: "DELETE", token: skyToken(false) });
    sel.remove(sel.selectedIndex);
    sel.value = "";
    sel.dispatchEvent(new Event("change"));
    $("sky-status").textContent = `Deleted calibration #${id} and ${res.detections_deleted} detection(s) made with it.`;
    loadTrajectory();
  } catch (err) {
    $("sky-status").textContent = `Could not delete: ${err.message}`;
  }
}

/** The selected calibration on the chosen frames against SPA; frames it was fitted on are marked. */
async function evaluateCalibration() {
  await namesRead;
  const id = $("sky-calibration").value;
  const timed = files.filter((r) => rowTimestamp(r));
  if (!id || !timed.length) {
    $("sky-status").textContent = "Choose a calibration and images with their times first.";
    return;
  }
  const box = $("sky-calibration-result");
  let cal;
  try {  // deleted meanwhile (another tab, the API): said, and the old evaluation cleared
    cal = await api(`/api/v1/vision/calibrations/${encodeURIComponent(id)}`);
  } catch (err) {
    box.innerHTML = "";
    $("sky-status").textContent = `Calibration #${id}: ${err.message}`;
    return;
  }
  const fittedOn = new Set(cal.frames.map((f) => f.filename));
  const form = new FormData();
  for (const r of timed) {
    form.append("files", r.file, r.file.name);
    form.append("timestamps", rowTimestamp(r));
  }
  form.append("calibration_id", id);
  form.append("methods", "robust");
  placeParams(form);
  $("sky-status").textContent = `evaluating ${calibrationLegend(id)} on ${timed.length} frames…`;
  box.innerHTML = "";
  try {
    const res = await api("/api/v1/vision/evaluate", { method: "POST", form, token: skyToken(true) });
    const rows = [];
    const held = [];
    for (const f of res.table2) {
      const az = f.robust_azimuth_deg;
      const el = f.robust_elevation_deg;
      let sep = null;
      if (typeof az === "number") {
        const c = Math.sin(el * DEG) * Math.sin(f.ephemeris_elevation_deg * DEG)
          + Math.cos(el * DEG) * Math.cos(f.ephemeris_elevation_deg * DEG) * Math.cos((az - f.ephemeris_azimuth_deg) * DEG);
        sep = Math.acos(Math.max(-1, Math.min(1, c))) / DEG;
      }
      const heldOut = !fittedOn.has(f.filename);
      if (heldOut && sep !== null) held.push(sep);
      rows.push(h("tr", {}, h("td", { title: f.filename }, f.filename), h("td", {}, heldOut ? "held out" : "fitted on"),
        h("td", {}, f.robust_sun_found ? "yes" : "no"), h("td", {}, num(sep, 2))));
    }
    const rms = held.length ? Math.sqrt(held.reduce((a, b) => a + b * b, 0) / held.length) : null;
    box.append(h("article", { class: "card", "data-testid": "calibration-evaluation" },
      h("header", {}, h("h2", {}, `${calibrationLegend(id)} on ${res.n_frames} frames`)),
      h("p", {}, held.length ? `Held-out frames: ${held.length}, error RMS ${num(rms, 2)}°, worst ${num(Math.max(...held), 2)}°.`
        : "Every frame here was used to fit this calibration: choose other frames for a held-out check."),
      h("table", { class: "kv frames" }, h("tr", {}, h("th", {}, "Frame"), h("th", {}, "Role"), h("th", {}, "Sun"), h("th", {}, "Error [°]")), rows)));
    $("sky-status").textContent = "";
  } catch (err) {
    box.append(h("article", { class: "card" }, h("p", { class: "error" }, `Evaluation failed: ${err.message}`)));
    $("sky-status").textContent = "";
  }
}

async function clearDetections() {
  if (!skyToken(false)) {
    $("sky-status").textContent = "Clearing needs a token: paste into “Write token” a site-scope token of the site "
      + "(heliotwin token create --site ID --scope site), any site's write token for a free place, or the admin token.";
    return;
  }
  const day = $("sky-day").value || st.day;
  const tz = trajectoryZone();
  const params = { start: new Date(localMidnightMs(tz, day)).toISOString(), end: new Date(localMidnightMs(tz, addDays(day, 1))).toISOString() };
  if ($("sky-place").value === "site") params.site_id = st.site.site_id;
  if ($("sky-clear-which").value === "uncalibrated") params.uncalibrated = "true";
  try {
    const res = await api("/api/v1/vision/detections", { method: "DELETE", params, token: skyToken(false) });
    $("sky-status").textContent = `Cleared ${res.detections_deleted} detection(s) of ${day}.`;
  } catch (err) {
    $("sky-status").textContent = `Could not clear: ${err.message}`;
  }
  loadTrajectory();
}

async function loadCalibrations() {
  try {
    const body = await api("/api/v1/vision/calibrations");
    const sel = $("sky-calibration");
    for (const c of body.calibrations) {
      sel.add(new Option(calibrationLabel(c), c.calibration_id));
      calibrationNames.set(String(c.calibration_id), c.name);
    }
  } catch (err) {
    // Listing is optional: a service without it still takes a calibration id typed by hand.
    if (err.status !== 404 && err.status !== 405) banner(`Calibrations unavailable: ${err.message}`);
  }
}

export function init(state) {
  st = state;
  $("sky-files").addEventListener("change", onFiles);
  // files chosen before this page was ready (its module starts after the site list has come)
  // raised no change it heard: "Detect the sun" then said to choose images already chosen
  if ($("sky-files").files.length) onFiles();
  $("sky-camera").addEventListener("change", () => {
    const cam = $("sky-camera").value;
    for (const box of document.querySelectorAll(".cam-params")) box.hidden = box.dataset.camera !== cam;
    $("sky-calibrate").disabled = cam !== "fisheye"; // calibration fits an all-sky camera
    $("sky-calibrate").title = cam === "fisheye" ? "Fit the fisheye camera from the timestamped images above"
      : "Calibration fits a fisheye (all-sky) camera";
  });
  $("sky-place").addEventListener("change", () => { $("sky-coords").hidden = $("sky-place").value !== "coords"; loadTrajectory(); });
  $("sky-calibration").addEventListener("change", () => {
    // a stored calibration is the camera: its parameters replace the ones typed here
    const stored = Boolean($("sky-calibration").value);
    $("sky-camera").disabled = stored;
    // its place is the one it was fitted at: after a reload the place went back to the
    // selected site, and its own frames read 108–110° off (a tester's finding)
    const place = $("sky-place");
    place.querySelector('option[value="calibration"]').disabled = !stored;
    if (stored) place.value = "calibration";
    else if (place.value === "calibration") place.value = "site";
    $("sky-coords").hidden = place.value !== "coords";
    for (const el of document.querySelectorAll(".cam-params input, .cam-params select")) el.disabled = stored;
  });
  $("sky-form").addEventListener("submit", detectAll);
  $("sky-calibrate").addEventListener("click", calibrate);
  // Enter in the calibration's name calibrates (it submitted the form: a detection run)
  $("sky-calibration-name").addEventListener("keydown", (ev) => {
    if (ev.key !== "Enter") return;
    ev.preventDefault();
    if (!$("sky-calibrate").disabled) calibrate();
  });
  if (st.meta?.vision_require_token) $("sky-token-why").textContent = "Write token (this service requires one for uploads and deletions)";
  $("sky-name-tz").addEventListener("change", refreshZones);
  $("sky-calibration").addEventListener("change", () => { $("sky-calibration-actions").hidden = !$("sky-calibration").value; });
  $("sky-calibration-delete").addEventListener("click", deleteCalibration);
  $("sky-evaluate").addEventListener("click", evaluateCalibration);
  $("sky-clear").addEventListener("click", clearDetections);
  $("sky-day").value = st.day;
  $("sky-day").addEventListener("change", loadTrajectory);
  loadCalibrations().finally(loadTrajectory); // the legends name the calibrations
}

export function siteChanged(state) {
  st = state;
  $("sky-day").value = st.day;
  loadTrajectory();
}

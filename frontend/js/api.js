// Thin wrappers over the heliotwin HTTP API (contracts: DESIGN.md, docs/architecture.md).

export class ApiError extends Error {
  constructor(status, message, body) {
    super(message);
    this.status = status;
    this.body = body;
  }
}

function detailText(body, fallback) {
  const d = body && body.detail;
  if (!d) return fallback;
  if (typeof d === "string") return d;
  if (Array.isArray(d)) {
    return d.map((e) => `${(e.loc || []).filter((x) => x !== "body").join(".")}: ${e.msg}`).join("; ");
  }
  return JSON.stringify(d);
}

/** GET/POST JSON; throws ApiError with the server's message on a non-2xx answer. */
export async function api(path, { method = "GET", params, json, form, signal, token } = {}) {
  let url = path;
  if (params) {
    const q = new URLSearchParams();
    for (const [k, v] of Object.entries(params)) if (v !== undefined && v !== null && v !== "") q.append(k, v);
    url += (url.includes("?") ? "&" : "?") + q.toString();
  }
  const init = { method, signal, headers: { Accept: "application/json" } };
  if (token) init.headers.Authorization = `Bearer ${token}`;
  if (json !== undefined) {
    init.body = JSON.stringify(json);
    init.headers["Content-Type"] = "application/json";
  } else if (form !== undefined) {
    init.body = form;
  }
  const res = await fetch(url, init);
  const text = await res.text();
  let body = null;
  try { body = text ? JSON.parse(text) : null; } catch { body = null; }
  if (!res.ok) {
    throw new ApiError(res.status, `${res.status} ${res.statusText}: ${detailText(body, text.slice(0, 200))}`, body);
  }
  return body;
}

export const getMeta = () => api("/api/v1/meta");
export const getSites = () => api("/api/v1/sites");
export const getStatus = (siteId, signal) => api(`/api/v1/sites/${encodeURIComponent(siteId)}/status`, { signal });

export function getMeasurements(siteId, { array, source, start, end, maxPoints }, signal) {
  return api(`/api/v1/sites/${encodeURIComponent(siteId)}/measurements`, {
    params: { array, source, start, end, max_points: maxPoints }, signal,
  });
}

export function getEnergy(siteId, { start, end, interval }, signal) {
  return api(`/api/v1/sites/${encodeURIComponent(siteId)}/energy`, { params: { start, end, interval }, signal });
}

/** Sites may come as a list or wrapped ({"sites": [...]}). */
export function siteList(body) {
  if (Array.isArray(body)) return body;
  if (body && Array.isArray(body.sites)) return body.sites;
  return [];
}

/** First defined value among dotted paths of an object (tolerates small shape differences). */
export function pick(obj, ...paths) {
  for (const path of paths) {
    let v = obj;
    for (const k of path.split(".")) {
      if (v === null || v === undefined) break;
      v = v[k];
    }
    if (v !== undefined && v !== null) return v;
  }
  return undefined;
}

/** Series in any of the shapes a table can travel in → list of row objects with `ts`. */
export function seriesRows(body) {
  if (!body) return [];
  const list = Array.isArray(body) ? body : body.points || body.rows || body.series;
  if (Array.isArray(list)) return list;
  const cols = (list && typeof list === "object" ? list : null) || body.columns || body.data || body;
  const ts = cols.ts || cols.index || cols.time;
  if (Array.isArray(ts)) {
    return ts.map((t, i) => {
      const row = { ts: t };
      for (const [k, v] of Object.entries(cols)) if (Array.isArray(v)) row[k] = v[i];
      return row;
    });
  }
  return [];
}

// Thin wrappers over the heliotwin HTTP API. The answers' shapes are the response models the
// OpenAPI declares (/docs; backend/api/schemas/): pages read those fields directly.

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

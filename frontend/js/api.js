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

// The dashboard's token: when the service requires one to read (HELIOTWIN_READ_REQUIRE_TOKEN,
// /api/v1/meta's read_require_token) the header's token field stores it here and every request
// that names no token of its own sends it. sessionStorage, not localStorage: a token may also
// write (a site-scope or the admin token), so it stays with this tab and is gone when the tab
// or the browser is closed — a shared control-room PC keeps no token; a reload keeps it.
const TOKEN_KEY = "heliotwin.token";

/** The stored token, or "" (no storage: a private window that refuses it). */
export function storedToken() {
  try { return sessionStorage.getItem(TOKEN_KEY) || ""; } catch { return ""; }
}

/** Store the dashboard's token ("" forgets it). */
export function storeToken(token) {
  try {
    if (token) sessionStorage.setItem(TOKEN_KEY, token);
    else sessionStorage.removeItem(TOKEN_KEY);
  } catch { /* not stored: the page asks again after a reload */ }
}

/** The Authorization header of the stored token (for a fetch outside api(): an image). */
export function authHeaders() {
  const t = storedToken();
  return t ? { Authorization: `Bearer ${t}` } : {};
}

/** The message of a request that got no answer at all (fetch's bare "Failed to fetch": the
 *  service stopped or restarting, or the network down), naming the address and what to do. */
export const NO_ANSWER_STATUS = 0;

async function send(url, init) {
  try {
    return await fetch(url, init);
  } catch (err) {
    if (err.name === "AbortError") throw err;
    throw new ApiError(NO_ANSWER_STATUS, `The service at ${location.host} did not answer (${url.split("?")[0]}): `
      + "it is stopped or restarting, or the network is down. Nothing is known of this data until it answers; "
      + "reload the page once it is back.", null);
  }
}

/** GET/POST JSON; throws ApiError with the server's message on a non-2xx answer, and with
 *  status 0 (NO_ANSWER_STATUS) and a message saying so when the service does not answer.
 *  `token`: the request's own token (a form's field; "" sends none); left out, the stored
 *  token is sent, and a 401 then dispatches "heliotwin:unauthorized" (main.js shows the
 *  header's token field with the server's message). */
export async function api(path, { method = "GET", params, json, form, signal, token } = {}) {
  let url = path;
  if (params) {
    const q = new URLSearchParams();
    for (const [k, v] of Object.entries(params)) if (v !== undefined && v !== null && v !== "") q.append(k, v);
    url += (url.includes("?") ? "&" : "?") + q.toString();
  }
  const init = { method, signal, headers: { Accept: "application/json" } };
  const bearer = token === undefined ? storedToken() : token;
  if (bearer) init.headers.Authorization = `Bearer ${bearer}`;
  if (json !== undefined) {
    init.body = JSON.stringify(json);
    init.headers["Content-Type"] = "application/json";
  } else if (form !== undefined) {
    init.body = form;
  }
  const res = await send(url, init);
  const text = await res.text();
  let body = null;
  try { body = text ? JSON.parse(text) : null; } catch { body = null; }
  if (!res.ok) {
    const detail = detailText(body, text.slice(0, 200));
    if (res.status === 401 && token === undefined) {
      window.dispatchEvent(new CustomEvent("heliotwin:unauthorized", { detail }));
    }
    throw new ApiError(res.status, `${res.status} ${res.statusText}: ${detail}`, body);
  }
  return body;
}

/** An image (or any file) of the API as an object URL, fetched with the stored token (an
 *  <img src> cannot send one); revoke it with URL.revokeObjectURL when replaced. */
export async function apiObjectUrl(path, signal) {
  const res = await send(path, { signal, headers: authHeaders() });
  if (!res.ok) {
    const text = await res.text();
    let body = null;
    try { body = JSON.parse(text); } catch { body = null; }
    const detail = detailText(body, text.slice(0, 200));
    if (res.status === 401) window.dispatchEvent(new CustomEvent("heliotwin:unauthorized", { detail }));
    throw new ApiError(res.status, `${res.status} ${res.statusText}: ${detail}`, body);
  }
  return URL.createObjectURL(await res.blob());
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

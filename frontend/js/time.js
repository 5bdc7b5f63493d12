// Times in the site's zone with Intl.DateTimeFormat; timestamps travel in UTC (ISO 8601).

const partsFormatters = new Map();
const offsetCache = new Map();
const HOUR_MS = 3600000;

function partsFormatter(tz) {
  let f = partsFormatters.get(tz);
  if (!f) {
    f = new Intl.DateTimeFormat("en-US", {
      timeZone: tz, hourCycle: "h23", year: "numeric", month: "2-digit", day: "2-digit",
      hour: "2-digit", minute: "2-digit", second: "2-digit",
    });
    partsFormatters.set(tz, f);
  }
  return f;
}

/** Offset of zone `tz` from UTC at instant `ms`, in milliseconds (cached per hour). */
export function zoneOffsetMs(tz, ms) {
  const key = `${tz}|${Math.floor(ms / HOUR_MS)}`;
  let off = offsetCache.get(key);
  if (off === undefined) {
    const p = {};
    for (const { type, value } of partsFormatter(tz).formatToParts(new Date(ms))) p[type] = value;
    const wall = Date.UTC(+p.year, +p.month - 1, +p.day, +p.hour, +p.minute, +p.second);
    off = Math.round((wall - Math.floor(ms / 1000) * 1000) / 60000) * 60000;
    offsetCache.set(key, off);
  }
  return off;
}

/** Wall-clock time in `tz` as "YYYY-MM-DD HH:MM:SS" (what Plotly plots as a local axis). */
export function toLocalWall(tz, isoOrMs) {
  const ms = typeof isoOrMs === "number" ? isoOrMs : Date.parse(isoOrMs);
  return new Date(ms + zoneOffsetMs(tz, ms)).toISOString().slice(0, 19).replace("T", " ");
}

/** The calendar date "YYYY-MM-DD" in `tz` at instant `ms` (default now). */
export function localDate(tz, ms = Date.now()) {
  return toLocalWall(tz, ms).slice(0, 10);
}

/** Add `n` days to a "YYYY-MM-DD" date (calendar arithmetic, no zone involved). */
export function addDays(date, n) {
  const [y, m, d] = date.split("-").map(Number);
  return new Date(Date.UTC(y, m - 1, d + n)).toISOString().slice(0, 10);
}

/** UTC instant (ms) of the wall-clock time "YYYY-MM-DDTHH:MM[:SS]" in `tz`: the offset
 * taken at the instant itself, not at the wall time read as UTC (one pass put a frame an
 * hour off when a DST change lay between the two). */
export function localWallMs(tz, wall) {
  const guess = Date.parse(`${wall.length === 16 ? `${wall}:00` : wall}Z`);
  let ms = guess - zoneOffsetMs(tz, guess);
  ms = guess - zoneOffsetMs(tz, ms); // second pass settles DST edges
  return ms;
}

/** UTC instant (ms) of local midnight starting `date` in `tz`. */
export function localMidnightMs(tz, date) {
  return localWallMs(tz, `${date}T00:00:00`);
}

const displayFormatters = new Map();
function displayFormatter(tz, kind) {
  const key = `${tz}|${kind}`;
  let f = displayFormatters.get(key);
  if (!f) {
    const opts = kind === "time"
      ? { hour: "2-digit", minute: "2-digit", hourCycle: "h23" }
      : kind === "date"
        ? { weekday: "short", year: "numeric", month: "short", day: "numeric" }
        : { year: "numeric", month: "short", day: "numeric", hour: "2-digit", minute: "2-digit", hourCycle: "h23" };
    f = new Intl.DateTimeFormat(undefined, { timeZone: tz, ...opts });
    displayFormatters.set(key, f);
  }
  return f;
}

/** "14:05" in `tz`. */
export function fmtTime(tz, iso) {
  return iso ? displayFormatter(tz, "time").format(new Date(iso)) : "—";
}

/** "22 Nov 2026, 14:05" in `tz`. */
export function fmtDateTime(tz, iso) {
  return iso ? displayFormatter(tz, "datetime").format(new Date(iso)) : "—";
}

/** "Sun, 22 Nov 2026" for a "YYYY-MM-DD" calendar date. */
export function fmtDate(date) {
  return displayFormatter("UTC", "date").format(new Date(`${date}T12:00:00Z`));
}

/** Short zone name with today's offset, e.g. "Europe/Madrid (UTC+01:00 now)": "now", as a
 *  day shown in summer is at +02:00 there (a researcher read the winter offset over a June
 *  day); each chart's time axis names the zone. */
export function zoneLabel(tz) {
  const off = zoneOffsetMs(tz, Date.now()) / 60000;
  const sign = off < 0 ? "−" : "+";
  const a = Math.abs(off);
  const hh = String(Math.floor(a / 60)).padStart(2, "0");
  const mm = String(a % 60).padStart(2, "0");
  return `${tz} (UTC${sign}${hh}:${mm} now)`;
}

/** "3 min ago" style age of an ISO instant. */
export function fmtAge(iso, nowMs = Date.now()) {
  if (!iso) return "never";
  const s = Math.max(0, (nowMs - Date.parse(iso)) / 1000);
  if (s < 90) return `${Math.round(s)} s ago`;
  if (s < 5400) return `${Math.round(s / 60)} min ago`;
  if (s < 172800) return `${(s / 3600).toFixed(1)} h ago`;
  return `${Math.round(s / 86400)} days ago`;
}

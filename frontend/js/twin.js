// 3D twin: the viser scene (served by the backend on its own port) in an iframe.

let loaded = false;

function twinUrl(state) {
  const port = state.meta?.viser_port || 8080;
  return `${location.protocol}//${location.hostname}:${port}/`;
}

function explain(message) {
  const wrap = document.querySelector(".twin-frame-wrap");
  wrap.innerHTML = "";
  const p = document.createElement("p");
  p.className = "muted";
  p.style.padding = "24px";
  p.textContent = message;
  wrap.append(p);
}

export async function init(state) {
  loaded = true;
  const url = twinUrl(state);
  const link = document.getElementById("twin-open");
  link.href = url;
  if (state.meta?.viser_enabled === false) {
    link.hidden = true;
    explain("The 3D twin is switched off on this service (HELIOTWIN_VISER=false).");
    return;
  }
  try {
    await fetch(url, { mode: "no-cors", cache: "no-store" }); // is viser listening?
  } catch {
    explain(`The 3D twin does not answer at ${url}: is the service's viser scene running?`);
    return;
  }
  // Loaded only when the page is first opened: the WebGL scene costs CPU.
  document.getElementById("twin-frame").src = url;
}

export function show(state) {
  if (!loaded) init(state);
}

// stereocam viewer page: polls for the newest frame (never a backlog), shows the camera's real
// configuration (a refused value snaps back, with the reason), counters with rates, the depth
// histogram, the 3-D view and the state of planes and triggers.
"use strict";
const $ = (id) => document.getElementById(id);
const PLANES = ["left", "right", "disparity"];
let lastSeq = -1;
let current = null; // the newest frame's metadata
let state = null; // the newest /api/state
const seenIn = {}; // plane -> the last frame that carried it

async function api(path, body) {
  if (body !== undefined) { // a change: in order with every other (settings.js postInOrder)
    const {r, doc} = await postInOrder(path, body);
    return {ok: r.ok, status: r.status, doc};
  }
  const r = await fetch(path);
  return {ok: r.ok, status: r.status, doc: await r.json()};
}

function loadImage(img, src) {
  return new Promise((resolve) => { img.onload = img.onerror = resolve; img.src = src; });
}

async function frames() {
  // One request at a time: ask for the frame after the one shown, then load its images.
  for (;;) {
    try {
      const {doc} = await api(`/api/frame?after=${lastSeq}`);
      if (doc && doc.sequence !== lastSeq) {
        current = doc;
        lastSeq = doc.sequence;
        $("sequence").textContent = doc.sequence;
        const loads = PLANES.filter((p) => doc.planes.includes(p))
          .map((p) => { seenIn[p] = doc.sequence; return loadImage($(p), `/image/${p}.jpg?seq=${doc.sequence}`); });
        drawColorbar(doc.colorbar);
        drawHistogram(doc.histogram);
        markPlanes();
        if (doc.planes.includes("disparity")) loads.push(cloud.load(doc.sequence));
        await Promise.all(loads);
      }
    } catch (e) {
      $("error").textContent = `viewer: ${e}`;
      await new Promise((r) => setTimeout(r, 500));
    }
  }
}

function markPlanes() {
  // A plane the newest frame lacks keeps its last image, dimmed and marked: off (the configuration
  // does not ask for it), missing (asked for but not in the frame) or stale (the camera failed).
  const expected = state ? state.expected_planes : PLANES;
  for (const p of [...PLANES, "cloud"]) {
    const plane = p === "cloud" ? "disparity" : p;
    const fig = $(`fig-${p}`);
    const inFrame = current && current.planes.includes(plane);
    let mark = "", cls = "";
    if (current && current.stale) { mark = `stale: camera lost, frame ${current.sequence}`; cls = "stale"; }
    else if (!inFrame && !expected.includes(plane)) {
      mark = `off (outputs=${state.config.outputs}, rectify=${state.config.rectify})` +
        (seenIn[plane] !== undefined ? `, last seen in frame ${seenIn[plane]}` : "");
      cls = seenIn[plane] !== undefined ? "absent" : "off";
    } else if (current && !inFrame) {
      mark = `missing from frame ${current.sequence}` +
        (seenIn[plane] !== undefined ? `, last seen in frame ${seenIn[plane]}` : "");
      cls = seenIn[plane] !== undefined ? "absent" : "off";
    } else if (!current) { mark = "no frame yet"; cls = "off"; }
    fig.classList.remove("absent", "stale", "off");
    if (cls) fig.classList.add(cls);
    $(`badge-${p}`).textContent = mark;
  }
}

function drawColorbar(bar) {
  $("colorbar").style.display = bar ? "flex" : "none";
  if (!bar) return;
  $("gradient").style.background = `linear-gradient(to bottom, ${bar.near_to_far.join(", ")})`;
  $("ticks").innerHTML = bar.ticks.map((t) =>
    `<span style="top:${(100 * t.at).toFixed(1)}%">${t.metres} m</span>`).join("");
}

function drawHistogram(h) {
  const c = $("histogram"), g = c.getContext("2d");
  g.clearRect(0, 0, c.width, c.height);
  if (!h) { $("hist-note").textContent = "no disparity in this frame"; return; }
  const max = Math.max(1, ...h.counts), n = h.counts.length, w = c.width / n;
  const stops = current && current.colorbar ? current.colorbar.near_to_far : ["#8cf"];
  h.counts.forEach((v, i) => {
    g.fillStyle = stops[Math.min(stops.length - 1, Math.floor(i * stops.length / n))];
    const bh = (c.height - 16) * v / max;
    g.fillRect(i * w, c.height - 14 - bh, w - 1, bh);
  });
  g.fillStyle = "#aaa"; g.font = "11px system-ui";
  g.fillText(`${h.near_m} m`, 2, c.height - 2);
  g.fillText(`${h.far_m} m`, c.width - 60, c.height - 2);
  $("hist-note").textContent = `${h.nearer} nearer, ${h.farther} farther, ${h.invalid} without depth`;
  if (!rangeEdited && document.activeElement !== $("near") && document.activeElement !== $("far")) {
    $("near").value = h.near_m; $("far").value = h.far_m;
  }
}

// -- counters as a table with rates -----------------------------------------------------------
let lastCounters = null;
function showCounters(doc) {
  const h = doc.host;
  const rows = [["frames", h.frames], ["dropped", h.frames_dropped], ["lost", h.lost],
    ["queue overflow", h.queue_overflow], ["viewer skipped", doc.viewer_skipped],
    ["CRC errors", h.header_crc_errors + h.payload_crc_errors], ["retries", h.retries], ["timeouts", h.timeouts],
    ...Object.entries(doc.device).map(([k, v]) => [`device ${k.replaceAll("_", " ")}`, v])];
  const now = performance.now();
  const body = $("counters").tBodies[0];
  body.innerHTML = "";
  for (const [name, v] of rows) {
    const prev = lastCounters ? lastCounters.values[name] : undefined;
    const rate = prev === undefined ? "" : ((v - prev) * 1000 / (now - lastCounters.t)).toFixed(1);
    const tr = body.insertRow();
    tr.dataset.name = name;
    if (/dropped|lost|overflow|CRC|timeouts|errors/.test(name) && v > 0) tr.className = "bad";
    for (const cell of [name, v, rate]) tr.insertCell().textContent = cell;
  }
  lastCounters = {t: now, values: Object.fromEntries(rows)};
}

async function refreshState() {
  const acts = recordActs;
  try {
    const {doc} = await api("/api/state");
    state = doc;
    $("identity").textContent = `${doc.model} ${doc.serial} firmware ${doc.firmware} at ${doc.url}`;
    $("fps").textContent = doc.fps.toFixed(1);
    $("streaming").textContent = doc.streaming ? "yes" : "no";
    $("waiting").textContent = doc.waiting || "";
    $("error").textContent = doc.error || "";
    showCounters(doc);
    // a saved file's line stays; a state asked for before a Record/Stop click was answered may
    // predate it (requests are served in parallel) and must not undo what the click showed
    if (acts === recordActs && (doc.recording || recording)) showRecording(doc.recording);
    Settings.build(doc);
    showPresets(doc.presets);
    markPlanes();
  } catch (e) {
    $("error").textContent = `viewer: ${e}`;
  }
}

let recording = null;
let recordActs = 0; // changes when a Record/Stop click is sent and when its answer comes
function showRecording(rec) {
  recording = rec && !rec.done ? rec : null;
  $("record").textContent = recording ? "Stop recording" : "Record";
  $("recording").textContent = rec
    ? `${rec.done ? "saved" : "recording"} ${rec.path}: ${rec.frames} frames, ${rec.megabytes} MB, ` +
      `${rec.recorder_dropped} dropped by the recorder`
    : "";
}

$("record").addEventListener("click", async () => {
  recordActs++;
  const {ok, doc} = await api(recording ? "/api/record/stop" : "/api/record/start", {});
  recordActs++;
  if (ok) showRecording(doc.recording);
  else $("action").innerHTML = `<span class="error">recording refused: ${escape(doc.reason || doc.error)}</span>`;
});

function escape(text) {
  return String(text).replace(/[&<>"]/g, (c) => ({"&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;"})[c]);
}

// -- defaults and presets ---------------------------------------------------------------------
function showPresets(names) {
  const list = $("preset-list");
  const have = [...list.options].map((o) => o.value).join("\n");
  if (have === names.join("\n")) return;
  list.innerHTML = names.map((n) => `<option value="${escape(n)}">${escape(n)}</option>`).join("");
}

async function configAction(path, body, what) {
  const {ok, doc} = await api(path, body);
  $("preset-note").className = ok ? "ok" : "error";
  $("preset-note").textContent = ok ? what : `${what} refused: ${doc.reason || doc.error}`;
  await refreshState();
}
$("reset").addEventListener("click", () => configAction("/api/config/reset", {}, "every setting at its default"));
$("preset-save").addEventListener("click", () =>
  configAction("/api/preset/save", {name: $("preset-name").value.trim()}, `saved preset ${$("preset-name").value.trim()}`));
$("preset-load").addEventListener("click", () =>
  configAction("/api/preset/load", {name: $("preset-list").value}, `loaded preset ${$("preset-list").value}`));

// -- near/far range ---------------------------------------------------------------------------
// A value the user typed stays until Apply or "Searched range", even after its field loses focus
// (typing near, then far: the refresh must not put near back before Apply).
let rangeEdited = false;
["near", "far"].forEach(id => $(id).addEventListener("input", () => { rangeEdited = true; }));
async function setRange(body) {
  rangeEdited = false;
  const {ok, doc} = await api("/api/range", body);
  $("range-reason").textContent = ok ? "" : doc.reason || doc.error;
  lastSeq = -1; // the same frame again, coloured anew
}
$("range-apply").addEventListener("click", () => setRange({near_m: Number($("near").value), far_m: Number($("far").value)}));
$("range-auto").addEventListener("click", () => setRange({near_m: null, far_m: null}));

// -- the point under the cursor -----------------------------------------------------------------
async function showPoint(ev) {
  if (!current) return;
  const img = ev.target;
  const x = Math.floor(ev.offsetX * current.width / img.clientWidth);
  const y = Math.floor(ev.offsetY * current.height / img.clientHeight);
  const {doc} = await api(`/api/point?x=${x}&y=${y}`);
  $("cursor").textContent = doc.valid
    ? `(${x}, ${y}): d ${doc.disparity_px.toFixed(2)} px, depth ${doc.depth_m.toFixed(3)} m, ` +
      `X ${doc.point_m[0].toFixed(3)} Y ${doc.point_m[1].toFixed(3)} Z ${doc.point_m[2].toFixed(3)} m`
    : `(${x}, ${y}): no depth here`;
}

let pointTimer = null;
for (const id of PLANES) {
  $(id).addEventListener("mousemove", (ev) => {
    clearTimeout(pointTimer);
    pointTimer = setTimeout(() => showPoint(ev), 30);
  });
}
// An action's answer (a refused trigger's reason) stays until the next action.
for (const action of ["start", "stop", "trigger"]) {
  $(action).addEventListener("click", async () => {
    const {ok, doc} = await api(`/api/${action}`, {});
    $("action").innerHTML = ok ? `<span class="ok">${action}: done</span>`
      : `<span class="error">${action} refused: ${escape(doc.reason || doc.error)}</span>`;
    refreshState();
  });
}
Settings.changed = refreshState;
const cloud = new Cloud3D($("cloud"), () => $("cloud-colour").value);
$("cloud-colour").addEventListener("change", () => cloud.load(lastSeq));
refreshState();
setInterval(refreshState, 1000);
frames();

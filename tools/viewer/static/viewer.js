// stereocam viewer page: polls for the newest frame (never a backlog), edits the configuration.
"use strict";
const $ = (id) => document.getElementById(id);
let lastSeq = -1;
let current = null; // the newest frame's metadata

async function api(path, body) {
  const init = body === undefined ? {} : {method: "POST", body: JSON.stringify(body),
                                           headers: {"Content-Type": "application/json"}};
  const r = await fetch(path, init);
  return {ok: r.ok, doc: await r.json()};
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
        const loads = ["left", "right", "disparity"].filter((p) => doc.planes.includes(p))
          .map((p) => loadImage($(p), `/image/${p}.jpg?seq=${doc.sequence}`));
        drawColorbar(doc.colorbar);
        await Promise.all(loads);
      }
    } catch (e) {
      $("error").textContent = `viewer: ${e}`;
      await new Promise((r) => setTimeout(r, 500));
    }
  }
}

function drawColorbar(bar) {
  $("colorbar").style.display = bar ? "flex" : "none";
  if (!bar) return;
  $("gradient").style.background = `linear-gradient(to bottom, ${bar.near_to_far.join(", ")})`;
  $("ticks").innerHTML = bar.ticks.map((t) =>
    `<span style="top:${(100 * t.at).toFixed(1)}%">${t.metres} m</span>`).join("");
}

async function refreshState() {
  try {
    const {doc} = await api("/api/state");
    $("identity").textContent = `${doc.model} ${doc.serial} firmware ${doc.firmware} at ${doc.url}`;
    $("fps").textContent = doc.fps.toFixed(1);
    $("streaming").textContent = doc.streaming ? "yes" : "no";
    $("error").textContent = doc.error || "";
    const h = doc.host;
    $("counters").textContent =
      `host: frames ${h.frames} dropped ${h.frames_dropped} lost ${h.lost} queue_overflow ${h.queue_overflow} ` +
      `viewer_skipped ${doc.viewer_skipped} crc ${h.header_crc_errors + h.payload_crc_errors} ` +
      `retries ${h.retries} timeouts ${h.timeouts}\n` +
      `device: ${Object.entries(doc.device).map(([k, v]) => `${k} ${v}`).join(" ")}`;
    if (doc.recording || recording) showRecording(doc.recording); // a saved file's line stays
    buildConfig(doc);
  } catch (e) {
    $("error").textContent = `viewer: ${e}`;
  }
}

let recording = null;
function showRecording(rec) {
  recording = rec && !rec.done ? rec : null;
  $("record").textContent = recording ? "Stop recording" : "Record";
  $("recording").textContent = rec
    ? `${rec.done ? "saved" : "recording"} ${rec.path}: ${rec.frames} frames, ${rec.megabytes} MB, ` +
      `${rec.recorder_dropped} dropped by the recorder`
    : "";
}

$("record").addEventListener("click", async () => {
  const {ok, doc} = await api(recording ? "/api/record/stop" : "/api/record/start", {});
  if (ok) showRecording(doc.recording);
  else $("error").textContent = `recording refused: ${doc.reason || doc.error}`;
});

function buildConfig(doc) {
  const form = $("config");
  for (const p of doc.options) {
    let row = document.getElementById(`param-${p.name}`);
    if (!row) {
      row = document.createElement("div");
      row.className = "param";
      row.id = `param-${p.name}`;
      row.title = p.description;
      const step = p.odd ? 2 : p.step;
      row.innerHTML = `<label for="in-${p.name}">${p.name}</label>` +
        `<input id="in-${p.name}" name="${p.name}" type="number" min="${p.lo}" max="${p.hi}" step="${step}">` +
        `<span class="range">${p.lo}…${p.hi}${p.unit ? " " + p.unit : ""}${p.odd ? ", odd" : ""}` +
        `${p.live ? "" : ", stopped only"} (default ${p.default})</span><span class="reason"></span>`;
      row.querySelector("input").addEventListener("change", (ev) => setParam(p.name, ev.target));
      form.appendChild(row);
    }
    const input = row.querySelector("input");
    if (document.activeElement !== input && !row.dataset.refused) input.value = p.value;
  }
}

async function setParam(name, input) {
  const row = $(`param-${name}`);
  const reason = row.querySelector(".reason");
  const {ok, doc} = await api("/api/config", {[name]: Number(input.value)});
  if (ok) {
    delete row.dataset.refused;
    reason.className = "reason ok";
    reason.textContent = `set to ${doc.config[name]}`;
  } else {
    row.dataset.refused = "1";
    reason.className = "reason error";
    reason.textContent = `refused: ${doc.reason || doc.error}`;
  }
}

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
for (const id of ["left", "right", "disparity"]) {
  $(id).addEventListener("mousemove", (ev) => {
    clearTimeout(pointTimer);
    pointTimer = setTimeout(() => showPoint(ev), 30);
  });
}
for (const action of ["start", "stop", "trigger"]) {
  $(action).addEventListener("click", async () => {
    const {ok, doc} = await api(`/api/${action}`, {});
    $("error").textContent = ok ? "" : `${action} refused: ${doc.reason || doc.error}`;
    refreshState();
  });
}
refreshState();
setInterval(refreshState, 1000);
frames();

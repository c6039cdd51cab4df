// stereocam viewer for a camera group: the newest matched set (one frame per head per trigger),
// each head's last frame with its age (marked when the head missed the newest set), the colour
// bar, the capture-time spread, each head's clock-map error, the sets a head missed; start, stop,
// one set on demand and settings for every head.
"use strict";
const $ = (id) => document.getElementById(id);
let lastTrigger = -1;
Settings.path = "/api/group/config";

async function get(path) {
  const r = await fetch(path);
  return r.json();
}

function headFigure(name, plane) {
  const id = `${name}-${plane}`;
  let fig = document.getElementById(`fig-${id}`);
  if (!fig) {
    fig = document.createElement("figure");
    fig.id = `fig-${id}`;
    fig.dataset.camera = name;
    fig.innerHTML = `<figcaption><b>${name}</b> ${plane} <span class="offset"></span> <span class="badge"></span>` +
      `</figcaption><img class="head" data-camera="${name}" data-plane="${plane}" alt="${name} ${plane}">`;
    $("heads").appendChild(fig);
  }
  return fig;
}

function loadImage(img, src) {
  return new Promise((resolve) => { img.onload = img.onerror = resolve; img.src = src; });
}

function drawColorbar(bar) {
  $("colorbar").style.display = bar ? "flex" : "none";
  if (!bar) return;
  $("gradient").style.background = `linear-gradient(to bottom, ${bar.near_to_far.join(", ")})`;
  $("ticks").innerHTML = bar.ticks.map((t) =>
    `<span style="top:${(100 * t.at).toFixed(1)}%">${t.metres} m</span>`).join("");
}

async function sets() {
  for (;;) {
    try {
      const s = await get(`/api/group/set?after=${lastTrigger}`);
      if (s && s.trigger_id !== lastTrigger) {
        lastTrigger = s.trigger_id;
        $("trigger-id").textContent = s.trigger_id;
        $("skew").textContent = s.skew_us.toFixed(1);
        drawColorbar(s.colorbar);
        const loads = [];
        for (const [name, h] of Object.entries(s.heads)) { // every head: its last frame, kept if it missed
          for (const plane of h.planes) {
            const fig = headFigure(name, plane);
            fig.classList.toggle("missed", h.missed);
            fig.querySelector(".offset").textContent = h.missed ? `frame ${h.sequence} of trigger ${h.trigger_id}`
              : `frame ${h.sequence}, +${s.frames[name].offset_us.toFixed(1)} µs`;
            fig.querySelector(".badge").textContent = h.missed
              ? `missed trigger ${s.trigger_id}: last frame ${h.age_s.toFixed(1)} s old` : "";
            if (fig.dataset.trigger !== String(h.trigger_id)) {
              fig.dataset.trigger = h.trigger_id;
              loads.push(loadImage(fig.querySelector("img"), `/image/${name}/${plane}.jpg?t=${h.trigger_id}`));
            }
          }
        }
        await Promise.all(loads);
      }
    } catch (e) {
      $("error").textContent = `viewer: ${e}`;
      await new Promise((r) => setTimeout(r, 500));
    }
  }
}

async function refreshState() {
  try {
    const st = await get("/api/group/state");
    $("identity").textContent = st.cameras.map((c) => `${c.name} (${c.model} at ${c.url}, clock map ±${c.clock_sigma_us} µs)`)
      .join(", ");
    $("complete").textContent = st.sets.complete;
    $("incomplete").textContent = st.sets.incomplete;
    $("streaming").textContent = st.cameras.every((c) => c.streaming) ? "yes"
      : st.cameras.some((c) => c.streaming) ? "some heads" : "no";
    $("error").textContent = st.error || "";
    $("missed").textContent = st.missed.length
      ? "missed: " + st.missed.map((m) => `trigger ${m.trigger_id} from ${m.missing.join(", ")}`).join("; ")
      : "no set has missed a head";
    Settings.build(st);
  } catch (e) {
    $("error").textContent = `viewer: ${e}`;
  }
}

// An action's answer (a refusal's reason) stays until the next action.
for (const action of ["start", "stop", "trigger"]) {
  $(action).addEventListener("click", async () => {
    const {r, doc} = await postInOrder(`/api/group/${action}`, {});
    $("action").className = r.ok ? "ok" : "error";
    $("action").textContent = r.ok ? (action === "trigger" ? `one set: trigger ${doc.trigger_id}` : `${action}: done`)
      : `${action} refused: ${doc.reason || doc.error}`;
    refreshState();
  });
}
refreshState();
setInterval(refreshState, 1000);
sets();

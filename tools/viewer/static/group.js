// stereocam viewer for a camera group: the newest matched set (one frame per head per trigger),
// its capture-time spread, each head's clock-map error, and the sets a head missed.
"use strict";
const $ = (id) => document.getElementById(id);
let lastTrigger = -1;

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
    fig.innerHTML = `<figcaption><b>${name}</b> ${plane} <span class="offset"></span></figcaption>` +
      `<img class="head" data-camera="${name}" data-plane="${plane}" alt="${name} ${plane}">`;
    $("heads").appendChild(fig);
  }
  return fig;
}

function loadImage(img, src) {
  return new Promise((resolve) => { img.onload = img.onerror = resolve; img.src = src; });
}

async function sets() {
  for (;;) {
    try {
      const s = await get(`/api/group/set?after=${lastTrigger}`);
      if (s && s.trigger_id !== lastTrigger) {
        lastTrigger = s.trigger_id;
        $("trigger").textContent = s.trigger_id;
        $("skew").textContent = s.skew_us.toFixed(1);
        const loads = [];
        for (const [name, f] of Object.entries(s.frames)) {
          for (const plane of f.planes) {
            const fig = headFigure(name, plane);
            fig.querySelector(".offset").textContent = `frame ${f.sequence}, +${f.offset_us.toFixed(1)} µs`;
            loads.push(loadImage(fig.querySelector("img"), `/image/${name}/${plane}.jpg?t=${s.trigger_id}`));
          }
        }
        for (const name of s.missing) {
          headFigure(name, "left").querySelector(".offset").textContent = `missed trigger ${s.trigger_id}`;
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
    $("error").textContent = st.error || "";
    $("counters").textContent = st.missed.length
      ? "missed: " + st.missed.map((m) => `trigger ${m.trigger_id} from ${m.missing.join(", ")}`).join("; ")
      : "no set has missed a head";
  } catch (e) {
    $("error").textContent = `viewer: ${e}`;
  }
}
refreshState();
setInterval(refreshState, 1000);
sets();

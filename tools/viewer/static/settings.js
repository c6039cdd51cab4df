// The settings form both viewer pages share: settings in their groups, named choices as menus,
// outputs as planes to tick, units as people write them; it always shows the camera's values
// (a refused value snaps back, its reason stays beside it until that setting changes again).
"use strict";

// Every change a page asks of the camera goes out in the order the user made it, one at a time: the
// server answers requests on threads of their own, so a value typed just before "Reset to defaults"
// could otherwise be applied after the reset.
let postsDone = Promise.resolve();
function postInOrder(path, body) {
  const send = async () => {
    const r = await fetch(path, {method: "POST", body: JSON.stringify(body), headers: {"Content-Type": "application/json"}});
    return {r, doc: await r.json()};
  };
  const answer = postsDone.then(send, send);
  postsDone = answer.catch(() => {});
  return answer;
}

const Settings = {
  path: "/api/config", // where a change is posted (a group page: every head)
  config: {}, // the configuration as last answered
  changed: () => {}, // called after each answer (the page refreshes what depends on the configuration)

  rangeText(p) {
    const differs = p.value === null ? "heads differ; " : "";
    if (p.choices) return differs + (p.live ? "" : "stopped only");
    return `${differs}${p.lo}…${p.hi}${p.unit ? " " + p.unit : ""}${p.odd ? ", odd" : ""}` +
      `${p.step > 1 ? `, step ${p.step}` : ""}${p.live ? "" : ", stopped only"}`;
  },

  control(p) {
    if (p.choices && p.choices.kind === "menu") {
      return `<select id="in-${p.name}" name="${p.name}">` + Object.entries(p.choices.values)
        .map(([v, name]) => `<option value="${v}">${name}${Number(v) === p.default ? " (default)" : ""}</option>`)
        .join("") + "</select>";
    }
    if (p.choices && p.choices.kind === "flags") {
      return `<span class="flags" id="in-${p.name}">` + Object.entries(p.choices.values)
        .map(([bit, name]) => `<label><input type="checkbox" value="${bit}">${name}</label>`).join("") + "</span>";
    }
    const step = p.odd ? 2 : p.step;
    return `<input id="in-${p.name}" name="${p.name}" type="number" min="${p.lo}" max="${p.hi}" step="${step}" ` +
      `placeholder="${p.default}">`;
  },

  read(p, el) {
    if (p.choices && p.choices.kind === "flags") {
      return [...el.querySelectorAll("input")].reduce((acc, i) => acc | (i.checked ? Number(i.value) : 0), 0);
    }
    return el.value.trim() === "" ? null : Number(el.value);
  },

  show(p, el, value) {
    if (p.choices && p.choices.kind === "flags") {
      for (const i of el.querySelectorAll("input")) i.checked = value !== null && (value & Number(i.value)) !== 0;
    } else {
      el.value = value === null || value === undefined ? "" : value;
    }
  },

  build(doc) {
    const form = document.getElementById("config");
    this.config = Object.fromEntries(doc.options.map((p) => [p.name, p.value]));
    for (const p of doc.options) {
      let row = document.getElementById(`param-${p.name}`);
      if (!row) {
        let group = document.getElementById(`group-${p.group}`);
        if (!group) {
          group = document.createElement("fieldset");
          group.id = `group-${p.group}`;
          group.innerHTML = `<legend>${p.group}</legend>`;
          const order = doc.groups.indexOf(p.group);
          const after = [...form.children].find((f) => doc.groups.indexOf(f.id.slice(6)) > order);
          form.insertBefore(group, after || null);
        }
        row = document.createElement("div");
        row.className = "param";
        row.id = `param-${p.name}`;
        row.title = `${p.description} (default ${p.default})`;
        row.innerHTML = `<label for="in-${p.name}">${p.name.replaceAll("_", " ")}</label>${this.control(p)}` +
          `<span class="range"></span><span class="reason"></span>`;
        const el = row.querySelector(`#in-${p.name}`);
        el.addEventListener("change", () => this.set(p, el));
        el.addEventListener("keydown", (ev) => { if (ev.key === "Enter") { ev.preventDefault(); this.set(p, el); } });
        group.appendChild(row);
      }
      row.querySelector(".range").textContent = this.rangeText(p);
      const el = row.querySelector(`#in-${p.name}`);
      if (document.activeElement !== el || row.dataset.sent) this.show(p, el, p.value);
    }
  },

  async set(p, el) {
    const row = document.getElementById(`param-${p.name}`);
    const reason = row.querySelector(".reason");
    const value = this.read(p, el);
    if (value === null) {
      reason.className = "reason error";
      reason.textContent = `not sent: enter a value (${this.rangeText(p)}, default ${p.default})`;
      this.show(p, el, this.config[p.name]);
      return;
    }
    row.dataset.sent = "1";
    const {r, doc} = await postInOrder(this.path, {[p.name]: value});
    if (doc.config) {
      Object.assign(this.config, doc.config);
      this.show(p, el, doc.config[p.name]); // the camera's value: a refused one snaps back
    }
    if (r.ok) {
      reason.className = "reason ok";
      reason.textContent = `${p.name} = ${doc.config[p.name]}`;
      const shown = reason.textContent;
      setTimeout(() => { if (reason.textContent === shown) reason.textContent = ""; }, 2000);
    } else {
      reason.className = "reason error";
      reason.textContent = `refused ${value}: ${doc.reason || doc.error}`; // stays until the next change
    }
    delete row.dataset.sent;
    if (document.activeElement === el) el.blur();
    this.changed();
  },
};

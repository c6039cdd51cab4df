// The viewer's 3-D view: the newest frame's point cloud (/api/points.bin) drawn on a canvas with
// a z-buffer, in plain JavaScript (no WebGL, no network): drag to orbit, wheel to zoom,
// double-click to go back to the camera's own view.
"use strict";

class Cloud3D {
  constructor(canvas, colouring) {
    this.canvas = canvas;
    this.colouring = colouring; // () => "depth" | "left"
    this.ctx = canvas.getContext("2d");
    this.points = null; // Float32Array x y z ...
    this.rgb = null; // Uint8Array r g b ...
    this.sequence = -1; // the frame the points came from
    this.drawn = 0; // points that landed on the canvas in the last drawing
    this.home();
    let drag = null;
    canvas.addEventListener("mousedown", (ev) => { drag = {x: ev.clientX, y: ev.clientY}; });
    window.addEventListener("mouseup", () => { drag = null; });
    window.addEventListener("mousemove", (ev) => {
      if (!drag) return;
      this.yaw += (ev.clientX - drag.x) * 0.01;
      this.pitch = Math.max(-1.5, Math.min(1.5, this.pitch + (ev.clientY - drag.y) * 0.01));
      drag = {x: ev.clientX, y: ev.clientY};
      this.draw();
    });
    canvas.addEventListener("wheel", (ev) => {
      ev.preventDefault();
      this.zoom = Math.max(0.2, Math.min(20, this.zoom * Math.exp(-ev.deltaY * 0.001)));
      this.draw();
    }, {passive: false});
    canvas.addEventListener("dblclick", () => { this.home(); this.draw(); });
  }

  home() { this.yaw = 0; this.pitch = 0; this.zoom = 1; }

  async load(sequence) {
    const r = await fetch(`/api/points.bin?step=2&colour=${this.colouring()}&seq=${sequence}`);
    if (!r.ok) return;
    const buf = await r.arrayBuffer();
    const n = new DataView(buf).getUint32(0, true);
    this.points = new Float32Array(buf, 4, 3 * n);
    this.rgb = new Uint8Array(buf, 4 + 12 * n, 3 * n);
    this.sequence = sequence;
    this.draw();
  }

  draw() {
    const {canvas, points, rgb} = this;
    const w = canvas.width, h = canvas.height;
    const img = this.ctx.createImageData(w, h);
    const px = new Uint32Array(img.data.buffer);
    px.fill(0xff1a1a1a);
    this.drawn = 0;
    if (!points || points.length === 0) { this.ctx.putImageData(img, 0, 0); return; }
    // orbit about the cloud's median depth on the optical axis
    const zs = [];
    for (let i = 2; i < points.length; i += 3 * Math.max(1, Math.floor(points.length / 3000))) zs.push(points[i]);
    zs.sort((a, b) => a - b);
    const cz = zs[zs.length >> 1];
    const cy = Math.cos(this.yaw), sy = Math.sin(this.yaw), cp = Math.cos(this.pitch), sp = Math.sin(this.pitch);
    const f = 0.9 * w * this.zoom, dist = cz;
    const depth = new Float32Array(w * h).fill(Infinity);
    for (let i = 0, j = 0; i < points.length; i += 3, j += 3) {
      const x0 = points[i], y0 = points[i + 1], z0 = points[i + 2] - cz;
      const x1 = cy * x0 + sy * z0, z1 = -sy * x0 + cy * z0; // yaw about the vertical
      const y2 = cp * y0 - sp * z1, z2 = sp * y0 + cp * z1 + dist; // pitch about the horizontal
      if (z2 <= 0.01) continue;
      const u = Math.round(w / 2 + f * x1 / z2), v = Math.round(h / 2 + f * y2 / z2);
      if (u < 0 || v < 0 || u >= w - 1 || v >= h - 1) continue;
      const colour = 0xff000000 | (rgb[j + 2] << 16) | (rgb[j + 1] << 8) | rgb[j];
      for (const k of [v * w + u, v * w + u + 1, (v + 1) * w + u, (v + 1) * w + u + 1]) { // 2x2 px
        if (z2 < depth[k]) { depth[k] = z2; px[k] = colour; }
      }
      this.drawn++;
    }
    this.ctx.putImageData(img, 0, 0);
  }
}

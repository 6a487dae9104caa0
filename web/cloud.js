// The node inspector's 3D view of a node's segmented cloud (the paper's Fig. 2 and 3): ground,
// landmark and overhang points in three colours, drag to orbit, wheel to zoom, with the points
// per class. A plain 2D canvas: perspective projection, far points drawn first.
//
// GET /api/v1/fleets/{fleet}/nodes/{node}/cloud gives points (flat x, y, z in m, the leveled
// frame of the node's scan: x forward, y left, z up) and one class per point (1 ground,
// 2 landmark, 3 overhang).

import { fillList } from "./panel.js";
import { apiFetch } from "./state.js";

export const CLASSES = [
  { code: 1, name: "ground", colour: "#b59a6a" },
  { code: 2, name: "landmark", colour: "#c0392b" },
  { code: 3, name: "overhang", colour: "#27ae60" },
];
const COLOUR = Object.fromEntries(CLASSES.map((c) => [c.code, c.colour]));

const $ = (id) => document.getElementById(id);

/// The value below which a share `q` of the sorted values lies.
function quantile(sorted, q) {
  return sorted.length ? sorted[Math.min(sorted.length - 1, Math.floor(q * sorted.length))] : 0;
}

/// An orbiting camera over one cloud, drawn on a canvas.
export class CloudView {
  constructor(canvas) {
    this.canvas = canvas;
    this.ctx = canvas.getContext("2d");
    this.points = new Float32Array(0);
    this.classes = new Uint8Array(0);
    this.centre = [0, 0, 0];
    this.radius = 1;
    // Looking forward (along x) from behind and above the sensor.
    this.camera = { yaw: 0, pitch: 0.55, zoom: 1 };
    this.drawn = 0;
    this.drawMs = 0;
    this.pending = false;
    let drag = null;
    canvas.addEventListener("pointerdown", (e) => {
      drag = { x: e.clientX, y: e.clientY };
      canvas.setPointerCapture(e.pointerId);
      canvas.classList.add("dragging");
    });
    canvas.addEventListener("pointermove", (e) => {
      if (!drag) return;
      this.orbit(e.clientX - drag.x, e.clientY - drag.y);
      drag = { x: e.clientX, y: e.clientY };
    });
    const end = () => {
      drag = null;
      canvas.classList.remove("dragging");
    };
    canvas.addEventListener("pointerup", end);
    canvas.addEventListener("pointercancel", end);
    canvas.addEventListener(
      "wheel",
      (e) => {
        e.preventDefault();
        this.zoomBy(Math.exp(-e.deltaY * 0.0015));
      },
      { passive: false },
    );
  }

  /// Shows a cloud: flat [x, y, z, …] (m) and a class per point. The camera keeps its angles
  /// from node to node; the zoom is reset and the view fitted to the cloud.
  set(points, classes) {
    this.points = Float32Array.from(points);
    this.classes = Uint8Array.from(classes);
    const n = this.classes.length;
    // Fit to the bulk of the cloud: a few far points (a wall 40 m away) do not shrink it.
    const axes = [0, 1, 2].map((k) => {
      const v = new Float32Array(n);
      for (let i = 0; i < n; i++) v[i] = this.points[3 * i + k];
      return v.sort();
    });
    this.centre = axes.map((v) => (quantile(v, 0.03) + quantile(v, 0.97)) / 2);
    const d = new Float32Array(n);
    for (let i = 0; i < n; i++) {
      d[i] = Math.hypot(
        this.points[3 * i] - this.centre[0],
        this.points[3 * i + 1] - this.centre[1],
        this.points[3 * i + 2] - this.centre[2],
      );
    }
    this.radius = Math.max(1, quantile(d.sort(), 0.95));
    this.camera.zoom = 1;
    this.draw();
  }

  orbit(dx, dy) {
    const c = this.camera;
    c.yaw -= dx * 0.01;
    c.pitch = Math.max(-1.45, Math.min(1.5, c.pitch + dy * 0.01));
    this.redraw();
  }

  zoomBy(factor) {
    const c = this.camera;
    c.zoom = Math.max(0.2, Math.min(40, c.zoom * factor));
    this.redraw();
  }

  redraw() {
    if (this.pending) return;
    this.pending = true;
    requestAnimationFrame(() => {
      this.pending = false;
      this.draw();
    });
  }

  draw() {
    const t0 = performance.now();
    const { canvas, ctx } = this;
    const dpr = window.devicePixelRatio || 1;
    const w = canvas.clientWidth || canvas.width;
    const h = canvas.clientHeight || canvas.height;
    if (canvas.width !== Math.round(w * dpr) || canvas.height !== Math.round(h * dpr)) {
      canvas.width = Math.round(w * dpr);
      canvas.height = Math.round(h * dpr);
    }
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    ctx.clearRect(0, 0, w, h);

    // Screen right r, screen up u, into the screen f (an orthonormal, unmirrored frame).
    const { yaw, pitch, zoom } = this.camera;
    const [cosY, sinY, cosP, sinP] = [Math.cos(yaw), Math.sin(yaw), Math.cos(pitch), Math.sin(pitch)];
    const r = [sinY, -cosY, 0];
    const u = [sinP * cosY, sinP * sinY, cosP];
    const f = [cosP * cosY, cosP * sinY, -sinP];
    const distance = 3 * this.radius; // camera from the centre
    const focal = ((Math.min(w, h) / 2 - 8) * distance * zoom) / this.radius;
    const [c0, c1, c2] = this.centre;
    const project = (x, y, z) => {
      const qx = x - c0, qy = y - c1, qz = z - c2;
      const depth = qx * f[0] + qy * f[1] + qz * f[2] + distance;
      const s = focal / depth;
      return [w / 2 + (qx * r[0] + qy * r[1]) * s, h / 2 - (qx * u[0] + qy * u[1] + qz * u[2]) * s, depth];
    };

    const n = this.classes.length;
    const px = new Float32Array(n);
    const py = new Float32Array(n);
    const depth = new Float32Array(n);
    const order = new Uint32Array(n);
    let m = 0;
    for (let i = 0; i < n; i++) {
      const [x, y, d] = project(this.points[3 * i], this.points[3 * i + 1], this.points[3 * i + 2]);
      if (d <= 0.05 * distance || x < -4 || y < -4 || x > w + 4 || y > h + 4) continue;
      px[i] = x;
      py[i] = y;
      depth[i] = d;
      order[m++] = i;
    }
    const visible = order.subarray(0, m).sort((a, b) => depth[b] - depth[a]);
    let colour = null;
    for (const i of visible) {
      const c = COLOUR[this.classes[i]];
      if (c !== colour) ctx.fillStyle = colour = c;
      // Nearer points a little bigger.
      const size = Math.max(1.5, Math.min(4, (2.2 * distance) / depth[i]));
      ctx.fillRect(px[i] - size / 2, py[i] - size / 2, size, size);
    }
    this.drawn = m;

    // The sensor at the scan's start, and forward (x, 2 m).
    const [ox, oy] = project(0, 0, 0);
    const [ax, ay] = project(2, 0, 0);
    ctx.strokeStyle = "#111";
    ctx.fillStyle = "#111";
    ctx.lineWidth = 2;
    ctx.beginPath();
    ctx.moveTo(ox, oy);
    ctx.lineTo(ax, ay);
    ctx.stroke();
    ctx.beginPath();
    ctx.arc(ox, oy, 3, 0, 2 * Math.PI);
    ctx.fill();
    ctx.font = "11px system-ui, sans-serif";
    ctx.fillText("x", ax + 3, ay - 3);
    this.drawMs = performance.now() - t0;
  }
}

let view = null;
let request = 0;

/// Loads and shows a node's cloud in the inspector (`path`: its …/cloud route under the API;
/// null: the node has none). Resolves to what is shown, `{points, ground, landmark, overhang, source_points,
/// drawn, loadMs, drawMs, shownAt, camera}`, or null when the node has no cloud or another
/// node was opened meanwhile.
export async function showCloud(path) {
  const mine = ++request;
  const box = $("cloud-box");
  const note = $("cloud-note");
  box.hidden = false;
  box.classList.toggle("empty", !path);
  if (!path) {
    note.textContent = "not sent by its robot";
    return null;
  }
  note.textContent = "loading…";
  const t0 = performance.now();
  const r = await apiFetch(path);
  if (!r.ok) throw new Error(`${path}: ${r.status} ${(await r.text()).trim()}`);
  const c = await r.json();
  if (mine !== request) return null;
  view ??= new CloudView($("cloud"));
  view.set(c.points, c.classes);
  const loadMs = performance.now() - t0;
  note.textContent = "drag to orbit, wheel to zoom";
  const legend = $("cloud-legend");
  legend.replaceChildren(
    ...CLASSES.map(({ name, colour }) => {
      const k = document.createElement("span");
      k.className = "k";
      k.dataset.class = name;
      const sw = document.createElement("i");
      sw.style.background = colour;
      k.append(sw, name);
      return k;
    }),
  );
  const share = (k) => (c.kept ? `${((100 * k) / c.kept).toFixed(0)} %` : "—");
  const of = (name) => (c.source_counts ? ` of ${c.source_counts[name]}` : "");
  fillList($("cloud-list"), [
    ["points", `${c.kept} of ${c.source_points}`],
    ...CLASSES.map(({ name }) => [name, `${c.counts[name]}${of(name)} (${share(c.counts[name])})`]),
    ["reduced", [c.voxel_m > 0 ? `${c.voxel_m.toFixed(2)} m voxels` : "", c.max_points ? `at most ${c.max_points}` : ""]
      .filter(Boolean).join(", ") || "no"],
    ["loaded", `${loadMs.toFixed(0)} ms`],
  ]);
  return {
    id: c.id,
    points: c.kept,
    ground: c.counts.ground,
    landmark: c.counts.landmark,
    overhang: c.counts.overhang,
    source_points: c.source_points,
    drawn: view.drawn,
    loadMs,
    drawMs: view.drawMs,
    shownAt: performance.now(),
    camera: view.camera, // live: orbit and zoom change it
  };
}

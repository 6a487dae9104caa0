// levelmap dashboard: the first fleet's map, robots, pose network and node inspector, live
// from the mapping server's API and its event stream (docs/services.md).

import { View, scaleBarMetres, formatMetres } from "./view.js";
import { enuToGeodetic, formatLatLon } from "./geo.js";
import { showCloud } from "./cloud.js";

const API = "/api/v1";
const PALETTE = ["#e6550d", "#3182bd", "#31a354", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#17becf"];
const EDGE_COLOURS = {
  Odometry: "#8a8a8a",
  ScanMatch: "#2f7ed8",
  LoopClosure: "#e0412f",
  InterRobot: "#9b3fd1",
};
const GPS_COLOUR = "#1b9e5a";

// Everything the page shows, open to tests and the console as window.levelmapState.
const state = {
  fleet: null,
  robots: {}, // id -> {id, colour, pose: {x, y, theta}, lastSeenMs, nodes}
  nodes: [], // {id, robot, node_seq, pose}
  edges: [], // {from, to, kind}
  gps: [], // {node, position_m, residual_m}
  summary: null,
  grid: null, // {resolution_m, origin_m, width, height, image}
  showNetwork: false,
  showGrid: true,
  inspector: null, // {id, points, counts}
  events: 0,
  autoFit: true,
  errors: [],
  cursor: null, // {x, y} map metres under the pointer, with latitude_deg, longitude_deg if the map has a datum
  firstFullFrameMs: null, // performance.now() of the first frame with every node of the summary drawn
  graphLoads: 0,
  draws: 0,
  drawMsMean: 0, // running mean of draw() time, ms (about the last 50 frames)
};
const view = new View();
window.levelmapState = state;
window.levelmapView = view;

const $ = (id) => document.getElementById(id);
const canvas = $("map");
const ctx = canvas.getContext("2d");

async function getJson(path) {
  const r = await fetch(API + path);
  if (!r.ok) throw new Error(`${path}: ${r.status}`);
  return r.json();
}

function note(e) {
  state.errors.push(String(e));
  if (state.errors.length > 20) state.errors.shift();
  console.warn(e);
}

function robot(id) {
  let r = state.robots[id];
  if (!r) {
    const n = Object.keys(state.robots).length;
    r = state.robots[id] = { id, colour: PALETTE[n % PALETTE.length], pose: null, lastSeenMs: 0, nodes: 0 };
    // Colours follow the id order, so a reload gives every robot the same colour.
    Object.keys(state.robots)
      .sort()
      .forEach((k, i) => (state.robots[k].colour = PALETTE[i % PALETTE.length]));
  }
  return r;
}

// ---- data --------------------------------------------------------------------------------

async function findFleet() {
  while (!state.fleet) {
    try {
      const { fleets } = await getJson("/fleets");
      if (fleets.length) state.fleet = fleets[0];
    } catch (e) {
      note(e);
    }
    if (!state.fleet) await new Promise((ok) => setTimeout(ok, 1000));
  }
  $("fleet").textContent = `fleet ${state.fleet}`;
}

async function loadRobots() {
  const { robots, now_ns } = await getJson(`/fleets/${state.fleet}/robots`);
  const now = Date.now();
  for (const r of robots) {
    const s = robot(r.id);
    s.pose = r.pose;
    s.nodes = r.nodes;
    if (r.last_seen_ns) s.lastSeenMs = now - (now_ns - r.last_seen_ns) / 1e6;
  }
}

// Nodes by id and each robot's nodes in sequence order, rebuilt (lazily, for the next frame)
// when nodes come or go.
let nodeIndex = new Map();
let tracks = new Map();
let tracksDirty = true;
let lastGraphLoad = 0;

async function loadGraph() {
  const g = await getJson(`/fleets/${state.fleet}/graph`);
  lastGraphLoad = Date.now();
  state.graphLoads += 1;
  const nodes = g.nodes.map((n) => ({ id: n.id, robot: n.robot, node_seq: n.node_seq, pose: n.pose }));
  // Nodes announced by events after this graph was made stay until the next one has them.
  const index = new Map(nodes.map((n) => [n.id, n]));
  for (const n of state.nodes) {
    if (!index.has(n.id) && n.fromEvent && Date.now() - n.fromEvent < 10_000) {
      index.set(n.id, n);
      nodes.push(n);
    }
  }
  state.nodes = nodes;
  nodeIndex = index;
  state.edges = g.edges.map((e) => ({ from: e.from, to: e.to, kind: e.kind }));
  state.gps = g.gps;
  for (const n of state.nodes) robot(n.robot);
  tracksDirty = true;
}

function addNode(n) {
  if (nodeIndex.has(n.id)) return;
  nodeIndex.set(n.id, n);
  state.nodes.push(n);
  tracksDirty = true;
}

function trackMap() {
  if (tracksDirty) {
    tracks = new Map();
    for (const n of state.nodes) {
      let t = tracks.get(n.robot);
      if (!t) tracks.set(n.robot, (t = []));
      t.push(n);
    }
    for (const t of tracks.values()) t.sort((a, b) => a.node_seq - b.node_seq);
    tracksDirty = false;
  }
  return tracks;
}

async function loadSummary() {
  state.summary = await getJson(`/fleets/${state.fleet}/summary`);
  renderSummary();
}

async function loadGrid() {
  const meta = await getJson(`/fleets/${state.fleet}/map.json`);
  const image = new Image();
  image.src = `${API}/fleets/${state.fleet}/map.png?t=${meta.nodes}`;
  await image.decode();
  // The PNG is a second request: keep it only if it is the grid the JSON described.
  if (image.naturalWidth === meta.width && image.naturalHeight === meta.height) {
    state.grid = { ...meta, image };
  }
}

// Refreshes that events ask for, each at most once per period and never two at once.
function throttled(fn, periodMs) {
  let running = false;
  let again = false;
  let last = 0;
  const run = async () => {
    if (running) {
      again = true;
      return;
    }
    const wait = last + periodMs - Date.now();
    if (wait > 0) {
      running = true;
      await new Promise((ok) => setTimeout(ok, wait));
      running = false;
    }
    running = true;
    last = Date.now();
    try {
      await fn();
    } catch (e) {
      note(e);
    }
    running = false;
    redraw();
    if (again) {
      again = false;
      run();
    }
  };
  return run;
}
const refreshGraph = throttled(loadGraph, 1000);
// Node events are applied as they come; the whole graph (edges, re-optimized poses) is
// fetched again at most every GRAPH_PERIOD_MS for them, and soon after an `optimized`.
const GRAPH_PERIOD_MS = 5000;
let graphTimer = null;
function graphSoon() {
  if (graphTimer) return;
  const wait = Math.max(0, lastGraphLoad + GRAPH_PERIOD_MS - Date.now());
  graphTimer = setTimeout(() => {
    graphTimer = null;
    refreshGraph();
  }, wait);
}
const refreshSummary = throttled(loadSummary, 1000);
const refreshGrid = throttled(loadGrid, 3000);
const refreshRobots = throttled(loadRobots, 1000);

function onEvent(msg) {
  let ev;
  try {
    ev = JSON.parse(msg.data);
  } catch {
    return;
  }
  if (ev.fleet !== state.fleet) return;
  state.events += 1;
  if (ev.type === "pose") {
    const r = robot(ev.robot);
    r.pose = ev.pose;
    r.lastSeenMs = Date.now();
  } else if (ev.type === "node") {
    addNode({ id: ev.node, robot: ev.robot, node_seq: ev.node_seq, pose: ev.pose, fromEvent: Date.now() });
    robot(ev.robot).nodes = ev.node_seq + 1;
    graphSoon();
    refreshSummary();
    refreshGrid();
  } else if (ev.type === "optimized") {
    refreshGraph();
    refreshSummary();
    refreshGrid();
  }
  redraw();
}

// ---- panels ------------------------------------------------------------------------------

function fillList(dl, rows) {
  dl.replaceChildren();
  for (const [k, v] of rows) {
    const dt = document.createElement("dt");
    dt.textContent = k;
    const dd = document.createElement("dd");
    dd.textContent = v;
    dl.append(dt, dd);
  }
}

function renderSummary() {
  const s = state.summary;
  if (!s) return;
  const o = s.last_optimization;
  fillList($("summary-list"), [
    ["robots", s.robots],
    ["nodes", s.nodes],
    ["edges", s.edges],
    ["loop closures", s.loop_closures],
    ["between robots", s.inter_robot_closures],
    ["GPS edges", s.gps_edges],
    ["last solve χ²", o ? o.final_chi2.toFixed(1) : "—"],
    ["iterations", o ? `${o.iterations} (${o.stop})` : "—"],
  ]);
}

function renderRobots() {
  const ul = $("robot-list");
  const now = Date.now();
  const items = Object.values(state.robots)
    .sort((a, b) => a.id.localeCompare(b.id))
    .map((r) => {
      const li = document.createElement("li");
      li.dataset.robot = r.id;
      const sw = document.createElement("span");
      sw.className = "swatch";
      sw.style.background = r.colour;
      const name = document.createElement("span");
      name.textContent = r.id;
      const age = document.createElement("span");
      age.className = "age";
      age.textContent = r.lastSeenMs ? `${((now - r.lastSeenMs) / 1000).toFixed(1)} s ago` : "no odometry";
      li.append(sw, name, age);
      return li;
    });
  ul.replaceChildren(...items);
}

async function inspect(id) {
  const n = await getJson(`/fleets/${state.fleet}/nodes/${id}`);
  const pts = [];
  n.scan.bearing_rad.forEach((b, i) => {
    const r = n.scan.range_m[i];
    if (r > 0) pts.push([r * Math.cos(b), r * Math.sin(b)]);
  });
  state.inspector = { id, robot: n.robot, points: pts.length, counts: n.counts };
  $("inspector").hidden = false;
  $("inspector-title").textContent = `${id} (${n.robot} #${n.node_seq})`;
  drawScan(pts);
  const c = n.counts || {};
  fillList($("inspector-list"), [
    ["pose", `${n.pose.x.toFixed(2)}, ${n.pose.y.toFixed(2)} m, ${((n.pose.theta * 180) / Math.PI).toFixed(1)}°`],
    ["scan points", pts.length],
    ["3D points", c.points ?? "—"],
    ["ground", c.ground ?? "—"],
    ["landmark", c.landmark ?? "—"],
    ["overhang", c.overhang ?? "—"],
    ["invalid", c.invalid ?? "—"],
    ["GPS fixes", n.gps.length],
    ["edges", n.edges.map((e) => `${e.kind} ${e.from}→${e.to}`).join(", ") || "—"],
  ]);
  redraw();
  // The segmented 3D cloud (cloud.js): state.inspector.cloud = {points, ground, landmark, overhang, …}.
  const cloud = await showCloud(n.cloud ? `${API}/fleets/${state.fleet}/nodes/${id}/cloud` : null);
  if (state.inspector?.id === id) state.inspector.cloud = cloud;
}

/// The leveled scan in the robot frame, forward (x) up, fitted to the canvas.
function drawScan(pts) {
  const c = $("scan");
  const g = c.getContext("2d");
  g.clearRect(0, 0, c.width, c.height);
  const maxR = Math.max(5, ...pts.map(([x, y]) => Math.hypot(x, y)));
  const s = (c.width / 2 - 8) / maxR;
  const cx = c.width / 2;
  const cy = c.height / 2;
  g.strokeStyle = "#ddd";
  for (const r of [maxR / 2, maxR]) {
    g.beginPath();
    g.arc(cx, cy, r * s, 0, 2 * Math.PI);
    g.stroke();
  }
  g.fillStyle = "#c0392b";
  for (const [x, y] of pts) g.fillRect(cx - y * s - 1, cy - x * s - 1, 2, 2);
  g.fillStyle = "#222";
  g.beginPath();
  g.moveTo(cx, cy - 8);
  g.lineTo(cx - 5, cy + 5);
  g.lineTo(cx + 5, cy + 5);
  g.fill();
  g.fillText(`${maxR.toFixed(0)} m`, cx + maxR * s * 0.71, cy - maxR * s * 0.71);
}

// ---- map ---------------------------------------------------------------------------------

function bounds() {
  let x0 = Infinity, y0 = Infinity, x1 = -Infinity, y1 = -Infinity;
  const add = (p) => {
    if (!p) return;
    if (p.x < x0) x0 = p.x;
    if (p.x > x1) x1 = p.x;
    if (p.y < y0) y0 = p.y;
    if (p.y > y1) y1 = p.y;
  };
  for (const n of state.nodes) add(n.pose);
  for (const r of Object.values(state.robots)) add(r.pose);
  return x0 <= x1 ? [x0, y0, x1, y1] : null;
}

let pending = false;
function redraw() {
  if (pending) return;
  pending = true;
  requestAnimationFrame(() => {
    pending = false;
    draw();
  });
}

// The world box on screen, with a margin of `px` pixels: what lies outside is not drawn.
function visibleBox(px = 20) {
  const [x0, y1] = view.toWorld(-px, -px);
  const [x1, y0] = view.toWorld(view.width + px, view.height + px);
  return [x0, y0, x1, y1];
}

const inBox = (b, x, y) => x >= b[0] && x <= b[2] && y >= b[1] && y <= b[3];
// Whether the segment's bounding box meets the box (cheap and conservative).
const segInBox = (b, ax, ay, bx, by) =>
  Math.max(ax, bx) >= b[0] && Math.min(ax, bx) <= b[2] && Math.max(ay, by) >= b[1] && Math.min(ay, by) <= b[3];

function draw() {
  const t0 = performance.now();
  drawFrame();
  const ms = performance.now() - t0;
  state.draws += 1;
  state.drawMsMean += (ms - state.drawMsMean) / Math.min(state.draws, 50);
}

function drawFrame() {
  const dpr = window.devicePixelRatio || 1;
  const w = canvas.clientWidth;
  const h = canvas.clientHeight;
  if (canvas.width !== Math.round(w * dpr) || canvas.height !== Math.round(h * dpr)) {
    canvas.width = Math.round(w * dpr);
    canvas.height = Math.round(h * dpr);
  }
  view.width = w;
  view.height = h;
  if (state.autoFit) view.fit(bounds());
  ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  ctx.clearRect(0, 0, w, h);

  const g = state.grid;
  if (g && state.showGrid) {
    const [x0, y0] = view.toScreen(g.origin_m[0], g.origin_m[1] + g.height * g.resolution_m);
    ctx.imageSmoothingEnabled = view.scale * g.resolution_m < 1;
    ctx.globalAlpha = 0.9;
    ctx.drawImage(g.image, x0, y0, g.width * g.resolution_m * view.scale, g.height * g.resolution_m * view.scale);
    ctx.globalAlpha = 1;
  }

  const box = visibleBox();
  if (state.showNetwork) drawNetwork(box);
  drawTrajectories(box);
  drawRobots(box);
  drawSelection();
  drawScaleBar();
  if (state.firstFullFrameMs === null && state.ready && state.summary && state.nodes.length > 0 &&
      state.nodes.length >= state.summary.nodes) {
    state.firstFullFrameMs = performance.now();
  }
}

function drawNetwork(box) {
  ctx.lineWidth = 1.5;
  // One path per edge kind.
  const paths = new Map();
  for (const e of state.edges) {
    const a = nodeIndex.get(e.from);
    const b = nodeIndex.get(e.to);
    if (!a || !b) continue;
    const ax = a.pose.x, ay = a.pose.y, bx = b.pose.x, by = b.pose.y;
    if (!segInBox(box, ax, ay, bx, by)) continue;
    let p = paths.get(e.kind);
    if (!p) paths.set(e.kind, (p = new Path2D()));
    const [sx, sy] = view.toScreen(ax, ay);
    const [ex, ey] = view.toScreen(bx, by);
    // Level of detail: an edge under a pixel long is not seen (zoomed out on a big map).
    if (Math.abs(ex - sx) + Math.abs(ey - sy) < 1) continue;
    p.moveTo(sx, sy);
    p.lineTo(ex, ey);
  }
  for (const [kind, p] of paths) {
    ctx.strokeStyle = EDGE_COLOURS[kind] || "#000";
    ctx.stroke(p);
  }
  // GPS residuals: from the fix to where the antenna is on the solved pose.
  const gpsLines = new Path2D();
  const gpsDots = new Path2D();
  for (const f of state.gps) {
    const [px, py] = f.position_m;
    const qx = px + f.residual_m[0];
    const qy = py + f.residual_m[1];
    if (!segInBox(box, px, py, qx, qy)) continue;
    const [sx, sy] = view.toScreen(px, py);
    const [ex, ey] = view.toScreen(qx, qy);
    gpsDots.rect(sx - 1, sy - 1, 2, 2);
    gpsLines.moveTo(sx, sy);
    gpsLines.lineTo(ex, ey);
  }
  ctx.strokeStyle = GPS_COLOUR;
  ctx.fillStyle = GPS_COLOUR;
  ctx.fill(gpsDots);
  ctx.stroke(gpsLines);
  const dots = new Path2D();
  const drawn = new Set(); // one dot per pixel
  for (const n of state.nodes) {
    if (!inBox(box, n.pose.x, n.pose.y)) continue;
    const [x, y] = view.toScreen(n.pose.x, n.pose.y);
    const key = Math.round(x) * 16384 + Math.round(y);
    if (drawn.has(key)) continue;
    drawn.add(key);
    dots.moveTo(x + 3, y);
    dots.arc(x, y, 3, 0, 2 * Math.PI);
  }
  ctx.fillStyle = "#222";
  ctx.fill(dots);
}

function drawTrajectories(box) {
  ctx.lineWidth = 2;
  for (const [id, nodes] of trackMap()) {
    const r = robot(id);
    const line = new Path2D();
    const marks = new Path2D();
    let px = 0, py = 0, penDown = false;
    let lx = -1e9, ly = -1e9; // the last point put in the path (screen px)
    const step = (x, y, mark) => {
      const [sx, sy] = view.toScreen(x, y);
      // Level of detail: points under a pixel from the last one drawn add nothing.
      const near = Math.abs(sx - lx) + Math.abs(sy - ly) < 1;
      if (penDown && segInBox(box, px, py, x, y)) {
        if (!near) {
          line.lineTo(sx, sy);
          if (mark) marks.rect(sx - 2, sy - 2, 4, 4);
          lx = sx;
          ly = sy;
        }
      } else {
        // Off screen: lift the pen; start again at this point.
        line.moveTo(sx, sy);
        if (mark && inBox(box, x, y)) marks.rect(sx - 2, sy - 2, 4, 4);
        lx = sx;
        ly = sy;
      }
      px = x;
      py = y;
      penDown = true;
    };
    for (const n of nodes) step(n.pose.x, n.pose.y, true);
    if (r.pose) step(r.pose.x, r.pose.y, false);
    ctx.strokeStyle = r.colour;
    ctx.stroke(line);
    ctx.fillStyle = r.colour;
    ctx.fill(marks);
  }
}

function drawRobots(box) {
  ctx.font = "12px system-ui, sans-serif";
  for (const r of Object.values(state.robots)) {
    if (!r.pose || !inBox(box, r.pose.x, r.pose.y)) continue;
    const [x, y] = view.toScreen(r.pose.x, r.pose.y);
    ctx.save();
    ctx.translate(x, y);
    ctx.rotate(-r.pose.theta);
    ctx.fillStyle = r.colour;
    ctx.strokeStyle = "#fff";
    ctx.lineWidth = 1.5;
    ctx.beginPath();
    ctx.moveTo(14, 0);
    ctx.lineTo(-8, 8);
    ctx.lineTo(-4, 0);
    ctx.lineTo(-8, -8);
    ctx.closePath();
    ctx.fill();
    ctx.stroke();
    ctx.restore();
    const age = r.lastSeenMs ? ` · ${((Date.now() - r.lastSeenMs) / 1000).toFixed(0)} s` : "";
    ctx.fillStyle = "#111";
    ctx.fillText(`${r.id}${age}`, x + 12, y - 10);
  }
}

function drawSelection() {
  const n = state.inspector && nodeIndex.get(state.inspector.id);
  if (!n) return;
  const [x, y] = view.toScreen(n.pose.x, n.pose.y);
  ctx.strokeStyle = "#000";
  ctx.lineWidth = 2;
  ctx.beginPath();
  ctx.arc(x, y, 7, 0, 2 * Math.PI);
  ctx.stroke();
}

function drawScaleBar() {
  const m = scaleBarMetres(view.scale);
  const px = m * view.scale;
  const x = 16;
  const y = view.height - 20;
  ctx.fillStyle = "rgba(255,255,255,0.8)";
  ctx.fillRect(x - 6, y - 18, px + 12, 26);
  ctx.strokeStyle = "#111";
  ctx.lineWidth = 2;
  ctx.beginPath();
  ctx.moveTo(x, y - 5);
  ctx.lineTo(x, y);
  ctx.lineTo(x + px, y);
  ctx.lineTo(x + px, y - 5);
  ctx.stroke();
  ctx.fillStyle = "#111";
  ctx.font = "12px system-ui, sans-serif";
  ctx.fillText(formatMetres(m), x + 4, y - 6);
}

/// The node nearest the canvas point (CSS px), within `radius` px.
function nodeAt(sx, sy, radius = 10) {
  let best = null;
  let bestD = radius;
  for (const n of state.nodes) {
    const [x, y] = view.toScreen(n.pose.x, n.pose.y);
    const d = Math.hypot(x - sx, y - sy);
    if (d <= bestD) {
      best = n;
      bestD = d;
    }
  }
  return best;
}
// Where a node is drawn, for tests: canvas CSS px relative to the page.
state.nodeOnPage = (id) => {
  const n = state.nodes.find((k) => k.id === id);
  if (!n) return null;
  const [x, y] = view.toScreen(n.pose.x, n.pose.y);
  const r = canvas.getBoundingClientRect();
  return { x: r.left + x, y: r.top + y };
};

// ---- input -------------------------------------------------------------------------------

let drag = null;
canvas.addEventListener("pointerdown", (e) => {
  drag = { x: e.clientX, y: e.clientY, moved: 0 };
  canvas.setPointerCapture(e.pointerId);
});
// The status bar: map metres under the pointer and, with a datum, WGS84.
function showCursor(sx, sy) {
  const [x, y] = view.toWorld(sx, sy);
  const c = { x, y };
  const d = state.summary?.datum;
  let text = `x ${x.toFixed(2)} m, y ${y.toFixed(2)} m`;
  if (d) {
    const g = enuToGeodetic(d, x, y);
    c.latitude_deg = g.latitude_deg;
    c.longitude_deg = g.longitude_deg;
    text += ` · ${formatLatLon(g)}`;
  } else {
    text += " · no GPS datum";
  }
  state.cursor = c;
  $("cursor").textContent = text;
}

canvas.addEventListener("pointermove", (e) => {
  const r = canvas.getBoundingClientRect();
  showCursor(e.clientX - r.left, e.clientY - r.top);
  if (!drag) return;
  const dx = e.clientX - drag.x;
  const dy = e.clientY - drag.y;
  drag.moved += Math.abs(dx) + Math.abs(dy);
  drag.x = e.clientX;
  drag.y = e.clientY;
  if (drag.moved > 3) {
    canvas.classList.add("dragging");
    state.autoFit = false;
    view.pan(dx, dy);
    redraw();
  }
});
canvas.addEventListener("pointerup", (e) => {
  const click = drag && drag.moved <= 3;
  drag = null;
  canvas.classList.remove("dragging");
  if (!click) return;
  const r = canvas.getBoundingClientRect();
  const n = nodeAt(e.clientX - r.left, e.clientY - r.top);
  if (n) inspect(n.id).catch(note);
});
canvas.addEventListener(
  "wheel",
  (e) => {
    e.preventDefault();
    state.autoFit = false;
    const r = canvas.getBoundingClientRect();
    view.zoomAt(e.clientX - r.left, e.clientY - r.top, Math.exp(-e.deltaY * 0.0015));
    redraw();
  },
  { passive: false },
);
window.addEventListener("resize", redraw);

$("toggle-network").addEventListener("change", (e) => {
  state.showNetwork = e.target.checked;
  document.body.classList.toggle("network", state.showNetwork);
  redraw();
});
$("toggle-grid").addEventListener("change", (e) => {
  state.showGrid = e.target.checked;
  redraw();
});
$("fit").addEventListener("click", () => {
  state.autoFit = true;
  redraw();
});
$("inspector-close").addEventListener("click", () => {
  state.inspector = null;
  $("inspector").hidden = true;
  redraw();
});

const TOKEN_KEY = "levelmap.token";
$("token").value = localStorage.getItem(TOKEN_KEY) || "";
$("token").addEventListener("change", (e) => localStorage.setItem(TOKEN_KEY, e.target.value));
$("optimize").addEventListener("click", async () => {
  const status = $("optimize-status");
  if (!state.fleet) return;
  status.textContent = "solving…";
  try {
    const r = await fetch(`${API}/fleets/${state.fleet}/optimize`, {
      method: "POST",
      headers: { Authorization: `Bearer ${$("token").value}` },
    });
    if (r.ok) {
      const rep = await r.json();
      status.textContent = rep.final_chi2 !== undefined ? `χ² ${rep.final_chi2.toFixed(1)}` : "done";
      refreshSummary();
      refreshGraph();
    } else {
      status.textContent = `${r.status}: ${(await r.text()).trim()}`;
    }
  } catch (e) {
    status.textContent = String(e);
  }
});

// ---- start -------------------------------------------------------------------------------

async function start() {
  redraw();
  await findFleet();
  const events = new EventSource(`${API}/events`);
  events.onmessage = onEvent;
  await Promise.all([loadGraph(), loadRobots(), loadSummary()]).catch(note);
  refreshGrid();
  state.ready = true;
  renderRobots();
  redraw();
  // Last-seen ages tick on, and the robots' list catches what the stream dropped.
  setInterval(() => {
    refreshRobots();
    renderRobots();
    redraw();
  }, 1000);
}

start().catch(note);

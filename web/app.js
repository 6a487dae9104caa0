// levelmap dashboard: the first fleet's map, robots, pose network and node inspector, live
// from the mapping server's API and its event stream (docs/services.md).

import { View, scaleBarMetres, formatMetres } from "./view.js";
import { enuToGeodetic, formatLatLon } from "./geo.js";
import { showCloud } from "./cloud.js";
import { fillList } from "./panel.js";

const API = "/api/v1";
const PALETTE = ["#e6550d", "#3182bd", "#31a354", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#17becf"];
const EDGE_COLOURS = {
  Odometry: "#8a8a8a",
  ScanMatch: "#2f7ed8",
  LoopClosure: "#e0412f",
  InterRobot: "#9b3fd1",
};
const GPS_COLOUR = "#1b9e5a";
const ELLIPSE_COLOUR = "#d98c00";

// Everything the page shows, open to tests and the console as window.levelmapState.
const state = {
  fleet: null,
  robots: {}, // id -> {id, colour, pose: {x, y, theta}, lastSeenMs, nodes}
  nodes: [], // {id, robot, node_seq, pose}
  edges: [], // {from, to, kind}
  gps: [], // {node, position_m, residual_m}
  summary: null,
  grid: null, // the whole map: {resolution_m, origin_m, width, height, nodes, image}
  gridDetail: null, // the part on screen at finer cells: the same, and {cell, box} asked for
  gridDetailLoads: 0,
  showNetwork: false,
  showGrid: true,
  inspector: null, // {id, points, counts}
  covariances: new Map(), // node id -> 3 × 3 marginal covariance of (x, y, θ), for the ellipses
  ellipses: "", // what the legend says about them
  events: 0,
  autoFit: true,
  errors: [],
  cursor: null, // {x, y} map metres under the pointer, with latitude_deg, longitude_deg if the map has a datum
  firstFullFrameMs: null, // performance.now() of the first frame with every node of the summary drawn
  graphLoads: 0,
  draws: 0,
  layerDraws: 0, // times the trajectories and network were drawn into the layer
  timings: {}, // performance.now() of the start's steps, and the last layer's drawing time (ms)
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
    layerData += 1;
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
let graphNodes = 0; // nodes in the last /graph (the ones the server can answer for)

async function loadGraph() {
  // Columns: a tenth of the bytes of one object per item, for maps of thousands of nodes.
  const g = await getJson(`/fleets/${state.fleet}/graph?columns=true`);
  lastGraphLoad = Date.now();
  state.graphLoads += 1;
  const gn = g.nodes;
  const nodes = new Array(gn.x.length);
  for (let i = 0; i < nodes.length; i++) {
    nodes[i] = { id: i, robot: g.robots[gn.robot[i]], node_seq: gn.node_seq[i], pose: { x: gn.x[i], y: gn.y[i], theta: gn.theta[i] } };
  }
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
  graphNodes = gn.x.length;
  // The poses moved: the uncertainty is the new network's.
  state.covariances = new Map();
  refreshCovariances();
  const ge = g.edges;
  state.edges = ge.from.map((from, i) => ({ from, to: ge.to[i], kind: g.kinds[ge.kind[i]] }));
  const gg = g.gps;
  state.gps = gg.node.map((node, i) => ({
    node,
    position_m: [gg.x[i], gg.y[i]],
    residual_m: [gg.residual_x[i], gg.residual_y[i]],
  }));
  for (const r of g.robots) robot(r);
  tracksDirty = true;
  layerData += 1;
}

function addNode(n) {
  if (nodeIndex.has(n.id)) return;
  nodeIndex.set(n.id, n);
  state.nodes.push(n);
  tracksDirty = true;
  layerData += 1;
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

// The occupancy grid in two pictures: an overview of the whole map, its cells as coarse as it
// takes to stay under GRID_MAX_CELLS, and, zoomed in past the overview's cells, a detail of
// the part on screen (and half a screen around) at the cells the zoom can show.
const GRID_MAX_CELLS = 2048 * 2048;
const GRID_FINEST_M = 0.1; // the mapper's default cell

async function fetchGrid(query) {
  const r = await fetch(`${API}/fleets/${state.fleet}/map.png?max_cells=${GRID_MAX_CELLS}${query}`, { cache: "no-store" });
  if (!r.ok) throw new Error(`map.png${query}: ${r.status} ${(await r.text()).trim()}`);
  // Where the picture lies comes with it, so it always matches the picture.
  const placement = JSON.parse(r.headers.get("levelmap-grid"));
  return { ...placement, image: await createImageBitmap(await r.blob()) };
}

async function loadGrid() {
  state.grid = await fetchGrid("");
  state.gridDetail = null;
  await loadGridDetail();
}

// The detail the view wants: null when the overview's cells are already under 2 px.
function wantedDetail() {
  const g = state.grid;
  if (!g || g.resolution_m * view.scale <= 2) return null;
  // The finest cell worth a pixel, in powers of two of the finest: small zooms reuse it.
  const cell = GRID_FINEST_M * 2 ** Math.max(0, Math.ceil(Math.log2(1 / (view.scale * GRID_FINEST_M))));
  if (cell >= g.resolution_m) return null;
  return { cell, box: visibleBox(view, Math.max(view.width, view.height) / 2) };
}

async function loadGridDetail() {
  const want = wantedDetail();
  const d = state.gridDetail;
  if (!want) {
    state.gridDetail = null;
    return;
  }
  const [x0, y0, x1, y1] = visibleBox(view, 0);
  if (d && d.cell === want.cell && d.nodes === state.grid.nodes &&
      x0 >= d.box[0] && y0 >= d.box[1] && x1 <= d.box[2] && y1 <= d.box[3]) {
    return;
  }
  const box = want.box.map((v) => v.toFixed(1));
  const detail = await fetchGrid(`&resolution_m=${want.cell}&bbox=${box.join(",")}`);
  state.gridDetail = { ...detail, cell: want.cell, box: want.box };
  state.gridDetailLoads += 1;
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
const refreshGridDetail = throttled(loadGridDetail, 300);

// Node uncertainty ellipses: the marginal covariances of the nodes on screen, asked for when
// the network is shown and at most MAX_ELLIPSE_NODES are on screen.
const MAX_ELLIPSE_NODES = 500;
async function loadCovariances() {
  if (!state.showNetwork) return;
  const box = visibleBox(view, 0);
  const onScreen = state.nodes.filter((n) => n.id < graphNodes && inBox(box, n.pose.x, n.pose.y));
  if (onScreen.length > MAX_ELLIPSE_NODES) {
    state.ellipses = `ellipses: zoom in (${onScreen.length} nodes on screen)`;
  } else {
    const missing = onScreen.filter((n) => !state.covariances.has(n.id)).map((n) => n.id);
    if (missing.length) {
      const loads = state.graphLoads;
      const c = await getJson(`/fleets/${state.fleet}/covariances?nodes=${missing.join(",")}`);
      // A graph that came meanwhile makes these stale.
      if (loads !== state.graphLoads) return;
      c.nodes.forEach((id, i) => state.covariances.set(id, c.covariance[i]));
      layerData += 1;
    }
    state.ellipses = `95% ellipses (${onScreen.length} nodes)`;
  }
  $("ellipses").textContent = state.ellipses;
}
const refreshCovariances = throttled(loadCovariances, 1000);
// After the view moves: the detail the new view needs, once the moving stops.
let viewTimer = null;
function viewMoved() {
  state.autoFit = false;
  clearTimeout(viewTimer);
  viewTimer = setTimeout(() => {
    refreshGridDetail();
    refreshCovariances();
  }, 250);
}
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

// The world box a view shows, with a margin of `px` pixels: what lies outside is not drawn.
function visibleBox(v, px = 20) {
  const [x0, y1] = v.toWorld(-px, -px);
  const [x1, y0] = v.toWorld(v.width + px, v.height + px);
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

// The map's static picture (trajectories and the pose network: thousands of paths) is drawn
// into a layer twice the canvas's size and moved with the view, so panning costs one image
// copy. It is drawn again when the view leaves it, when what it shows is toggled, and when the
// data or the zoom changed, then no sooner than ten times its last drawing time (at most
// LAYER_REFRESH_MS) after the last: a live big map spends at most a tenth of its time on it.
// Meanwhile the old layer is moved and scaled.
const LAYER_REFRESH_MS = 500;
let layerData = 0; // bumped whenever the data the layer shows changes
const layer = { canvas: document.createElement("canvas"), view: null, data: -1, style: "", madeAt: -Infinity, drawMs: 0 };
layer.ctx = layer.canvas.getContext("2d");

function drawLayer(dpr, style) {
  const t0 = performance.now();
  const lv = new View();
  Object.assign(lv, { cx: view.cx, cy: view.cy, scale: view.scale, width: view.width * 2, height: view.height * 2 });
  const c = layer.canvas;
  if (c.width !== Math.round(lv.width * dpr) || c.height !== Math.round(lv.height * dpr)) {
    c.width = Math.round(lv.width * dpr);
    c.height = Math.round(lv.height * dpr);
  }
  const g = layer.ctx;
  g.setTransform(dpr, 0, 0, dpr, 0, 0);
  g.clearRect(0, 0, lv.width, lv.height);
  const box = visibleBox(lv);
  if (state.showNetwork) drawNetwork(g, lv, box);
  drawTrajectories(g, lv, box);
  const now = performance.now();
  state.timings.layer_draw_ms = now - t0;
  Object.assign(layer, { view: lv, data: layerData, style, madeAt: now, drawMs: now - t0 });
  state.layerDraws += 1;
}

// Whether the layer holds everything the canvas shows now.
function layerCovers() {
  const lv = layer.view;
  const [x0, y1] = view.toWorld(0, 0);
  const [x1, y0] = view.toWorld(view.width, view.height);
  const [lx0, ly1] = lv.toWorld(0, 0);
  const [lx1, ly0] = lv.toWorld(lv.width, lv.height);
  return x0 >= lx0 && x1 <= lx1 && y0 >= ly0 && y1 <= ly1;
}

let layerTimer = null;
function drawLayerAndBlit(dpr) {
  const style = `${state.showNetwork}|${dpr}`;
  const lv = layer.view;
  const age = performance.now() - layer.madeAt;
  const wait = Math.min(LAYER_REFRESH_MS, 10 * layer.drawMs);
  const young = age < wait;
  const sameScale = lv && lv.scale === view.scale;
  const exact = sameScale && layer.data === layerData;
  if (!lv || layer.style !== style || (!exact && !young) || (!layerCovers() && (sameScale || !young))) {
    drawLayer(dpr, style);
  } else if (!exact && !layerTimer) {
    layerTimer = setTimeout(() => {
      layerTimer = null;
      redraw();
    }, wait - age);
  }
  const l = layer.view;
  const k = view.scale / l.scale;
  const [wx, wy] = l.toWorld(0, 0);
  const [sx, sy] = view.toScreen(wx, wy);
  ctx.drawImage(layer.canvas, sx, sy, l.width * k, l.height * k);
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

  if (state.showGrid) {
    ctx.globalAlpha = 0.9;
    for (const g of [state.grid, state.gridDetail]) {
      if (!g) continue;
      const [x0, y0] = view.toScreen(g.origin_m[0], g.origin_m[1] + g.height * g.resolution_m);
      ctx.imageSmoothingEnabled = view.scale * g.resolution_m < 1;
      ctx.drawImage(g.image, x0, y0, g.width * g.resolution_m * view.scale, g.height * g.resolution_m * view.scale);
    }
    ctx.globalAlpha = 1;
  }

  const box = visibleBox(view);
  drawLayerAndBlit(dpr);
  drawLiveTails(box);
  drawRobots(box);
  drawSelection();
  drawScaleBar();
  if (state.firstFullFrameMs === null && state.ready && state.summary && state.nodes.length > 0 &&
      state.nodes.length >= state.summary.nodes && layer.data === layerData) {
    state.firstFullFrameMs = performance.now();
  }
}

function drawNetwork(g, v, box) {
  g.lineWidth = 1.5;
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
    const [sx, sy] = v.toScreen(ax, ay);
    const [ex, ey] = v.toScreen(bx, by);
    // Level of detail: an edge under a pixel long is not seen (zoomed out on a big map).
    if (Math.abs(ex - sx) + Math.abs(ey - sy) < 1) continue;
    p.moveTo(sx, sy);
    p.lineTo(ex, ey);
  }
  for (const [kind, p] of paths) {
    g.strokeStyle = EDGE_COLOURS[kind] || "#000";
    g.stroke(p);
  }
  // GPS residuals: from the fix to where the antenna is on the solved pose.
  const gpsLines = new Path2D();
  const gpsDots = new Path2D();
  for (const f of state.gps) {
    const [px, py] = f.position_m;
    const qx = px + f.residual_m[0];
    const qy = py + f.residual_m[1];
    if (!segInBox(box, px, py, qx, qy)) continue;
    const [sx, sy] = v.toScreen(px, py);
    const [ex, ey] = v.toScreen(qx, qy);
    gpsDots.rect(sx - 1, sy - 1, 2, 2);
    gpsLines.moveTo(sx, sy);
    gpsLines.lineTo(ex, ey);
  }
  g.strokeStyle = GPS_COLOUR;
  g.fillStyle = GPS_COLOUR;
  g.fill(gpsDots);
  g.stroke(gpsLines);
  // Uncertainty: the 95% ellipse of each node's position (χ² of 2 degrees: 5.991).
  const ellipses = new Path2D();
  for (const [id, c] of state.covariances) {
    const n = nodeIndex.get(id);
    if (!c || !n || !inBox(box, n.pose.x, n.pose.y)) continue;
    const [a, b, d] = [c[0][0], c[0][1], c[1][1]];
    const mid = (a + d) / 2;
    const half = Math.hypot((a - d) / 2, b);
    const r1 = Math.sqrt(5.991 * (mid + half)) * v.scale;
    const r2 = Math.sqrt(5.991 * Math.max(mid - half, 0)) * v.scale;
    if (r1 < 1) continue;
    const [x, y] = v.toScreen(n.pose.x, n.pose.y);
    // The major axis's angle from east; screen y points down.
    const angle = 0.5 * Math.atan2(2 * b, a - d);
    ellipses.moveTo(x + r1 * Math.cos(-angle), y + r1 * Math.sin(-angle));
    ellipses.ellipse(x, y, r1, r2, -angle, 0, 2 * Math.PI);
  }
  g.lineWidth = 1;
  g.strokeStyle = ELLIPSE_COLOUR;
  g.stroke(ellipses);
  const dots = new Path2D();
  const drawn = new Set(); // one dot per pixel
  for (const n of state.nodes) {
    if (!inBox(box, n.pose.x, n.pose.y)) continue;
    const [x, y] = v.toScreen(n.pose.x, n.pose.y);
    const key = Math.round(x) * 16384 + Math.round(y);
    if (drawn.has(key)) continue;
    drawn.add(key);
    dots.moveTo(x + 3, y);
    dots.arc(x, y, 3, 0, 2 * Math.PI);
  }
  g.fillStyle = "#222";
  g.fill(dots);
}

function drawTrajectories(g, v, box) {
  g.lineWidth = 2;
  for (const [id, nodes] of trackMap()) {
    const r = robot(id);
    const line = new Path2D();
    const marks = new Path2D();
    let px = 0, py = 0, penDown = false;
    let lx = -1e9, ly = -1e9; // the last point put in the path (screen px)
    for (const n of nodes) {
      const { x, y } = n.pose;
      const [sx, sy] = v.toScreen(x, y);
      // Level of detail: points under a pixel from the last one drawn add nothing.
      const near = Math.abs(sx - lx) + Math.abs(sy - ly) < 1;
      if (penDown && segInBox(box, px, py, x, y)) {
        if (!near) {
          line.lineTo(sx, sy);
          marks.rect(sx - 2, sy - 2, 4, 4);
          lx = sx;
          ly = sy;
        }
      } else {
        // Off screen: lift the pen; start again at this point.
        line.moveTo(sx, sy);
        if (inBox(box, x, y)) marks.rect(sx - 2, sy - 2, 4, 4);
        lx = sx;
        ly = sy;
      }
      px = x;
      py = y;
      penDown = true;
    }
    g.strokeStyle = r.colour;
    g.stroke(line);
    g.fillStyle = r.colour;
    g.fill(marks);
  }
}

// Each robot's way from its last node to where it is now: live, so drawn every frame.
function drawLiveTails(box) {
  ctx.lineWidth = 2;
  for (const [id, nodes] of trackMap()) {
    const r = robot(id);
    const last = nodes[nodes.length - 1];
    if (!r.pose || !last || !segInBox(box, last.pose.x, last.pose.y, r.pose.x, r.pose.y)) continue;
    const [ax, ay] = view.toScreen(last.pose.x, last.pose.y);
    const [bx, by] = view.toScreen(r.pose.x, r.pose.y);
    ctx.strokeStyle = r.colour;
    ctx.beginPath();
    ctx.moveTo(ax, ay);
    ctx.lineTo(bx, by);
    ctx.stroke();
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

// One pointer drags (or clicks, if it hardly moved); two pinch: zoom about their midpoint
// and pan with it (tablets).
let drag = null;
const pointers = new Map(); // pointerId -> {x, y} (client px)
let pinch = null; // {distance, x, y} of the two pointers last move
const pinchOf = () => {
  const [a, b] = [...pointers.values()];
  return { distance: Math.hypot(a.x - b.x, a.y - b.y), x: (a.x + b.x) / 2, y: (a.y + b.y) / 2 };
};
canvas.addEventListener("pointerdown", (e) => {
  pointers.set(e.pointerId, { x: e.clientX, y: e.clientY });
  canvas.setPointerCapture(e.pointerId);
  if (pointers.size === 2) {
    pinch = pinchOf();
    drag = null;
  } else if (pointers.size === 1) {
    drag = { x: e.clientX, y: e.clientY, moved: 0 };
  }
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
  if (pointers.has(e.pointerId)) pointers.set(e.pointerId, { x: e.clientX, y: e.clientY });
  if (pinch && pointers.size === 2) {
    const p = pinchOf();
    view.pan(p.x - pinch.x, p.y - pinch.y);
    if (pinch.distance > 0) view.zoomAt(p.x - r.left, p.y - r.top, p.distance / pinch.distance);
    pinch = p;
    viewMoved();
    redraw();
    return;
  }
  if (!drag) return;
  const dx = e.clientX - drag.x;
  const dy = e.clientY - drag.y;
  drag.moved += Math.abs(dx) + Math.abs(dy);
  drag.x = e.clientX;
  drag.y = e.clientY;
  if (drag.moved > 3) {
    canvas.classList.add("dragging");
    view.pan(dx, dy);
    viewMoved();
    redraw();
  }
});
function pointerEnd(e) {
  pointers.delete(e.pointerId);
  if (pointers.size < 2) pinch = null;
  const click = drag && drag.moved <= 3 && e.type === "pointerup";
  drag = null;
  canvas.classList.remove("dragging");
  if (!click) return;
  const r = canvas.getBoundingClientRect();
  const n = nodeAt(e.clientX - r.left, e.clientY - r.top, e.pointerType === "touch" ? 20 : 10);
  if (n) inspect(n.id).catch(note);
}
canvas.addEventListener("pointerup", pointerEnd);
canvas.addEventListener("pointercancel", pointerEnd);
canvas.addEventListener(
  "wheel",
  (e) => {
    e.preventDefault();
    const r = canvas.getBoundingClientRect();
    view.zoomAt(e.clientX - r.left, e.clientY - r.top, Math.exp(-e.deltaY * 0.0015));
    viewMoved();
    redraw();
  },
  { passive: false },
);
window.addEventListener("resize", redraw);

$("toggle-network").addEventListener("change", (e) => {
  state.showNetwork = e.target.checked;
  refreshCovariances();
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
  setTimeout(refreshGridDetail, 50);
});
$("inspector-close").addEventListener("click", () => {
  state.inspector = null;
  $("inspector").hidden = true;
  redraw();
});

// The bearer token, kept in this browser. The page asks /auth whether the mapper takes it
// (no write is tried with a token it refuses) and shows the answer on the token field and
// the re-optimize button.
const TOKEN_KEY = "levelmap.token";
$("token").value = localStorage.getItem(TOKEN_KEY) || "";
const bearer = () => ({ Authorization: `Bearer ${$("token").value}` });

async function checkToken() {
  const r = await fetch(`${API}/auth`, { headers: bearer() });
  const a = await r.json();
  state.auth = !a.write_routes ? "off" : a.authorized ? "ok" : $("token").value ? "refused" : "none";
  document.body.dataset.auth = state.auth;
  const why = {
    off: "the mapper has no token: its write routes are off",
    none: "enter the mapper's bearer token to re-optimize",
    refused: `token refused: ${a.reason}`,
    ok: "token accepted",
  }[state.auth];
  $("token").title = why;
  $("optimize").disabled = state.auth !== "ok";
  $("optimize").title = why;
  $("optimize-status").textContent = state.auth === "refused" ? "token refused" : state.auth === "off" ? "read-only" : "";
}

$("token").addEventListener("change", (e) => {
  localStorage.setItem(TOKEN_KEY, e.target.value);
  checkToken().catch(note);
});
$("optimize").addEventListener("click", async () => {
  const status = $("optimize-status");
  if (!state.fleet) return;
  status.textContent = "solving…";
  try {
    const r = await fetch(`${API}/fleets/${state.fleet}/optimize`, { method: "POST", headers: bearer() });
    if (r.ok) {
      const rep = await r.json();
      status.textContent = rep.final_chi2 !== undefined ? `χ² ${rep.final_chi2.toFixed(1)}` : "done";
      refreshSummary();
      refreshGraph();
    } else {
      status.textContent = `${r.status}: ${(await r.text()).trim()}`;
      checkToken().catch(note);
    }
  } catch (e) {
    status.textContent = String(e);
  }
});

// ---- start -------------------------------------------------------------------------------

async function start() {
  redraw();
  checkToken().catch(note);
  await findFleet();
  state.timings.fleet = performance.now();
  const events = new EventSource(`${API}/events`);
  events.onmessage = onEvent;
  await Promise.all([loadGraph(), loadRobots(), loadSummary()]).catch(note);
  state.timings.loaded = performance.now();
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

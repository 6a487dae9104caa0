// The map's data from the API: the fleet, its robots, its pose network (graph and node
// events), its summary and the covariances of the nodes on screen; the refreshes the event
// stream asks for.

import { visibleBox, inBox } from "./view.js";
import { state, view, $, index, getJson, note, robot, redraw, throttled } from "./state.js";
import { refreshGrid } from "./grid.js";
import { renderSummary } from "./sidebar.js";

export async function findFleet() {
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

export async function loadRobots() {
  const { robots, now_ns } = await getJson(`/fleets/${state.fleet}/robots`);
  const now = Date.now();
  for (const r of robots) {
    const s = robot(r.id);
    s.pose = r.pose;
    s.nodes = r.nodes;
    if (r.last_seen_ns) s.lastSeenMs = now - (now_ns - r.last_seen_ns) / 1e6;
  }
  // Each robot's mode (map, or localize on a version) and its newest localization: a
  // robot that only localizes has no node in the map, its pose is the localization's.
  const { modes, localizations } = await getJson(`/fleets/${state.fleet}/modes`);
  for (const [id, l] of Object.entries(localizations)) {
    const s = robot(id);
    s.localization = l;
    if (l.pose && !robots.some((r) => r.id === id)) s.pose = l.pose;
  }
  for (const s of Object.values(state.robots)) s.mode = modes.robots[s.id] ?? modes.fleet;
}

let lastGraphLoad = 0;
let graphNodes = 0; // nodes in the last /graph (the ones the server can answer for)

export async function loadGraph() {
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
  const byId = new Map(nodes.map((n) => [n.id, n]));
  for (const n of state.nodes) {
    if (!byId.has(n.id) && n.fromEvent && Date.now() - n.fromEvent < 10_000) {
      byId.set(n.id, n);
      nodes.push(n);
    }
  }
  state.nodes = nodes;
  index.nodes = byId;
  graphNodes = gn.x.length;
  // The poses moved: the uncertainty is asked for again for the new network. The old ellipses
  // stay drawn until their answers come, so a live map (a new graph every second or so) still
  // gets ellipses when the answers take longer than the graph's next load.
  state.covariancesAsked = new Set();
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
  index.tracksDirty = true;
  index.layerData += 1;
}

function addNode(n) {
  if (index.nodes.has(n.id)) return;
  index.nodes.set(n.id, n);
  state.nodes.push(n);
  index.tracksDirty = true;
  index.layerData += 1;
}

export async function loadSummary() {
  state.summary = await getJson(`/fleets/${state.fleet}/summary`);
  renderSummary();
}

export const refreshGraph = throttled(loadGraph, 1000);
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
export const refreshSummary = throttled(loadSummary, 1000);

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
    const missing = onScreen.filter((n) => !state.covariancesAsked.has(n.id)).map((n) => n.id);
    if (missing.length) {
      const loads = state.graphLoads;
      const c = await getJson(`/fleets/${state.fleet}/covariances?nodes=${missing.join(",")}`);
      c.nodes.forEach((id, i) => state.covariances.set(id, c.covariance[i]));
      // Of this graph: done; a graph that came meanwhile asks for them again.
      if (loads === state.graphLoads) missing.forEach((id) => state.covariancesAsked.add(id));
      index.layerData += 1;
    }
    state.ellipses = `95% ellipses (${onScreen.length} nodes)`;
  }
  $("ellipses").textContent = state.ellipses;
}
export const refreshCovariances = throttled(loadCovariances, 1000);
export const refreshRobots = throttled(loadRobots, 1000);

export function onEvent(msg) {
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

// What the page shows and the helpers every part of it uses: the state (window.levelmapState),
// the camera, the map canvas, the API's requests (with the bearer token) and JSON, the robots'
// colours, the node index, redraw and the throttle of refreshes.

import { View } from "./view.js";

export const API = "/api/v1";
const PALETTE = ["#e6550d", "#3182bd", "#31a354", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#17becf"];

// Everything the page shows, open to tests and the console as window.levelmapState.
export const state = {
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
  baseMap: null, // {url, attribution, max_zoom} of /api/v1/dashboard, when configured
  showBaseMap: true,
  baseMapZoom: null, // the zoom of the tiles drawn last
  baseMapTiles: 0, // tiles loaded
  inspector: null, // {id, points, counts}
  covariances: new Map(), // node id -> 3 × 3 marginal covariance of (x, y, θ), for the ellipses
  covariancesAsked: new Set(), // node ids whose covariance is of the current graph
  ellipses: "", // what the legend says about them
  events: 0,
  autoFit: true,
  follow: null, // the followed robot (follow.js): {robot, pose, scan, samples, delayMs, drawnAt, scanPointsDrawn}
  errors: [],
  auth: null, // the token's standing (auth.js): needed, refused, none, off, read, ok
  cursor: null, // {x, y} map metres under the pointer, with latitude_deg, longitude_deg if the map has a datum
  firstFullFrameMs: null, // performance.now() of the first frame with every node of the summary drawn
  graphLoads: 0,
  draws: 0,
  layerDraws: 0, // times the trajectories and network were drawn into the layer
  timings: {}, // performance.now() of the start's steps, and the last layer's drawing time (ms)
  drawMsMean: 0, // running mean of draw() time, ms (about the last 50 frames)
};
export const view = new View();
window.levelmapState = state;
window.levelmapView = view;

export const $ = (id) => document.getElementById(id);
export const canvas = $("map");
export const ctx = canvas.getContext("2d");

// Kept beside the state rather than in it (tests read the state as it is). Nodes by id and
// each robot's nodes in sequence order, rebuilt (lazily, for the next frame) when nodes come
// or go; and the version of the data the layer shows (layer.js), bumped whenever it changes.
export const index = { nodes: new Map(), tracks: new Map(), tracksDirty: true, layerData: 0 };

export function trackMap() {
  if (index.tracksDirty) {
    const tracks = new Map();
    for (const n of state.nodes) {
      let t = tracks.get(n.robot);
      if (!t) tracks.set(n.robot, (t = []));
      t.push(n);
    }
    for (const t of tracks.values()) t.sort((a, b) => a.node_seq - b.node_seq);
    index.tracks = tracks;
    index.tracksDirty = false;
  }
  return index.tracks;
}

// The bearer token the page sends: one the mapper took (auth.js checks a token before it is
// used), kept in this browser.
const TOKEN_KEY = "levelmap.token";
let token = localStorage.getItem(TOKEN_KEY) || "";
export const sentToken = () => token;
export function useToken(t) {
  token = t;
  localStorage.setItem(TOKEN_KEY, t);
}
export const authHeaders = (t = token) => (t ? { Authorization: `Bearer ${t}` } : {});

// On a 401 the page asks for a token (auth.js sets how) and every request waits until one is
// taken, then goes again with it.
let askForToken = async () => {
  throw new Error("the mapper wants a token");
};
export function onTokenWanted(ask) {
  askForToken = ask;
}
let tokenWait = null;
export function tokenWanted() {
  tokenWait ??= askForToken().finally(() => (tokenWait = null));
  return tokenWait;
}

export const sleep = (ms) => new Promise((ok) => setTimeout(ok, ms));
const BUSY_RETRIES = 3;

// A request to the API with the token. A 503 with Retry-After (the mapper at a limit: busy)
// is sent again after the wait, a few times; what comes then is the caller's.
export async function apiFetch(path, init = {}) {
  for (let busy = 0; ; ) {
    if (tokenWait) await tokenWait;
    const r = await fetch(API + path, { ...init, headers: { ...authHeaders(), ...init.headers } });
    if (r.status === 401) {
      await tokenWanted();
      continue;
    }
    const retryS = Number(r.headers.get("retry-after"));
    if (r.status === 503 && retryS > 0 && busy++ < BUSY_RETRIES) {
      await sleep(retryS * 1000);
      continue;
    }
    return r;
  }
}

export async function getJson(path) {
  const r = await apiFetch(path);
  if (!r.ok) throw new Error(`${path}: ${r.status}`);
  return r.json();
}

export function note(e) {
  state.errors.push(String(e));
  if (state.errors.length > 20) state.errors.shift();
  console.warn(e);
}

export function robot(id) {
  let r = state.robots[id];
  if (!r) {
    const n = Object.keys(state.robots).length;
    r = state.robots[id] = { id, colour: PALETTE[n % PALETTE.length], pose: null, lastSeenMs: 0, nodes: 0 };
    // Colours follow the id order, so a reload gives every robot the same colour.
    Object.keys(state.robots)
      .sort()
      .forEach((k, i) => (state.robots[k].colour = PALETTE[i % PALETTE.length]));
    index.layerData += 1;
  }
  return r;
}

// One frame at the next animation frame, however many ask. The frame is frame.js's, set
// there (so the data and input modules can ask for one without importing the drawing).
let frame = () => {};
export function onRedraw(draw) {
  frame = draw;
}
let pending = false;
export function redraw() {
  if (pending) return;
  pending = true;
  requestAnimationFrame(() => {
    pending = false;
    frame();
  });
}

// Refreshes that events ask for, each at most once per period and never two at once.
export function throttled(fn, periodMs) {
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

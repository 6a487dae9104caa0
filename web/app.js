// levelmap dashboard: the first fleet's map, robots, pose network and node inspector, live
// from the mapping server's API and its event stream (docs/services.md). This module starts
// the page; the parts are state.js (what it shows), data.js (the API), grid.js, layer.js and
// frame.js (the map), basemap.js (a web map under it), sidebar.js (the panels), input.js (pointer, controls), auth.js (the
// token) and stream.js (the event stream).

import { state, note, redraw } from "./state.js";
import { findFleet, loadGraph, loadRobots, loadSummary, onEvent, refreshRobots } from "./data.js";
import { refreshGrid } from "./grid.js";
import { loadBaseMap } from "./basemap.js";
import { renderRobots } from "./sidebar.js";
import "./frame.js"; // sets the frame redraw() draws
import "./input.js"; // the map's pointer and the header's controls
import { ensureToken } from "./auth.js";
import { streamEvents } from "./stream.js";

async function start() {
  redraw();
  // Nothing is read before the page has a token the mapper takes (when it needs one).
  await ensureToken().catch(note);
  await findFleet();
  state.timings.fleet = performance.now();
  streamEvents(onEvent);
  await Promise.all([loadGraph(), loadRobots(), loadSummary(), loadBaseMap()]).catch(note);
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

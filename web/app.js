// levelmap dashboard: the first fleet's map, robots, pose network and node inspector, live
// from the mapping server's API and its event stream (docs/services.md). This module starts
// the page; the parts are state.js (what it shows), data.js (the API), grid.js, layer.js and
// frame.js (the map), sidebar.js (the panels) and input.js (pointer, controls, token).

import { API, state, note, redraw } from "./state.js";
import { findFleet, loadGraph, loadRobots, loadSummary, onEvent, refreshRobots } from "./data.js";
import { refreshGrid } from "./grid.js";
import { renderRobots } from "./sidebar.js";
import "./frame.js"; // sets the frame redraw() draws
import { checkToken } from "./input.js";

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

// One frame of the map canvas, from the bottom up: the base map (when configured), the grid, the layer (trajectories and
// network), each robot's live tail and arrow, the selected node, the scale bar.

import { scaleBarMetres, formatMetres, visibleBox, inBox, segInBox } from "./view.js";
import { state, view, canvas, ctx, index, trackMap, robot, onRedraw } from "./state.js";
import { drawGrid } from "./grid.js";
import { drawBaseMap } from "./basemap.js";
import { drawLayerAndBlit, layerUpToDate } from "./layer.js";
import { drawFollowScan } from "./follow.js";

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

// The frame, timed (state.drawMsMean); redraw() in state.js calls it.
function draw() {
  const t0 = performance.now();
  drawFrame();
  const ms = performance.now() - t0;
  state.draws += 1;
  state.drawMsMean += (ms - state.drawMsMean) / Math.min(state.draws, 50);
}
onRedraw(draw);

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

  drawBaseMap();
  drawGrid();
  const box = visibleBox(view);
  drawLayerAndBlit(dpr);
  drawLiveTails(box);
  drawFollowScan(ctx);
  drawRobots(box);
  drawSelection();
  drawScaleBar();
  if (state.firstFullFrameMs === null && state.ready && state.summary && state.nodes.length > 0 &&
      state.nodes.length >= state.summary.nodes && layerUpToDate()) {
    state.firstFullFrameMs = performance.now();
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
    if (state.follow?.robot === r.id) state.follow.drawnAt = [x, y, view.width / 2, view.height / 2];
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
  const n = state.inspector && index.nodes.get(state.inspector.id);
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

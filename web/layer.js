// The map's static picture: each robot's trajectory and, on the toggle, the pose network
// (edges by kind, GPS residuals, 95% ellipses, nodes), drawn into a layer that frame.js copies.

import { View, visibleBox, inBox, segInBox } from "./view.js";
import { state, view, ctx, index, trackMap, robot, redraw } from "./state.js";

const EDGE_COLOURS = {
  Odometry: "#8a8a8a",
  ScanMatch: "#2f7ed8",
  LoopClosure: "#e0412f",
  InterRobot: "#9b3fd1",
};
const GPS_COLOUR = "#1b9e5a";
const ELLIPSE_COLOUR = "#d98c00";

// The map's static picture (trajectories and the pose network: thousands of paths) is drawn
// into a layer twice the canvas's size and moved with the view, so panning costs one image
// copy. It is drawn again when the view leaves it, when what it shows is toggled, and when the
// data or the zoom changed, then no sooner than ten times its last drawing time (at most
// LAYER_REFRESH_MS) after the last: a live big map spends at most a tenth of its time on it.
// Meanwhile the old layer is moved and scaled.
const LAYER_REFRESH_MS = 500;
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
  Object.assign(layer, { view: lv, data: index.layerData, style, madeAt: now, drawMs: now - t0 });
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
export function drawLayerAndBlit(dpr) {
  const style = `${state.showNetwork}|${dpr}`;
  const lv = layer.view;
  const age = performance.now() - layer.madeAt;
  const wait = Math.min(LAYER_REFRESH_MS, 10 * layer.drawMs);
  const young = age < wait;
  const sameScale = lv && lv.scale === view.scale;
  const exact = sameScale && layer.data === index.layerData;
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

// Whether the layer shows the data as it is now (the first full frame waits for it).
export const layerUpToDate = () => layer.data === index.layerData;

function drawNetwork(g, v, box) {
  g.lineWidth = 1.5;
  // One path per edge kind.
  const paths = new Map();
  for (const e of state.edges) {
    const a = index.nodes.get(e.from);
    const b = index.nodes.get(e.to);
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
    const n = index.nodes.get(id);
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

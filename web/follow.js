// The follow view: one robot's live feed (GET …/robots/{robot}/live, server-sent events read
// like the event stream) keeps the map centred on the robot at the feed's rate, with the scan
// it sees now drawn around it, and the feed's delay in the status bar.

import { state, view, $, redraw, robot } from "./state.js";
import { streamEvents } from "./stream.js";
import { refreshGridDetail } from "./grid.js";

let stop = null;

/// Follows robot `id` (the one followed before is let go).
export function follow(id) {
  unfollow();
  const controller = new AbortController();
  stop = controller;
  state.follow = { robot: id, pose: null, scan: null, samples: 0, delayMs: null, drawnAt: null, scanPointsDrawn: 0 };
  state.autoFit = false;
  let detailAt = 0;
  streamEvents((m) => {
    const d = JSON.parse(m.data);
    const f = state.follow;
    if (!f || f.robot !== id || !d.pose) return;
    f.pose = d.pose;
    f.samples += 1;
    // Robot stamp → this browser, and mapper → this browser (the same clock here; a remote
    // robot's clock offset adds to the first).
    f.delayMs = Date.now() - d.stamp_ns / 1e6;
    f.mapperDelayMs = Date.now() - d.sent_ns / 1e6;
    if (d.scan) f.scan = d.scan;
    const r = robot(id);
    r.pose = d.pose;
    r.lastSeenMs = Date.now();
    view.cx = d.pose.x;
    view.cy = d.pose.y;
    $("follow-status").textContent =
      `following ${id} · feed ${f.mapperDelayMs.toFixed(0)} ms from the mapper, ` +
      `${f.delayMs.toFixed(0)} ms after the robot's odometry`;
    // The finer grid of the part on screen, now and then as the robot moves on.
    if (Date.now() - detailAt > 2000) {
      detailAt = Date.now();
      refreshGridDetail();
    }
    redraw();
  }, `/fleets/${state.fleet}/robots/${encodeURIComponent(id)}/live`, controller.signal);
  redraw();
}

/// Stops following.
export function unfollow() {
  if (stop) stop.abort();
  stop = null;
  if (state.follow) {
    state.follow = null;
    $("follow-status").textContent = "";
    redraw();
  }
}

/// The followed robot's live scan, in its colour, at its pose now.
export function drawFollowScan(ctx) {
  const f = state.follow;
  if (!f || !f.pose || !f.scan) return;
  const o = f.scan.origin_in_robot;
  const p = f.pose;
  const [co, so] = [Math.cos(o.theta), Math.sin(o.theta)];
  const [cp, sp] = [Math.cos(p.theta), Math.sin(p.theta)];
  ctx.fillStyle = robot(f.robot).colour;
  let drawn = 0;
  f.scan.bearing_rad.forEach((b, i) => {
    const r = f.scan.range_m[i];
    if (!(r > 0)) return;
    // Beam → scan frame → robot frame → map.
    const [sx, sy] = [r * Math.cos(b), r * Math.sin(b)];
    const [rx, ry] = [o.x + co * sx - so * sy, o.y + so * sx + co * sy];
    const [x, y] = view.toScreen(p.x + cp * rx - sp * ry, p.y + sp * rx + cp * ry);
    ctx.fillRect(x - 1.5, y - 1.5, 3, 3);
    drawn += 1;
  });
  f.scanPointsDrawn = drawn;
  f.scanReturns = f.scan.range_m.filter((r) => r > 0).length;
}

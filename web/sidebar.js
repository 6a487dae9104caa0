// The side panels: the map's summary, the robots' list, and the node inspector (its leveled
// scan here; cloud.js draws its 3D cloud).

import { fillList } from "./panel.js";
import { showCloud } from "./cloud.js";
import { follow, unfollow } from "./follow.js";
import { state, $, getJson, redraw } from "./state.js";

export function renderSummary() {
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

/// "maps", or "v1 · localized" (the version it localizes on, and how its last node went).
function modeText(r) {
  if (r.mode?.mode !== "localize") return "maps";
  const status = r.localization?.version === r.mode.version ? ` · ${r.localization.status.replace("_", " ")}` : "";
  return `v${r.mode.version}${status}`;
}

export function renderRobots() {
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
      const button = document.createElement("button");
      button.type = "button";
      button.className = "follow";
      const following = state.follow?.robot === r.id;
      button.textContent = following ? "stop" : "follow";
      button.title = following ? "stop following" : `follow ${r.id}: the map moves with it, its live scan drawn`;
      button.addEventListener("click", () => {
        // Stopping goes back to the whole map.
        if (state.follow?.robot === r.id) {
          unfollow();
          state.autoFit = true;
        } else follow(r.id);
        renderRobots();
      });
      const mode = document.createElement("span");
      mode.className = "mode";
      mode.textContent = modeText(r);
      li.append(sw, name, mode, age, button);
      return li;
    });
  ul.replaceChildren(...items);
}

export async function inspect(id) {
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
  const cloud = await showCloud(n.cloud ? `/fleets/${state.fleet}/nodes/${id}/cloud` : null);
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

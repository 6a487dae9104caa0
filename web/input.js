// The page's input: pointer, pinch and wheel on the map (pan, zoom, click a node to inspect
// it), the status bar under the pointer, the header's toggles (the token: auth.js).

import { enuToGeodetic, formatLatLon } from "./geo.js";
import { state, view, $, canvas, note, redraw } from "./state.js";
import { refreshCovariances } from "./data.js";
import { refreshGridDetail } from "./grid.js";
import { inspect, renderRobots } from "./sidebar.js";
import { unfollow } from "./follow.js";

// Panning by hand lets the followed robot go (zooming keeps it).
function panned() {
  if (!state.follow) return;
  unfollow();
  renderRobots();
}

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
    panned();
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
$("toggle-base-map").addEventListener("change", (e) => {
  state.showBaseMap = e.target.checked;
  $("attribution").hidden = !state.showBaseMap;
  redraw();
});
$("fit").addEventListener("click", () => {
  unfollow();
  renderRobots();
  state.autoFit = true;
  redraw();
  setTimeout(refreshGridDetail, 50);
});
$("inspector-close").addEventListener("click", () => {
  state.inspector = null;
  $("inspector").hidden = true;
  redraw();
});

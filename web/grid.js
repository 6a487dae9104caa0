// The occupancy grid in two pictures: an overview of the whole map, its cells as coarse as it
// takes to stay under GRID_MAX_CELLS, and, zoomed in past the overview's cells, a detail of
// the part on screen (and half a screen around) at the cells the zoom can show.

import { visibleBox } from "./view.js";
import { apiFetch, state, view, ctx, throttled } from "./state.js";

const GRID_MAX_CELLS = 2048 * 2048;
const GRID_FINEST_M = 0.1; // the mapper's default cell

// The grid in map_server's scale mode: each known cell's grey is 255·(1 − p), unknown cells
// are transparent; `picture` turns it into what the map shows.
async function fetchGrid(query) {
  const r = await apiFetch(`/fleets/${state.fleet}/map.png?mode=scale&max_cells=${GRID_MAX_CELLS}${query}`, { cache: "no-store" });
  if (!r.ok) throw new Error(`map.png${query}: ${r.status} ${(await r.text()).trim()}`);
  // Where the picture lies comes with it, so it always matches the picture.
  const placement = JSON.parse(r.headers.get("levelmap-grid"));
  const bitmap = await createImageBitmap(await r.blob());
  const c = new OffscreenCanvas(bitmap.width, bitmap.height).getContext("2d");
  c.drawImage(bitmap, 0, 0);
  const cells = c.getImageData(0, 0, bitmap.width, bitmap.height);
  const g = { ...placement, cells };
  g.image = picture(g, 1);
  return g;
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

export const refreshGrid = throttled(loadGrid, 3000);
export const refreshGridDetail = throttled(loadGridDetail, 300);

// The scale PNG's greys against the grid's thresholds (0.65 and 0.35): occupied at or below
// OCCUPIED_MAX, free at or above FREE_MIN, seen but undecided in between.
const OCCUPIED_MAX = 89, FREE_MIN = 166;
// What the map shows: occupied darker with more evidence (0–71), free whiter with more
// (235–255), unknown (never seen, or undecided) a blue-grey told apart from both.
const UNKNOWN_RGB = [196, 202, 214];
function shade(grey) {
  if (grey <= OCCUPIED_MAX) return Math.round(grey * 0.8);
  if (grey >= FREE_MIN) return Math.round(235 + ((grey - FREE_MIN) * 20) / (255 - FREE_MIN));
  return -1;
}

/// The picture of the grid reduced by `k` × `k` blocks (1: every cell), each block the state
/// that matters most in it: occupied (its darkest) over free (its palest) over unknown.
/// Averaging (the canvas's smoothing) would fade a tree's few cells into the free space around
/// it and lose it when zoomed out. Kept per factor.
function picture(g, k) {
  g.pictures ??= new Map();
  if (g.pictures.has(k)) return g.pictures.get(k);
  const { data, width, height } = g.cells;
  const [w, h] = [Math.ceil(width / k), Math.ceil(height / k)];
  const out = new ImageData(w, h);
  for (let by = 0; by < h; by++) {
    for (let bx = 0; bx < w; bx++) {
      let occupied = 256, free = -1;
      for (let y = by * k; y < Math.min((by + 1) * k, height); y++) {
        for (let x = bx * k; x < Math.min((bx + 1) * k, width); x++) {
          const i = 4 * (y * width + x);
          if (data[i + 3] === 0) continue;
          const v = shade(data[i]);
          if (v < 0) continue;
          if (data[i] <= OCCUPIED_MAX) occupied = Math.min(occupied, v);
          else free = Math.max(free, v);
        }
      }
      const o = 4 * (by * w + bx);
      const rgb = occupied < 256 ? [occupied, occupied, occupied] : free >= 0 ? [free, free, free] : UNKNOWN_RGB;
      out.data.set([...rgb, 255], o);
    }
  }
  const canvas = new OffscreenCanvas(w, h);
  canvas.getContext("2d").putImageData(out, 0, 0);
  g.pictures.set(k, canvas);
  return canvas;
}

/// Both pictures on the map canvas, each where its header placed it (the frame's first layer).
/// A cell under a device pixel is drawn from the reduced picture, so an occupied cell stays at
/// least one device pixel at every zoom.
export function drawGrid() {
  if (!state.showGrid) return;
  const dpr = window.devicePixelRatio || 1;
  ctx.globalAlpha = 0.9;
  // Over a base map the grid multiplies: free (white) shows the map as it is, unknown greys
  // it a little, occupied stays black.
  if (state.baseMap && state.showBaseMap) ctx.globalCompositeOperation = "multiply";
  for (const g of [state.grid, state.gridDetail]) {
    if (!g) continue;
    const [x0, y0] = view.toScreen(g.origin_m[0], g.origin_m[1] + g.height * g.resolution_m);
    const cellPx = view.scale * g.resolution_m * dpr;
    const k = cellPx < 1 ? Math.ceil(1 / cellPx) : 1;
    const shown = picture(g, k);
    // A reduced picture's last blocks may reach past the grid: its own size, in cells.
    const cellM = g.resolution_m * (k > 1 ? k : 1);
    ctx.imageSmoothingEnabled = false;
    ctx.drawImage(shown, x0, y0, shown.width * cellM * view.scale, shown.height * cellM * view.scale);
  }
  ctx.globalAlpha = 1;
  ctx.globalCompositeOperation = "source-over";
}

// The occupancy grid in two pictures: an overview of the whole map, its cells as coarse as it
// takes to stay under GRID_MAX_CELLS, and, zoomed in past the overview's cells, a detail of
// the part on screen (and half a screen around) at the cells the zoom can show.

import { visibleBox } from "./view.js";
import { apiFetch, state, view, ctx, throttled } from "./state.js";

const GRID_MAX_CELLS = 2048 * 2048;
const GRID_FINEST_M = 0.1; // the mapper's default cell

async function fetchGrid(query) {
  const r = await apiFetch(`/fleets/${state.fleet}/map.png?max_cells=${GRID_MAX_CELLS}${query}`, { cache: "no-store" });
  if (!r.ok) throw new Error(`map.png${query}: ${r.status} ${(await r.text()).trim()}`);
  // Where the picture lies comes with it, so it always matches the picture.
  const placement = JSON.parse(r.headers.get("levelmap-grid"));
  return { ...placement, image: await createImageBitmap(await r.blob()) };
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

// The picture's greys (map_saver's trinary PNG): occupied 0, unknown 205, free 254.
const OCCUPIED = 0, UNKNOWN = 205, FREE = 254;

/// The picture reduced by `k` × `k` blocks, each block the state that matters most in it:
/// occupied over free over unknown. Averaging (the canvas's smoothing) would fade a tree's
/// few cells into the free space around it and lose it when zoomed out. Kept per factor.
function reduced(g, k) {
  g.reduced ??= new Map();
  if (g.reduced.has(k)) return g.reduced.get(k);
  const src = new OffscreenCanvas(g.image.width, g.image.height).getContext("2d");
  src.drawImage(g.image, 0, 0);
  const { data } = src.getImageData(0, 0, g.image.width, g.image.height);
  const [w, h] = [Math.ceil(g.image.width / k), Math.ceil(g.image.height / k)];
  const out = new ImageData(w, h);
  for (let by = 0; by < h; by++) {
    for (let bx = 0; bx < w; bx++) {
      let v = UNKNOWN;
      for (let y = by * k; y < Math.min((by + 1) * k, g.image.height) && v !== OCCUPIED; y++) {
        for (let x = bx * k; x < Math.min((bx + 1) * k, g.image.width); x++) {
          const c = data[4 * (y * g.image.width + x)];
          if (c < 100) { v = OCCUPIED; break; }
          if (c > 230) v = FREE;
        }
      }
      const o = 4 * (by * w + bx);
      out.data[o] = out.data[o + 1] = out.data[o + 2] = v;
      out.data[o + 3] = 255;
    }
  }
  const canvas = new OffscreenCanvas(w, h);
  canvas.getContext("2d").putImageData(out, 0, 0);
  g.reduced.set(k, canvas);
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
    const picture = k > 1 ? reduced(g, k) : g.image;
    // A reduced picture's last blocks may reach past the grid: its own size, in cells.
    const cellM = g.resolution_m * (k > 1 ? k : 1);
    ctx.imageSmoothingEnabled = false;
    ctx.drawImage(picture, x0, y0, picture.width * cellM * view.scale, picture.height * cellM * view.scale);
  }
  ctx.globalAlpha = 1;
  ctx.globalCompositeOperation = "source-over";
}

// The base map under the grid, when the mapper's config names one (`[http.base_map]`, read
// from /api/v1/dashboard; none by default: sites are often offline). Its XYZ tiles (Web
// Mercator, 256 px) are fetched by the browser at the zoom whose pixels are closest to the
// screen's, and each is drawn into the box its corners make in the map's east-north frame
// (through the fleet's datum): over one tile the two planes differ by far less than a pixel.

import { apiFetch, state, view, ctx, redraw } from "./state.js";
import { enuToGeodetic, geodeticToEnu } from "./geo.js";
import { visibleBox } from "./view.js";

const TILE_PX = 256;
const EARTH_RADIUS_M = 6378137; // Web Mercator's sphere
const MAX_TILES = 256; // kept, the oldest dropped first
const MAX_TILES_ON_SCREEN = 64;
const tiles = new Map(); // "z/x/y" -> { image, ok }

/// Reads the dashboard's settings: shows the base map's toggle and credit when there is one.
export async function loadBaseMap() {
  const r = await apiFetch("/dashboard");
  if (!r.ok) throw new Error(`dashboard settings: ${r.status} ${(await r.text()).trim()}`);
  state.baseMap = (await r.json()).base_map;
  document.getElementById("base-map-toggle").hidden = !state.baseMap;
  document.getElementById("attribution").textContent = state.baseMap?.attribution ?? "";
  redraw();
}

// The tile (x, y) holding a WGS84 position at zoom z (the slippy-map formula).
function tileAt(latDeg, lonDeg, z) {
  const n = 2 ** z;
  const lat = (latDeg * Math.PI) / 180;
  const x = ((lonDeg + 180) / 360) * n;
  const y = ((1 - Math.log(Math.tan(lat) + 1 / Math.cos(lat)) / Math.PI) / 2) * n;
  return [Math.floor(x), Math.floor(y)];
}

// The WGS84 position of tile corner (x, y) at zoom z.
function cornerOf(x, y, z) {
  const n = 2 ** z;
  const lat = Math.atan(Math.sinh(Math.PI * (1 - (2 * y) / n)));
  return { latitude_deg: (lat * 180) / Math.PI, longitude_deg: (x / n) * 360 - 180, height_m: 0 };
}

function tile(z, x, y) {
  const key = `${z}/${x}/${y}`;
  let t = tiles.get(key);
  if (t) return t;
  const url = state.baseMap.url.replace("{z}", z).replace("{x}", x).replace("{y}", y);
  t = { image: new Image(), ok: false };
  t.image.crossOrigin = "anonymous"; // the canvas stays readable
  t.image.onload = () => {
    t.ok = true;
    state.baseMapTiles += 1;
    redraw();
  };
  t.image.src = url;
  tiles.set(key, t);
  if (tiles.size > MAX_TILES) tiles.delete(tiles.keys().next().value);
  return t;
}

/// The base map's tiles on screen (the frame's first layer), when shown.
export function drawBaseMap() {
  const base = state.baseMap;
  const datum = state.summary?.datum;
  if (!base || !state.showBaseMap || !datum) return;
  const [x0, y0, x1, y1] = visibleBox(view, 0);
  const sw = enuToGeodetic(datum, x0, y0);
  const ne = enuToGeodetic(datum, x1, y1);
  const metresPerPx = 1 / (view.scale * (window.devicePixelRatio || 1));
  const ground = (2 * Math.PI * EARTH_RADIUS_M * Math.cos((datum.latitude_deg * Math.PI) / 180)) / TILE_PX;
  const z = Math.max(0, Math.min(base.max_zoom, Math.round(Math.log2(ground / metresPerPx))));
  const [tx0, ty0] = tileAt(ne.latitude_deg, sw.longitude_deg, z);
  const [tx1, ty1] = tileAt(sw.latitude_deg, ne.longitude_deg, z);
  if ((tx1 - tx0 + 1) * (ty1 - ty0 + 1) > MAX_TILES_ON_SCREEN) return;
  state.baseMapZoom = z;
  for (let ty = ty0; ty <= ty1; ty++) {
    for (let tx = tx0; tx <= tx1; tx++) {
      const t = tile(z, tx, ty);
      if (!t.ok) continue;
      const nw = geodeticToEnu(datum, cornerOf(tx, ty, z));
      const se = geodeticToEnu(datum, cornerOf(tx + 1, ty + 1, z));
      const [sx0, sy0] = view.toScreen(nw[0], nw[1]);
      const [sx1, sy1] = view.toScreen(se[0], se[1]);
      // Half a pixel more each way: neighbours overlap instead of leaving a seam between them.
      ctx.drawImage(t.image, sx0 - 0.5, sy0 - 0.5, sx1 - sx0 + 1, sy1 - sy0 + 1);
    }
  }
}

// The map camera: world metres (x east, y north) to canvas pixels, pan, zoom, scale bar, and
// the world box a view shows (for culling).

export class View {
  constructor() {
    this.cx = 0; // world point at the canvas centre (m)
    this.cy = 0;
    this.scale = 4; // pixels per metre
    this.width = 1; // canvas size in CSS pixels
    this.height = 1;
  }

  toScreen(x, y) {
    return [this.width / 2 + (x - this.cx) * this.scale, this.height / 2 - (y - this.cy) * this.scale];
  }

  toWorld(sx, sy) {
    return [this.cx + (sx - this.width / 2) / this.scale, this.cy - (sy - this.height / 2) / this.scale];
  }

  pan(dxPx, dyPx) {
    this.cx -= dxPx / this.scale;
    this.cy += dyPx / this.scale;
  }

  /// Zoom by `factor` keeping the world point under (sx, sy) in place.
  zoomAt(sx, sy, factor) {
    const [wx, wy] = this.toWorld(sx, sy);
    this.scale = Math.min(500, Math.max(0.02, this.scale * factor));
    const [nx, ny] = this.toWorld(sx, sy);
    this.cx += wx - nx;
    this.cy += wy - ny;
  }

  /// Frame the box [minX, minY, maxX, maxY] with a margin.
  fit(box) {
    if (!box) return;
    const [x0, y0, x1, y1] = box;
    this.cx = (x0 + x1) / 2;
    this.cy = (y0 + y1) / 2;
    const w = Math.max(x1 - x0, 10);
    const h = Math.max(y1 - y0, 10);
    this.scale = Math.min((this.width * 0.85) / w, (this.height * 0.85) / h);
  }
}

/// A scale bar length (m) of 1, 2 or 5 times a power of ten, about `targetPx` long.
export function scaleBarMetres(scale, targetPx = 120) {
  const raw = targetPx / scale;
  const p = 10 ** Math.floor(Math.log10(raw));
  for (const m of [5, 2, 1]) {
    if (m * p <= raw) return m * p;
  }
  return p;
}

export function formatMetres(m) {
  return m >= 1000 ? `${m / 1000} km` : m >= 1 ? `${m} m` : `${Math.round(m * 100)} cm`;
}

// The world box a view shows, with a margin of `px` pixels: what lies outside is not drawn.
export function visibleBox(v, px = 20) {
  const [x0, y1] = v.toWorld(-px, -px);
  const [x1, y0] = v.toWorld(v.width + px, v.height + px);
  return [x0, y0, x1, y1];
}

export const inBox = (b, x, y) => x >= b[0] && x <= b[2] && y >= b[1] && y <= b[3];
// Whether the segment's bounding box meets the box (cheap and conservative).
export const segInBox = (b, ax, ay, bx, by) =>
  Math.max(ax, bx) >= b[0] && Math.min(ax, bx) <= b[2] && Math.max(ay, by) >= b[1] && Math.min(ay, by) <= b[3];

"""The mapper's GeoTIFF and XYZ tiles read by another implementation: rasterio (GDAL, PROJ).

Usage: geo_check.py HTTP FLEET DATUM_JSON LANDMARKS_JSON OUT_DIR

DATUM_JSON is {"latitude_deg", "longitude_deg", "height_m"}; LANDMARKS_JSON a list of
{"east_m", "north_m", "radius_m"}: upright cylinders (trunks, posts) the robots passed, in the
datum's east-north frame, from the simulator's truth. The east-north frame is PROJ's
orthographic projection on the WGS84 ellipsoid at the datum (EPSG method 9840: the tangent
plane), so no levelmap code places a landmark on the Earth. Prints one JSON line of figures;
exits non-zero on a failed check.
"""
import json
import math
import os
import sys
import urllib.request
import warnings

import numpy as np
import rasterio
from rasterio.errors import NotGeoreferencedWarning
from rasterio.crs import CRS
from rasterio.warp import transform

http, fleet, datum, landmarks, out = sys.argv[1:6]
datum = json.loads(datum)
landmarks = json.loads(landmarks)
enu = CRS.from_proj4(
    f"+proj=ortho +lat_0={datum['latitude_deg']} +lon_0={datum['longitude_deg']} "
    "+ellps=WGS84 +units=m +no_defs"
)
GRID_CELL_M = 0.1  # the map's cell: map.tif's default resolution
# A landmark with an occupied point this close (m) is one the map shows: its nearest occupied
# point must then be within one cell of its surface, or the map is misplaced.
SHOWN_WITHIN_M = 1.0
failures = []
# The tiles are plain PNGs: GDAL reads them without a place on the Earth, as it should.
warnings.filterwarnings("ignore", category=NotGeoreferencedWarning)


def check(ok, what):
    if not ok:
        failures.append(what)


def fetch(path, name):
    with urllib.request.urlopen(f"http://{http}/api/v1/fleets/{fleet}/{path}", timeout=60) as r:
        assert r.status == 200, (path, r.status)
        data = r.read()
    file = os.path.join(out, name)
    with open(file, "wb") as f:
        f.write(data)
    return file


def to_lonlat(east, north):
    lon, lat = transform(enu, "EPSG:4326", list(east), list(north))
    return np.array(lon), np.array(lat)


def to_enu(lon, lat):
    e, n = transform("EPSG:4326", enu, list(lon), list(lat))
    return np.array(e), np.array(n)


# The GeoTIFF: its size, CRS, transform and no-data value, as GDAL reads them.
placement = json.loads(urllib.request.urlopen(f"http://{http}/api/v1/fleets/{fleet}/map.json").read())
tif = rasterio.open(fetch("map.tif", "map.tif"))
band = tif.read(1)
t = tif.transform
lat0 = math.radians(datum["latitude_deg"])
cell_lon = GRID_CELL_M / (111_320.0 * math.cos(lat0))
figures = {
    "size": [tif.width, tif.height],
    "grid_size": [placement["width"], placement["height"]],
    "crs": tif.crs.to_string(),
    "transform": list(t)[:6],
    "nodata": tif.nodata,
}
check(tif.crs == CRS.from_epsg(4326), f"CRS {tif.crs}")
check(tif.count == 1 and band.dtype == np.uint8, "one 8-bit band")
check(tif.nodata == 205, f"no-data {tif.nodata}")
check(t.b == 0 and t.d == 0 and t.a > 0 and t.e < 0, f"a north-up transform {t}")
check(abs(t.a / cell_lon - 1) < 0.01, f"pixel width {t.a}° against {cell_lon}° for 0.1 m")
check(
    0 <= tif.width - placement["width"] <= 4 and 0 <= tif.height - placement["height"] <= 4,
    f"{tif.width} × {tif.height} pixels for a grid of {placement['width']} × {placement['height']}",
)
values = set(np.unique(band).tolist())
check(values <= {0, 205, 254}, f"grey levels {values}")

# Each landmark: the nearest occupied pixel to its WGS84 place, in metres from its surface.
occupied_rows, occupied_cols = np.nonzero(band == 0)
occ_lon, occ_lat = rasterio.transform.xy(t, occupied_rows, occupied_cols)
occ_e, occ_n = to_enu(np.atleast_1d(occ_lon), np.atleast_1d(occ_lat))
land_lon, land_lat = to_lonlat([l["east_m"] for l in landmarks], [l["north_m"] for l in landmarks])


def surface_gap(e, n, landmark):
    """How far beyond the landmark's surface its nearest occupied point lies (m)."""
    d = np.hypot(e - landmark["east_m"], n - landmark["north_m"])
    return float(np.min(d)) - landmark["radius_m"] if len(d) else math.inf


# The landmarks in the map's own grid at a cell size (map.png, placed by map.json in the
# east-north frame): what the map shows there before it is put on the Earth. A grid of
# another cell size is another picture (a trunk seen by few beams may show in one only).
def local_gaps(cell):
    query = f"?resolution_m={cell}"
    placed = json.loads(urllib.request.urlopen(f"http://{http}/api/v1/fleets/{fleet}/map.json{query}").read())
    grey = rasterio.open(fetch("map.png" + query, f"map-{cell}.png")).read(1)
    rows, cols = np.nonzero(grey == 0)
    (ox, oy), res = placed["origin_m"], placed["resolution_m"]
    e = ox + (cols + 0.5) * res
    n = oy + (placed["height"] - rows - 0.5) * res
    return [surface_gap(e, n, l) for l in landmarks]


def check_placed(gaps, cell, where):
    local = local_gaps(cell)
    """Each landmark the map shows is as far from its surface on the Earth as in the map's own
    grid, within one cell; and within one cell and the map's own error (0.2 m, what the map's
    score calls found) of its true WGS84 place."""
    shown = [(g, lg) for g, lg in zip(gaps, local) if lg <= SHOWN_WITHIN_M]
    moved = [round(g - lg, 3) for g, lg in shown if abs(g - lg) > cell]
    off = [round(g, 3) for g, _ in shown if g > cell + 0.2]
    check(len(shown) >= 5 and not moved and not off,
          f"{where}: {len(shown)} landmarks shown, moved from the map's grid by {moved}, off the truth by {off}")
    return {"shown": len(shown), "largest_shift_m": round(max((abs(g - lg) for g, lg in shown), default=0.0), 3),
            "largest_gap_m": round(max((g for g, _ in shown), default=0.0), 3)}


tif_gaps = [surface_gap(occ_e, occ_n, l) for l in landmarks]
figures["landmarks"] = len(landmarks)
figures["tif_landmarks"] = check_placed(tif_gaps, GRID_CELL_M, "GeoTIFF")
# The landmark's own pixel, by rasterio's index: a pixel next to it (one cell) is occupied.
best = int(np.argmin(tif_gaps))
row, col = tif.index(land_lon[best], land_lat[best])
reach = int(math.ceil((landmarks[best]["radius_m"] + GRID_CELL_M) / GRID_CELL_M))
window = band[max(row - reach, 0) : row + reach + 1, max(col - reach, 0) : col + reach + 1]
check((window == 0).any(), f"no occupied pixel within one cell of landmark {best}'s pixel")
figures["landmark"] = {
    "east_m": landmarks[best]["east_m"],
    "north_m": landmarks[best]["north_m"],
    "longitude_deg": float(land_lon[best]),
    "latitude_deg": float(land_lat[best]),
    "pixel": [row, col],
    "gap_m": tif_gaps[best],
}


def tile_of(lon, lat, z):
    """The slippy-map tile (x, y) and the pixel in it of a WGS84 position."""
    n = 2**z * 256
    x = (lon + 180.0) / 360.0 * n
    r = math.radians(lat)
    y = (1.0 - math.log(math.tan(r) + 1.0 / math.cos(r)) / math.pi) / 2.0 * n
    return int(x // 256), int(y // 256)


def lonlat_of(tx, ty, px, py, z):
    n = 2**z * 256
    gx, gy = tx * 256 + px, ty * 256 + py
    lon = gx / n * 360.0 - 180.0
    lat = math.degrees(math.atan(math.sinh(math.pi * (1.0 - 2.0 * gy / n))))
    return lon, lat


# The tiles at two zoom levels: each landmark drawn within one of the tile's cells of its
# place, and each occupied tile pixel within one cell of an occupied GeoTIFF pixel.
for z in (19, 21):
    pixel_m = 2 * math.pi * 6_378_137.0 * math.cos(lat0) / (2**z * 256)
    cell = GRID_CELL_M * 2 ** max(0, math.ceil(math.log2(pixel_m / GRID_CELL_M)))
    tiles = {}
    for lon, lat in zip(land_lon, land_lat):
        key = tile_of(lon, lat, z)
        if key not in tiles:
            path = fetch(f"tiles/{z}/{key[0]}/{key[1]}.png", f"tile-{z}-{key[0]}-{key[1]}.png")
            with rasterio.open(path) as png:
                check(png.count == 2 and png.width == 256 and png.height == 256, f"tile {key}: grey and alpha, 256 px")
                grey, alpha = png.read(1), png.read(2)
            rows, cols = np.nonzero((alpha == 255) & (grey == 0))
            pts = [lonlat_of(key[0], key[1], c + 0.5, r + 0.5, z) for r, c in zip(rows, cols)]
            tiles[key] = pts
    pts = [p for ps in tiles.values() for p in ps]
    e, n = to_enu([p[0] for p in pts], [p[1] for p in pts]) if pts else (np.array([]), np.array([]))
    gaps = [surface_gap(e, n, l) for l in landmarks]
    figures[f"z{z}"] = {"tiles": len(tiles), "occupied_pixels": len(pts), "cell_m": cell,
                        "landmarks": check_placed(gaps, cell, f"z {z}")}
    # Line-up: an occupied GeoTIFF pixel within one tile cell of each occupied tile pixel.
    lined_up = 0
    for pe, pn in zip(e, n):
        d = np.hypot(occ_e - pe, occ_n - pn)
        lined_up += bool(len(d) and d.min() <= cell + GRID_CELL_M)
    share = lined_up / max(len(pts), 1)
    figures[f"z{z}"]["lined_up_with_tif"] = round(share, 4)
    check(len(pts) > 0 and share >= 0.95, f"z {z}: {share:.3f} of occupied tile pixels line up with the GeoTIFF")

print(json.dumps(figures))
if failures:
    sys.exit("geo_check: " + "; ".join(failures))

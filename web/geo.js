// Local map metres (x east, y north, on the datum's tangent plane) to WGS84, the same way the
// mapper converts (slam::geodesy): ENU -> Earth-centred Earth-fixed -> geodetic on the WGS84
// ellipsoid. Exact up to floating point, so millimetres over kilometres.

const A = 6378137.0; // WGS84 semi-major axis (m)
const F = 1 / 298.257223563; // WGS84 flattening
const E2 = F * (2 - F);
const RAD = Math.PI / 180;

function toEcef(latDeg, lonDeg, h) {
  const lat = latDeg * RAD;
  const lon = lonDeg * RAD;
  const n = A / Math.sqrt(1 - E2 * Math.sin(lat) ** 2);
  return [(n + h) * Math.cos(lat) * Math.cos(lon), (n + h) * Math.cos(lat) * Math.sin(lon), (n * (1 - E2) + h) * Math.sin(lat)];
}

function fromEcef([x, y, z]) {
  const lon = Math.atan2(y, x);
  const rho = Math.hypot(x, y);
  let lat = Math.atan2(z, rho * (1 - E2));
  let h = 0;
  for (let i = 0; i < 6; i++) {
    const n = A / Math.sqrt(1 - E2 * Math.sin(lat) ** 2);
    h = rho / Math.cos(lat) - n;
    lat = Math.atan2(z, rho * (1 - (E2 * n) / (n + h)));
  }
  return { latitude_deg: lat / RAD, longitude_deg: lon / RAD, height_m: h };
}

/// WGS84 position of the local point (east, north, up) metres, for a datum
/// {latitude_deg, longitude_deg, height_m} (the summary's `datum`).
export function enuToGeodetic(datum, east, north, up = 0) {
  const lat = datum.latitude_deg * RAD;
  const lon = datum.longitude_deg * RAD;
  const [sl, cl] = [Math.sin(lat), Math.cos(lat)];
  const [so, co] = [Math.sin(lon), Math.cos(lon)];
  const o = toEcef(datum.latitude_deg, datum.longitude_deg, datum.height_m);
  // Columns of the ENU -> ECEF rotation: east, north, up unit vectors.
  return fromEcef([
    o[0] - so * east - sl * co * north + cl * co * up,
    o[1] + co * east - sl * so * north + cl * so * up,
    o[2] + cl * north + sl * up,
  ]);
}

/// Local (east, north) metres of a WGS84 position {latitude_deg, longitude_deg} on the datum's
/// ellipsoid height: the inverse of enuToGeodetic.
export function geodeticToEnu(datum, g) {
  const lat = datum.latitude_deg * RAD;
  const lon = datum.longitude_deg * RAD;
  const [sl, cl] = [Math.sin(lat), Math.cos(lat)];
  const [so, co] = [Math.sin(lon), Math.cos(lon)];
  const o = toEcef(datum.latitude_deg, datum.longitude_deg, datum.height_m);
  const p = toEcef(g.latitude_deg, g.longitude_deg, datum.height_m);
  const d = [p[0] - o[0], p[1] - o[1], p[2] - o[2]];
  return [-so * d[0] + co * d[1], -sl * co * d[0] - sl * so * d[1] + cl * d[2]];
}

/// 52.390012° N, 9.710034° E
export function formatLatLon(g) {
  const lat = `${Math.abs(g.latitude_deg).toFixed(7)}° ${g.latitude_deg >= 0 ? "N" : "S"}`;
  const lon = `${Math.abs(g.longitude_deg).toFixed(7)}° ${g.longitude_deg >= 0 ? "E" : "W"}`;
  return `${lat}, ${lon}`;
}

//! WGS84 geodesy for GPS constraints: conversions between geodetic positions and a local
//! east-north-up frame (x east, y north, z up, metres) around a map datum. Conversions go
//! exactly through Earth-centred Earth-fixed coordinates on the WGS84 ellipsoid
//! (millimetre-exact over the park).

use nalgebra::{Matrix3, Vector3};

/// WGS84 semi-major axis (m).
const WGS84_A: f64 = 6_378_137.0;
/// WGS84 flattening.
const WGS84_F: f64 = 1.0 / 298.257_223_563;

/// A geodetic position on the WGS84 ellipsoid.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Geodetic {
    /// Latitude (degrees, north positive).
    pub latitude_deg: f64,
    /// Longitude (degrees, east positive).
    pub longitude_deg: f64,
    /// Height above the ellipsoid (m).
    pub height_m: f64,
}

/// The origin of the local ENU frame.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GeoDatum {
    /// The datum: where the ENU frame's origin is, on the ellipsoid.
    pub origin: Geodetic,
}

fn e2() -> f64 {
    WGS84_F * (2.0 - WGS84_F)
}

fn to_ecef(g: &Geodetic) -> Vector3<f64> {
    let (lat, lon) = (g.latitude_deg.to_radians(), g.longitude_deg.to_radians());
    let n = WGS84_A / (1.0 - e2() * lat.sin().powi(2)).sqrt();
    Vector3::new(
        (n + g.height_m) * lat.cos() * lon.cos(),
        (n + g.height_m) * lat.cos() * lon.sin(),
        (n * (1.0 - e2()) + g.height_m) * lat.sin(),
    )
}

fn from_ecef(p: &Vector3<f64>) -> Geodetic {
    let lon = p.y.atan2(p.x);
    let rho = p.x.hypot(p.y);
    // Fixed-point iteration on the latitude; converges to < 1e-12 rad in a few rounds.
    let mut lat = p.z.atan2(rho * (1.0 - e2()));
    let mut height = 0.0;
    for _ in 0..6 {
        let n = WGS84_A / (1.0 - e2() * lat.sin().powi(2)).sqrt();
        height = rho / lat.cos() - n;
        lat = p.z.atan2(rho * (1.0 - e2() * n / (n + height)));
    }
    Geodetic {
        latitude_deg: lat.to_degrees(),
        longitude_deg: lon.to_degrees(),
        height_m: height,
    }
}

impl GeoDatum {
    /// Rows: east, north, up unit vectors in ECEF at the datum.
    fn ecef_to_enu(&self) -> Matrix3<f64> {
        let (lat, lon) = (
            self.origin.latitude_deg.to_radians(),
            self.origin.longitude_deg.to_radians(),
        );
        let (sl, cl) = lat.sin_cos();
        let (so, co) = lon.sin_cos();
        Matrix3::new(-so, co, 0.0, -sl * co, -sl * so, cl, cl * co, cl * so, sl)
    }

    /// WGS84 position of a point given in local ENU metres.
    pub fn enu_to_geodetic(&self, enu_m: &Vector3<f64>) -> Geodetic {
        from_ecef(&(to_ecef(&self.origin) + self.ecef_to_enu().transpose() * enu_m))
    }

    /// Local ENU metres of a WGS84 position.
    pub fn geodetic_to_enu(&self, g: &Geodetic) -> Vector3<f64> {
        self.ecef_to_enu() * (to_ecef(g) - to_ecef(&self.origin))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_point_converts_exactly() {
        // The datum's own origin is ENU zero; a point 100 m up is straight above it.
        let d = GeoDatum {
            origin: Geodetic {
                latitude_deg: -33.8568,
                longitude_deg: 151.2153,
                height_m: 10.0,
            },
        };
        let up = d.geodetic_to_enu(&Geodetic {
            height_m: 110.0,
            ..d.origin
        });
        assert!(
            up.x.abs() < 1e-6 && up.y.abs() < 1e-6 && (up.z - 100.0).abs() < 1e-6,
            "{up}"
        );
    }

    #[test]
    fn round_trip_and_scale() {
        // A datum near Hannover (52.39° N, 9.71° E, 55 m).
        let d = GeoDatum {
            origin: Geodetic {
                latitude_deg: 52.39,
                longitude_deg: 9.71,
                height_m: 55.0,
            },
        };
        let o = d.enu_to_geodetic(&Vector3::zeros());
        assert!((o.latitude_deg - 52.39).abs() < 1e-10 && (o.height_m - 55.0).abs() < 1e-6);
        for enu in [
            Vector3::new(80.0, -60.0, 3.0),
            Vector3::new(-1000.0, 2500.0, -10.0),
        ] {
            let back = d.geodetic_to_enu(&d.enu_to_geodetic(&enu));
            assert!((back - enu).norm() < 1e-6, "{back} vs {enu}");
        }
        // 1 km north is about 0.009° of latitude; 1 km east about 0.0147° of longitude here.
        let north = d.enu_to_geodetic(&Vector3::new(0.0, 1000.0, 0.0));
        assert!((north.latitude_deg - 52.39 - 0.008_987).abs() < 2e-5);
        let east = d.enu_to_geodetic(&Vector3::new(1000.0, 0.0, 0.0));
        assert!(
            (east.longitude_deg - 9.71 - 0.014_71).abs() < 5e-5,
            "{}",
            east.longitude_deg - 9.71
        );
    }
}

//! The park's map datum. The conversions between local ENU metres and WGS84 are
//! `slam::geodesy`'s (one implementation for the simulator and the mapper).

pub use slam::geodesy::{GeoDatum, Geodetic};

/// The park's datum: near the Georgengarten, Hannover (52.39° N, 9.71° E, 55 m).
pub const PARK_DATUM: GeoDatum = GeoDatum {
    origin: Geodetic {
        latitude_deg: 52.39,
        longitude_deg: 9.71,
        height_m: 55.0,
    },
};

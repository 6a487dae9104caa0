//! A deterministic synthetic outdoor world with sensors and ground truth, for levelmap's
//! tests and demos (after Wulf, Brenneke & Wagner, "Using 3D Laser Range Data for SLAM in
//! Outdoor Environments").
//!
//! Pure library but for [`scan_file`] (the simulator's scan files, JSON): no other file I/O,
//! no threads; everything is fixed by a seed ([`Rng`], our own
//! generator, so results never change with a dependency's version).
//!
//! # The park ([`World::park`])
//!
//! World frame: local east-north-up, x east, y north, z up along gravity, metres, origin at
//! [`PARK_DATUM`] (near Hannover). The park spans 160 m × 120 m:
//!
//! ```text
//!  y=60 +--------------------------------------------------------------------------------+
//!       |                 ####################################                           |
//!       |                                                                                |
//!       |     #####             2222222222222222222222222222                             |
//!       |     #####            2211111111                   2       CC C  CC             |
//!       |                    22211       11111              2                            |
//!       |               111112     ^^^^^^^^   1             2                            |
//!       |             111    22   ^^^PPPP^^^  1            22 :::            ^^^         |
//!       |            11       22   ^^^PP^^^^  1      2222222 :::::      ^^^^^^^^^^^^     |
//!       |           11         22            22222222        :::::    ^^^^^^^^^^^^^^^^   |
//!  y=0  |          11           222 222222222 1  000000000=============000000^^^^^^^^^   |
//!       |          1              222         1  0           :::::     ^^^^^0^^^^^^^^^   |
//!       |          111                       11  00          :::::       ^^^0^^^^^^      |
//!       |            111vvvv                11    0          :::::          0            |
//!       |           vvv1111vvv            111     00          ::::          0            |
//!       |            vvvvvv11111       111         00000000000000000000000000            |
//!       |     ####             111111111                  #                              |
//!       |        ####                                  ####                              |
//!       |                                           ####                                 |
//!       |                                        ####                                    |
//! y=-60 +--------------------------------------------------------------------------------+
//!      x=-80                                    x=0                                     x=80
//!
//!  ^ ground above 2 m (pavilion hill, east hill)   v dell   : ravine   P pavilion
//!  = bridge   # walls (garden wall, shed, south-west wall, the test wall)   C cars
//!  0 1 2 footpath loops; trees, bushes and lamp posts are scattered off the paths
//! ```
//!
//! - **Terrain**: a smooth height field, a sum of Gaussian bumps ([`Terrain`]); steepest
//!   slope about 20°. The pavilion hill (4.5 m, σ 8 m) carries the **pavilion**: eight
//!   round pillars (landmarks) under a flat round roof that overhangs them. The **dell** is a
//!   hollow 2.5 m deep with trees, bushes and a lamp in it. A north–south **ravine** (3 m)
//!   runs between the middle of the park and the east hill.
//! - **Bridge** ([`Bridge`]): 24 m long, climbing 2 m, crosses the ravine: a drivable deck
//!   (ramp) with side beams, posts and rails (landmarks) and 3 m of room under its middle.
//! - **Objects**: trees (trunk r 0.15–0.3 m, 2–3 m; ellipsoid crown 1.5–3 m wide, an
//!   overhang), lamp posts, walls (a long straight test wall in the flat south, a garden
//!   wall on the north edge, a shed), five parked cars, bushes.
//! - **Footpaths**: three overlapping closed loops ([`Route::park_loop`]); loop 0 crosses
//!   the bridge, loop 1 passes the foot of the pavilion hill and runs through the dell.
//!
//! [`World::raycast`] returns the first surface along a ray with its [`SurfaceKind`].
//!
//! # Sensors ([`sensors`])
//!
//! The paper's yawing 3D scanner ([`YawingScanner`]: 270° × 100°, 27,000 points in 4 s,
//! each column measured from the robot's true pose at its own time), a chassis-fixed
//! horizontal 2D laser ([`FixedScanner2d`]), 3D dead reckoning ([`DeadReckoning`]) and GPS
//! ([`Gps`]). [`scenario`] packs ready-made scans ([`SimScanFile`]).

pub mod fleet;
pub mod geodesy;
mod park;
pub mod rng;
pub mod robot;
pub mod scan_file;
pub mod scenario;
pub mod sensors;
pub mod shape;
pub mod terrain;
pub mod world;

pub use fleet::{FleetRobot, FleetScan, FleetStart};
pub use geodesy::{GeoDatum, Geodetic, PARK_DATUM};
pub use rng::Rng;
pub use robot::{RobotBody, Route};
pub use scenario::{SimFileError, SimScanFile, demo_scan, pavilion_hill_scan, wall_drive_scan};
pub use sensors::{Beam2d, DeadReckoning, FixedScanner2d, Gps, GpsFix, SimScan, YawingScanner};
pub use shape::{Cuboid, Ellipsoid, Shape, VerticalCylinder};
pub use terrain::{Bump, GroundBounds, Terrain};
pub use world::{Bridge, Hit, Part, Places, SurfaceKind, WallLine, World};

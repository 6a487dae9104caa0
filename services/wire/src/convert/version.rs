//! Map versions (`map_version.proto`): a fleet's map frozen, as one file. Written by the
//! mapper, read back by it and by `levelmap map import` through [`decode_map_version_file`],
//! which checks the whole file once: its format version, its checksum, then every number.

use super::decode;
use super::pose::{pose2_from_wire, pose2_to_wire};
use super::scan::check_beam;
use crate::error::{MAX_RANGE_M, bounded, coordinate, within};
use crate::{Message, WireError, v1, validate_id};
use slam::geodesy::{GeoDatum, Geodetic};
use slam::{OccupancyGrid, Pose2};

/// The format version a [`v1::MapVersionFile`] carries; readers reject any other.
pub const MAP_VERSION_FORMAT: u32 = 1;
/// What `MapVersionFile.message` names.
pub const MAP_VERSION_MESSAGE: &str = "levelmap.v1.MapVersion";
/// The largest version file written or read (bytes): about 30,000 nodes of 1,000 beams with
/// a full grid. A bigger map is refused when frozen, not when it is imported elsewhere.
pub const MAX_MAP_VERSION_BYTES: usize = 256 << 20;
/// The most nodes a version holds.
pub const MAX_MAP_VERSION_NODES: usize = 1 << 20;
/// The most cells of a version's grid (the mapper's grids stop at 2²⁴).
pub const MAX_MAP_VERSION_CELLS: usize = 1 << 26;

/// A fleet's map frozen, checked: what a version holds.
#[derive(Clone, Debug, PartialEq)]
pub struct MapVersion {
    /// The fleet.
    pub fleet: String,
    /// Its number in the fleet, from 1.
    pub number: u64,
    /// When the map was frozen (ns since the Unix epoch).
    pub created_ns: u64,
    /// The origin of the map's east-north frame, if it has one.
    pub datum: Option<GeoDatum>,
    /// Relative edges of the network when frozen.
    pub edges: u64,
    /// GPS edges of the network when frozen.
    pub gps_edges: u64,
    /// Loop closures among the relative edges.
    pub loop_closures: u64,
    /// Every node, in map order.
    pub nodes: Vec<VersionNode>,
    /// The occupancy grid of the nodes' scans at their poses.
    pub grid: OccupancyGrid,
    /// Where it came from, when imported.
    pub imported_from: Option<VersionOrigin>,
}

/// One node of a frozen map: its pose and its leveled scan.
#[derive(Clone, Debug, PartialEq)]
pub struct VersionNode {
    /// The robot that sent it.
    pub robot: String,
    /// The robot's chain.
    pub chain_id: u64,
    /// Its number in the chain.
    pub node_seq: u64,
    /// The scan's start (ns since the Unix epoch).
    pub stamp_ns: u64,
    /// The scan frame in the map frame.
    pub pose: Pose2,
    /// Bearing of each beam (rad).
    pub bearings_rad: Vec<f32>,
    /// Range of each beam (m, 0 = no return).
    pub ranges_m: Vec<f32>,
}

impl VersionNode {
    /// The scan as matching uses it, cut at `max_range_m` ([`super::matching_scan`]'s rule).
    pub fn matching_scan(&self, max_range_m: f32) -> slam::matching::Scan2 {
        super::localization::scan_of_returns(self.returns(), max_range_m)
    }

    /// The beams with a return, as (bearing in rad, range in m).
    pub fn returns(&self) -> impl Iterator<Item = (f32, f32)> + '_ {
        self.bearings_rad
            .iter()
            .zip(&self.ranges_m)
            .filter(|(_, r)| **r > 0.0)
            .map(|(b, r)| (*b, *r))
    }
}

/// Where an imported version came from.
#[derive(Clone, Debug, PartialEq)]
pub struct VersionOrigin {
    /// Its fleet in the mapper it was exported from.
    pub fleet: String,
    /// Its number there.
    pub number: u64,
    /// When it was imported (ns since the Unix epoch).
    pub imported_ns: u64,
}

/// The version as its message.
pub fn map_version_to_wire(version: &MapVersion) -> v1::MapVersion {
    let g = &version.grid;
    v1::MapVersion {
        fleet_id: version.fleet.clone(),
        number: version.number,
        created_ns: version.created_ns,
        datum: version.datum.map(|d| v1::GeoDatum {
            latitude_deg: d.origin.latitude_deg,
            longitude_deg: d.origin.longitude_deg,
            height_m: d.origin.height_m,
        }),
        edges: version.edges,
        gps_edges: version.gps_edges,
        loop_closures: version.loop_closures,
        nodes: version
            .nodes
            .iter()
            .map(|n| v1::VersionNode {
                robot_id: n.robot.clone(),
                chain_id: n.chain_id,
                node_seq: n.node_seq,
                stamp_ns: n.stamp_ns,
                pose: Some(pose2_to_wire(&n.pose)),
                bearing_rad: n.bearings_rad.clone(),
                range_m: n.ranges_m.clone(),
            })
            .collect(),
        grid: Some(v1::VersionGrid {
            resolution_m: g.resolution_m,
            origin_x_m: g.origin_m[0],
            origin_y_m: g.origin_m[1],
            width: u32::try_from(g.width).unwrap_or(u32::MAX),
            height: u32::try_from(g.height).unwrap_or(u32::MAX),
            // -1 (never seen) is 255 as a byte.
            occupancy_percent: g.cells.iter().map(|&c| c as u8).collect(),
            occupied_percent: g.occupied_percent.max(0) as u32,
            free_percent: g.free_percent.max(0) as u32,
        }),
        imported_from: version.imported_from.as_ref().map(|o| v1::VersionOrigin {
            fleet_id: o.fleet.clone(),
            number: o.number,
            imported_ns: o.imported_ns,
        }),
    }
}

/// The version as one file (a [`v1::MapVersionFile`]); refused over [`MAX_MAP_VERSION_BYTES`].
pub fn encode_map_version_file(version: &MapVersion) -> Result<Vec<u8>, WireError> {
    let body = map_version_to_wire(version).encode_to_vec();
    let file = v1::MapVersionFile {
        format_version: MAP_VERSION_FORMAT,
        message: MAP_VERSION_MESSAGE.to_owned(),
        map_version_crc32: crc32(&body),
        map_version: body,
    }
    .encode_to_vec();
    check_file_size(file.len())?;
    Ok(file)
}

/// Decodes and checks a version file: its size, format version, message, checksum, then
/// every field of the version ([`map_version_from_wire`]).
pub fn decode_map_version_file(bytes: &[u8]) -> Result<MapVersion, WireError> {
    check_file_size(bytes.len())?;
    let file: v1::MapVersionFile = decode("MapVersionFile", bytes)?;
    if file.format_version != MAP_VERSION_FORMAT {
        return Err(WireError::Version {
            field: "MapVersionFile.format_version",
            found: file.format_version,
        });
    }
    if file.message != MAP_VERSION_MESSAGE {
        return Err(WireError::Invalid {
            field: "MapVersionFile.message",
            detail: format!("holds {:?}, not {MAP_VERSION_MESSAGE}", file.message),
        });
    }
    if file.map_version.is_empty() {
        return Err(WireError::Missing {
            field: "MapVersionFile.map_version",
        });
    }
    let crc = crc32(&file.map_version);
    if crc != file.map_version_crc32 {
        return Err(WireError::Invalid {
            field: "MapVersionFile.map_version_crc32",
            detail: format!(
                "the content's CRC-32 is {crc:08x}, the file says {:08x}: the file is damaged \
                 or cut short",
                file.map_version_crc32
            ),
        });
    }
    map_version_from_wire(&decode("MapVersion", &file.map_version)?)
}

fn check_file_size(len: usize) -> Result<(), WireError> {
    if len > MAX_MAP_VERSION_BYTES {
        return Err(WireError::Implausible {
            field: "MapVersionFile",
            index: None,
            value: len as f64,
            limit: MAX_MAP_VERSION_BYTES as f64,
            reason: "too_large",
        });
    }
    Ok(())
}

/// A version from its message, checked: a valid fleet id, a number from 1, at least one and
/// at most [`MAX_MAP_VERSION_NODES`] nodes (each a valid robot id, a finite pose within
/// [`crate::MAX_POSITION_M`], a scan as `LeveledScan` checks it), a datum on the ellipsoid,
/// a grid whose size matches its cells (at most [`MAX_MAP_VERSION_CELLS`]) and whose cells
/// and thresholds are per cents.
pub fn map_version_from_wire(msg: &v1::MapVersion) -> Result<MapVersion, WireError> {
    validate_id("fleet", &msg.fleet_id)?;
    if msg.number == 0 {
        return Err(WireError::Invalid {
            field: "MapVersion.number",
            detail: "0: versions are numbered from 1".into(),
        });
    }
    if msg.nodes.is_empty() || msg.nodes.len() > MAX_MAP_VERSION_NODES {
        return Err(WireError::Invalid {
            field: "MapVersion.nodes",
            detail: format!(
                "{} nodes: a version holds 1 to {MAX_MAP_VERSION_NODES}",
                msg.nodes.len()
            ),
        });
    }
    let imported_from = match &msg.imported_from {
        Some(o) => {
            validate_id("fleet", &o.fleet_id)?;
            Some(VersionOrigin {
                fleet: o.fleet_id.clone(),
                number: o.number,
                imported_ns: o.imported_ns,
            })
        }
        None => None,
    };
    Ok(MapVersion {
        fleet: msg.fleet_id.clone(),
        number: msg.number,
        created_ns: msg.created_ns,
        datum: msg.datum.as_ref().map(datum_from_wire).transpose()?,
        edges: msg.edges,
        gps_edges: msg.gps_edges,
        loop_closures: msg.loop_closures,
        nodes: msg
            .nodes
            .iter()
            .enumerate()
            .map(|(i, n)| node_from_wire(i, n))
            .collect::<Result<_, _>>()?,
        grid: grid_from_wire(msg.grid.as_ref().ok_or(WireError::Missing {
            field: "MapVersion.grid",
        })?)?,
        imported_from,
    })
}

fn datum_from_wire(d: &v1::GeoDatum) -> Result<GeoDatum, WireError> {
    Ok(GeoDatum {
        origin: Geodetic {
            latitude_deg: within("GeoDatum.latitude_deg", d.latitude_deg, 90.0)?,
            longitude_deg: within("GeoDatum.longitude_deg", d.longitude_deg, 180.0)?,
            height_m: coordinate("GeoDatum.height_m", None, d.height_m)?,
        },
    })
}

fn node_from_wire(index: usize, n: &v1::VersionNode) -> Result<VersionNode, WireError> {
    validate_id("robot", &n.robot_id)?;
    let pose = n.pose.as_ref().ok_or(WireError::Missing {
        field: "VersionNode.pose",
    })?;
    let beams = n.bearing_rad.len();
    if beams == 0 || n.range_m.len() != beams {
        return Err(WireError::Invalid {
            field: "VersionNode.range_m",
            detail: format!(
                "node {index}: {} ranges for {beams} bearings (at least one beam)",
                n.range_m.len()
            ),
        });
    }
    for (i, (&bearing, &range)) in n.bearing_rad.iter().zip(&n.range_m).enumerate() {
        check_beam(
            ("VersionNode.bearing_rad", "VersionNode.range_m"),
            i,
            bearing,
            range,
        )?;
    }
    Ok(VersionNode {
        robot: n.robot_id.clone(),
        chain_id: n.chain_id,
        node_seq: n.node_seq,
        stamp_ns: n.stamp_ns,
        pose: pose2_from_wire(pose)?,
        bearings_rad: n.bearing_rad.clone(),
        ranges_m: n.range_m.clone(),
    })
}

fn grid_from_wire(g: &v1::VersionGrid) -> Result<OccupancyGrid, WireError> {
    let resolution_m = bounded(
        "VersionGrid.resolution_m",
        None,
        g.resolution_m,
        MAX_RANGE_M,
        "implausible_resolution",
    )?;
    if resolution_m <= 0.0 {
        return Err(WireError::InvalidValue {
            field: "VersionGrid.resolution_m",
            index: None,
            value: resolution_m,
            problem: "not positive",
        });
    }
    let cells = u64::from(g.width) * u64::from(g.height);
    if cells == 0 || cells != g.occupancy_percent.len() as u64 {
        return Err(WireError::Invalid {
            field: "VersionGrid.occupancy_percent",
            detail: format!(
                "{} cells for {} × {}",
                g.occupancy_percent.len(),
                g.width,
                g.height
            ),
        });
    }
    if g.occupancy_percent.len() > MAX_MAP_VERSION_CELLS {
        return Err(WireError::Implausible {
            field: "VersionGrid.occupancy_percent",
            index: None,
            value: cells as f64,
            limit: MAX_MAP_VERSION_CELLS as f64,
            reason: "too_large",
        });
    }
    if let Some(i) = g
        .occupancy_percent
        .iter()
        .position(|&c| c > 100 && c != 255)
    {
        return Err(WireError::InvalidValue {
            field: "VersionGrid.occupancy_percent",
            index: Some(i),
            value: g.occupancy_percent[i].into(),
            problem: "not a per cent (0-100) or unknown (255)",
        });
    }
    let per_cent = |field, value: u32| {
        i8::try_from(value)
            .ok()
            .filter(|v| *v <= 100)
            .ok_or(WireError::InvalidValue {
                field,
                index: None,
                value: value.into(),
                problem: "not a per cent (0-100)",
            })
    };
    let occupied_percent = per_cent("VersionGrid.occupied_percent", g.occupied_percent)?;
    let free_percent = per_cent("VersionGrid.free_percent", g.free_percent)?;
    if free_percent >= occupied_percent {
        return Err(WireError::Invalid {
            field: "VersionGrid.free_percent",
            detail: format!("{free_percent} is not below occupied_percent {occupied_percent}"),
        });
    }
    Ok(OccupancyGrid {
        resolution_m,
        origin_m: [
            coordinate("VersionGrid.origin_x_m", None, g.origin_x_m)?,
            coordinate("VersionGrid.origin_y_m", None, g.origin_y_m)?,
        ],
        width: g.width as usize,
        height: g.height as usize,
        cells: g.occupancy_percent.iter().map(|&c| c as i8).collect(),
        occupied_percent,
        free_percent,
    })
}

/// CRC-32 (IEEE 802.3, reflected, as zip, gzip and PNG).
pub fn crc32(bytes: &[u8]) -> u32 {
    crc32fast::hash(bytes)
}

#[cfg(test)]
#[path = "version_tests.rs"]
mod tests;

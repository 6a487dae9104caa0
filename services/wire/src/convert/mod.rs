//! Conversions between the wire messages and the domain types (`leveling`, `slam`), and the
//! checks every received message passes before anything downstream sees it.

mod cloud;
#[cfg(test)]
mod fixtures;
mod gps;
mod input;
mod localization;
mod map;
mod node;
mod odometry;
mod pose;
mod scan;
mod version;

pub use cloud::{
    CLOUD_MAX_COORD_CM, CLOUD_MAX_POINTS, ClassifiedCloud, cloud_from_wire, cloud_to_wire,
    decode_cloud, point_class_from_wire, validate_cloud,
};
pub use gps::{fix_status_to_wire, gps_fix_from_wire, gps_fix_to_wire, validate_gps_fix};
pub use input::{
    LiveScan, Node, NodeParts, OdometryInput, check_step, decode_live_scan, decode_node,
    encode_odometry, node_from_wire, odometry_input,
};
pub use localization::{
    DEFAULT_PRIOR_SIGMA, LocalizeQuery, Localized, decode_localization, decode_localize_request,
    grid_fan, localization_to_wire, localize_query, matching_scan,
};
pub use map::{MapPose, decode_map_poses, decode_map_summary, map_poses_to_wire};
#[cfg(test)]
pub(crate) use node::decode_node_message;
pub use node::{
    decode_ack, decode_odometry, node_as_sent, split_node_cloud, validate_ack, validate_node,
};
pub use odometry::{odometry_from_wire, odometry_to_wire};
pub use pose::{
    pose2_from_wire, pose2_to_wire, pose2d_from_wire, pose2d_to_wire, pose3d_from_wire,
    pose3d_to_wire,
};
pub use scan::{counts_from_wire, counts_to_wire, leveled_scan_from_wire, leveled_scan_to_wire};
pub use version::{
    MAP_VERSION_FORMAT, MAP_VERSION_MESSAGE, MAX_MAP_VERSION_BYTES, MAX_MAP_VERSION_CELLS,
    MAX_MAP_VERSION_NODES, MapVersion, VersionNode, VersionOrigin, crc32, decode_map_version_file,
    encode_map_version_file, map_version_from_wire, map_version_to_wire,
};

use crate::{Message, WIRE_VERSION, WireError, v1, validate_id};

/// Returns the header if it is present, of [`WIRE_VERSION`], with valid fleet and robot ids.
/// `field` names it in errors (`"Node.header"`).
pub fn check_header<'a>(
    header: Option<&'a v1::Header>,
    field: &'static str,
) -> Result<&'a v1::Header, WireError> {
    let header = header.ok_or(WireError::Missing { field })?;
    if header.version != WIRE_VERSION {
        return Err(WireError::Version {
            field,
            found: header.version,
        });
    }
    validate_id("fleet", &header.fleet_id)?;
    validate_id("robot", &header.robot_id)?;
    Ok(header)
}

/// A nested message must come from the same fleet and robot as the message holding it.
pub(crate) fn same_sender(
    outer: &v1::Header,
    inner: &v1::Header,
    field: &'static str,
) -> Result<(), WireError> {
    if outer.fleet_id == inner.fleet_id && outer.robot_id == inner.robot_id {
        Ok(())
    } else {
        Err(WireError::Invalid {
            field,
            detail: format!(
                "sender {}/{} differs from the enclosing message's {}/{}",
                inner.fleet_id, inner.robot_id, outer.fleet_id, outer.robot_id
            ),
        })
    }
}

pub(crate) fn decode<M: Message + Default>(
    message: &'static str,
    bytes: &[u8],
) -> Result<M, WireError> {
    M::decode(bytes).map_err(|source| WireError::Decode { message, source })
}

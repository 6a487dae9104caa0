//! The one error type of the wire contract.

use std::fmt;

/// Why a message, id or key expression was rejected. Every variant names the offending field
/// (as `Message.field`) so that a rejection can be logged and counted meaningfully.
#[derive(Clone, Debug, PartialEq)]
pub enum WireError {
    /// The bytes are not a protobuf encoding of `message`.
    Decode {
        /// The message expected.
        message: &'static str,
        /// What prost said.
        source: prost::DecodeError,
    },
    /// The header's wire version is not [`crate::WIRE_VERSION`] (0: the header left it unset).
    Version {
        /// The header (`Node.header`).
        field: &'static str,
        /// The version it carries.
        found: u32,
    },
    /// A required field (a header, a scan, a pose) is absent.
    Missing {
        /// The field, as `Message.field`.
        field: &'static str,
    },
    /// A fleet or robot id is empty or has a character outside `[A-Za-z0-9_-]`.
    InvalidId {
        /// What kind of id (`fleet`, `robot`).
        kind: &'static str,
        /// The id as given.
        id: String,
    },
    /// A Zenoh key expression is not one of levelmap's.
    InvalidKey {
        /// The key as given.
        key: String,
    },
    /// One number is out of its domain (NaN, infinite, negative range, latitude beyond 90°).
    InvalidValue {
        /// The field, as `Message.field`.
        field: &'static str,
        /// The element's index in a repeated field, `None` for a singular one.
        index: Option<usize>,
        /// The value.
        value: f64,
        /// What is wrong with it.
        problem: &'static str,
    },
    /// A number that is valid but not physically plausible for a robot: a position beyond
    /// [`MAX_POSITION_M`], a range beyond [`MAX_RANGE_M`], a node larger than
    /// [`MAX_NODE_BYTES`], a step faster than [`MAX_SPEED_M_PER_S`].
    Implausible {
        /// The field, as `Message.field`.
        field: &'static str,
        /// The element's index in a repeated field, `None` for a singular one.
        index: Option<usize>,
        /// The value.
        value: f64,
        /// The bound it passed.
        limit: f64,
        /// The rejection's reason, for counters (`implausible_position`, …).
        reason: &'static str,
    },
    /// A structural inconsistency: lengths that differ, counts that do not add up, ids that
    /// disagree between nested headers, an empty scan.
    Invalid {
        /// The field, as `Message.field`.
        field: &'static str,
        /// What is inconsistent.
        detail: String,
    },
}

impl WireError {
    /// A short label of the kind of rejection, for counters (`/metrics`) and logs.
    pub fn reason(&self) -> &'static str {
        match self {
            WireError::Decode { .. } => "malformed",
            WireError::Version { .. } => "version",
            WireError::Missing { .. } => "missing_field",
            WireError::InvalidId { .. } => "invalid_id",
            WireError::InvalidKey { .. } => "invalid_key",
            WireError::InvalidValue { .. } => "invalid_value",
            WireError::Invalid { .. } => "inconsistent",
            WireError::Implausible { reason, .. } => reason,
        }
    }
}

impl fmt::Display for WireError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            WireError::Decode { message, source } => {
                write!(f, "not a valid levelmap.v1.{message} message: {source}")
            }
            WireError::Version { field, found } => write!(
                f,
                "{field}: wire version {found} is not supported (expected {})",
                crate::WIRE_VERSION
            ),
            WireError::Missing { field } => write!(f, "{field} is missing"),
            WireError::InvalidId { kind, id } => write!(
                f,
                "{kind} id {id:?} is invalid: it must be non-empty and use only A-Z, a-z, 0-9, _ and -"
            ),
            WireError::InvalidKey { key } => {
                write!(f, "{key:?} is not a levelmap key expression")
            }
            WireError::InvalidValue {
                field,
                index,
                value,
                problem,
            } => {
                write!(f, "{field}")?;
                if let Some(i) = index {
                    write!(f, "[{i}]")?;
                }
                write!(f, " = {value} is {problem}")
            }
            WireError::Invalid { field, detail } => write!(f, "{field}: {detail}"),
            WireError::Implausible {
                field,
                index,
                value,
                limit,
                ..
            } => {
                write!(f, "{field}")?;
                if let Some(i) = index {
                    write!(f, "[{i}]")?;
                }
                write!(f, " = {value} is beyond the plausible {limit}")
            }
        }
    }
}

impl std::error::Error for WireError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            WireError::Decode { source, .. } => Some(source),
            _ => None,
        }
    }
}

/// The farthest a position may be from its frame's origin (m): 1,000 km, more than any
/// site's extent from its robots' odometry origins or its datum. Finite but absurd values
/// (1e200 m) would pass `finite` and break every later solve of the fleet's network.
pub const MAX_POSITION_M: f64 = 1e6;

/// The farthest return a leveled scan may carry (m): no lidar a robot carries sees 1 km.
pub const MAX_RANGE_M: f64 = 1e3;

/// The largest encoded node taken (bytes): a 6,000-point cloud and a 2,000-beam scan are
/// about 60 KB; [`crate::CLOUD_MAX_POINTS`] points at 7 bytes are 7.3 MB. Zenoh's maximum
/// message size is set from it.
pub const MAX_NODE_BYTES: usize = 8 << 20;

/// The fastest a robot may move between two nodes of a chain (m/s), by odometry over the
/// nodes' stamps: a faster step is an odometry reset or a fault, not motion.
pub const MAX_SPEED_M_PER_S: f64 = 50.0;

/// `value` if finite and within ±[`MAX_POSITION_M`]; `field` names it in the error.
pub(crate) fn coordinate(
    field: &'static str,
    index: Option<usize>,
    value: f64,
) -> Result<f64, WireError> {
    bounded(field, index, value, MAX_POSITION_M, "implausible_position")
}

/// `value` if finite and within ±`limit`, else an [`WireError::Implausible`] with `reason`.
pub(crate) fn bounded(
    field: &'static str,
    index: Option<usize>,
    value: f64,
    limit: f64,
    reason: &'static str,
) -> Result<f64, WireError> {
    let value = finite(field, index, value)?;
    if value.abs() > limit {
        return Err(WireError::Implausible {
            field,
            index,
            value,
            limit,
            reason,
        });
    }
    Ok(value)
}

/// `value` if finite and within ±`limit` (a latitude, a longitude in degrees).
pub(crate) fn within(field: &'static str, value: f64, limit: f64) -> Result<f64, WireError> {
    finite(field, None, value)?;
    if value.abs() > limit {
        return Err(WireError::InvalidValue {
            field,
            index: None,
            value,
            problem: "out of range",
        });
    }
    Ok(value)
}

/// `value` if finite.
pub(crate) fn finite(
    field: &'static str,
    index: Option<usize>,
    value: f64,
) -> Result<f64, WireError> {
    if value.is_finite() {
        Ok(value)
    } else {
        Err(WireError::InvalidValue {
            field,
            index,
            value,
            problem: "not finite",
        })
    }
}

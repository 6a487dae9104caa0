//! Zenoh key expressions (ARCHITECTURE.md, "The wire contract"), built only from validated ids.
//!
//! Ids are restricted to `[A-Za-z0-9_-]` so that no id can add a chunk (`/`) or a wildcard
//! (`*`, `**`, `$*`) to a key expression: a robot named `*` must not subscribe to, or
//! publish as, every robot of its fleet.

use crate::WireError;
use std::fmt;

/// Root chunk of every levelmap key expression.
pub const KEY_ROOT: &str = "levelmap";

/// A per-robot topic.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Topic {
    /// `.../node`: one collection position ([`crate::v1::Node`]); reliable.
    Node,
    /// `.../odom`: live odometry ([`crate::v1::Odometry`]); best effort.
    Odom,
    /// `.../ack`: the mapper's highest durably stored node ([`crate::v1::Ack`]).
    Ack,
    /// `.../scan`: the latest leveled scan for live views ([`crate::v1::LiveScan`]); best
    /// effort.
    Scan,
    /// `.../localization`: the mapper's pose of the robot's node on a map version
    /// ([`crate::v1::Localization`]), when the robot localizes instead of mapping.
    Localization,
}

impl Topic {
    /// The key chunk of the topic.
    pub fn as_str(self) -> &'static str {
        match self {
            Topic::Node => "node",
            Topic::Odom => "odom",
            Topic::Ack => "ack",
            Topic::Scan => "scan",
            Topic::Localization => "localization",
        }
    }

    fn parse(chunk: &str) -> Option<Topic> {
        match chunk {
            "node" => Some(Topic::Node),
            "odom" => Some(Topic::Odom),
            "ack" => Some(Topic::Ack),
            "scan" => Some(Topic::Scan),
            "localization" => Some(Topic::Localization),
            _ => None,
        }
    }
}

impl fmt::Display for Topic {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Accepts an id that is non-empty and uses only `[A-Za-z0-9_-]`; `kind` ("fleet",
/// "robot", ...) names it in the error.
pub fn validate_id(kind: &'static str, id: &str) -> Result<(), WireError> {
    let ok = !id.is_empty()
        && id
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'-');
    if ok {
        Ok(())
    } else {
        Err(WireError::InvalidId {
            kind,
            id: id.to_owned(),
        })
    }
}

/// `levelmap/{fleet}/robots/{robot}/{topic}`.
pub fn robot_key(fleet: &str, robot: &str, topic: Topic) -> Result<String, WireError> {
    validate_id("fleet", fleet)?;
    validate_id("robot", robot)?;
    Ok(format!("{KEY_ROOT}/{fleet}/robots/{robot}/{topic}"))
}

/// `levelmap/{fleet}/robots/{robot}/node`: the robot's nodes (reliable).
pub fn node_key(fleet: &str, robot: &str) -> Result<String, WireError> {
    robot_key(fleet, robot, Topic::Node)
}

/// `levelmap/{fleet}/robots/{robot}/odom`: the robot's live odometry (best effort).
pub fn odom_key(fleet: &str, robot: &str) -> Result<String, WireError> {
    robot_key(fleet, robot, Topic::Odom)
}

/// `levelmap/{fleet}/robots/{robot}/scan`: the robot's live leveled scans (best effort).
pub fn scan_key(fleet: &str, robot: &str) -> Result<String, WireError> {
    robot_key(fleet, robot, Topic::Scan)
}

/// `levelmap/{fleet}/robots/{robot}/localization`: the mapper's localizations of the
/// robot's nodes on a map version.
pub fn localization_key(fleet: &str, robot: &str) -> Result<String, WireError> {
    robot_key(fleet, robot, Topic::Localization)
}

/// `levelmap/{fleet}/robots/{robot}/ack`: the mapper's acknowledgements to the robot.
pub fn ack_key(fleet: &str, robot: &str) -> Result<String, WireError> {
    robot_key(fleet, robot, Topic::Ack)
}

/// `levelmap/{fleet}/robots/*/{topic}`: one topic of every robot of the fleet (what the
/// mapper subscribes to; [`parse_robot_key`] recovers the robot from a sample's key).
pub fn all_robots_key_expr(fleet: &str, topic: Topic) -> Result<String, WireError> {
    validate_id("fleet", fleet)?;
    Ok(format!("{KEY_ROOT}/{fleet}/robots/*/{topic}"))
}

/// `levelmap/{fleet}/map/**`: everything the mapper serves and publishes for the fleet.
pub fn map_key_expr(fleet: &str) -> Result<String, WireError> {
    validate_id("fleet", fleet)?;
    Ok(format!("{KEY_ROOT}/{fleet}/map/**"))
}

/// `levelmap/{fleet}/map/{item}`: one of the mapper's queryables or publications
/// (e.g. `summary`, `graph`, `poses`, `grid`); `item` follows the id rules.
pub fn map_key(fleet: &str, item: &str) -> Result<String, WireError> {
    validate_id("fleet", fleet)?;
    validate_id("map item", item)?;
    Ok(format!("{KEY_ROOT}/{fleet}/map/{item}"))
}

/// The parts of a concrete per-robot key.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RobotKey<'a> {
    /// The fleet's id.
    pub fleet: &'a str,
    /// The robot's id.
    pub robot: &'a str,
    /// What the key carries.
    pub topic: Topic,
}

/// Splits `levelmap/{fleet}/robots/{robot}/{topic}` into its parts, validating both ids.
pub fn parse_robot_key(key: &str) -> Result<RobotKey<'_>, WireError> {
    let invalid = || WireError::InvalidKey {
        key: key.to_owned(),
    };
    let chunks: Vec<&str> = key.split('/').collect();
    let [root, fleet, "robots", robot, topic] = chunks[..] else {
        return Err(invalid());
    };
    if root != KEY_ROOT {
        return Err(invalid());
    }
    let topic = Topic::parse(topic).ok_or_else(invalid)?;
    validate_id("fleet", fleet)?;
    validate_id("robot", robot)?;
    Ok(RobotKey {
        fleet,
        robot,
        topic,
    })
}

/// The full protobuf name of the message a concrete levelmap key carries (as in `.proto`,
/// package `levelmap.v1`): `…/robots/{robot}/node` → `levelmap.v1.Node`, `…/odom` →
/// `levelmap.v1.Odometry`, `…/ack` → `levelmap.v1.Ack`, `…/scan` → `levelmap.v1.LiveScan`,
/// `levelmap/{fleet}/map/poses` →
/// `levelmap.v1.MapPoses`, `…/map/summary` → `levelmap.v1.MapSummary`. `None` for any other
/// key (recorders skip those).
pub fn message_name_of_key(key: &str) -> Option<&'static str> {
    if let Ok(parsed) = parse_robot_key(key) {
        return Some(match parsed.topic {
            Topic::Node => "levelmap.v1.Node",
            Topic::Odom => "levelmap.v1.Odometry",
            Topic::Ack => "levelmap.v1.Ack",
            Topic::Scan => "levelmap.v1.LiveScan",
            Topic::Localization => "levelmap.v1.Localization",
        });
    }
    let chunks: Vec<&str> = key.split('/').collect();
    let [KEY_ROOT, fleet, "map", item] = chunks[..] else {
        return None;
    };
    validate_id("fleet", fleet).ok()?;
    match item {
        "poses" => Some("levelmap.v1.MapPoses"),
        "summary" => Some("levelmap.v1.MapSummary"),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn key_expressions_are_exact() {
        assert_eq!(
            node_key("campus", "rover-1").unwrap(),
            "levelmap/campus/robots/rover-1/node"
        );
        assert_eq!(
            odom_key("campus", "rover_2").unwrap(),
            "levelmap/campus/robots/rover_2/odom"
        );
        assert_eq!(
            ack_key("Site-A", "R3").unwrap(),
            "levelmap/Site-A/robots/R3/ack"
        );
        assert_eq!(map_key_expr("campus").unwrap(), "levelmap/campus/map/**");
        assert_eq!(
            map_key("campus", "summary").unwrap(),
            "levelmap/campus/map/summary"
        );
        assert_eq!(
            all_robots_key_expr("campus", Topic::Node).unwrap(),
            "levelmap/campus/robots/*/node"
        );
    }

    #[test]
    fn bad_ids_are_rejected() {
        for bad in [
            "", "a/b", "*", "**", "$*", "rover 1", "rover?", "ünï", "a#b", "x\n",
        ] {
            assert!(
                matches!(
                    node_key("campus", bad),
                    Err(WireError::InvalidId { kind: "robot", .. })
                ),
                "robot {bad:?}"
            );
            assert!(
                matches!(
                    map_key_expr(bad),
                    Err(WireError::InvalidId { kind: "fleet", .. })
                ),
                "fleet {bad:?}"
            );
            assert!(odom_key(bad, "r").is_err());
            assert!(ack_key("f", bad).is_err());
            assert!(map_key("f", bad).is_err());
        }
        let message = node_key("campus", "a/b").unwrap_err().to_string();
        assert!(message.contains("robot id \"a/b\""), "{message}");
    }

    #[test]
    fn keys_name_their_message() {
        for (key, name) in [
            ("levelmap/park/robots/r1/node", Some("levelmap.v1.Node")),
            ("levelmap/park/robots/r1/odom", Some("levelmap.v1.Odometry")),
            ("levelmap/park/robots/r1/ack", Some("levelmap.v1.Ack")),
            ("levelmap/park/robots/r1/scan", Some("levelmap.v1.LiveScan")),
            ("levelmap/park/map/poses", Some("levelmap.v1.MapPoses")),
            ("levelmap/park/map/summary", Some("levelmap.v1.MapSummary")),
            ("levelmap/park/map/grid", None),
            ("levelmap/p*/map/poses", None),
            ("levelmap/park/robots/r1/pose", None),
            ("other/park/map/poses", None),
            ("levelmap/park/map/poses/x", None),
        ] {
            assert_eq!(message_name_of_key(key), name, "{key}");
        }
    }

    #[test]
    fn robot_keys_parse_back() {
        let key = odom_key("campus", "rover-1").unwrap();
        assert_eq!(
            parse_robot_key(&key).unwrap(),
            RobotKey {
                fleet: "campus",
                robot: "rover-1",
                topic: Topic::Odom
            }
        );
        for bad in [
            "levelmap/campus/robots/*/node",
            "levelmap/campus/robots/r1/pose",
            "levelmap/campus/map/summary",
            "other/campus/robots/r1/node",
            "levelmap/campus/robots/r1/node/extra",
        ] {
            assert!(parse_robot_key(bad).is_err(), "{bad}");
        }
    }
}

//! Map nodes and trajectories as GeoJSON (RFC 7946) in WGS84, for web maps: the map frame is
//! the east-north frame of the datum (see `slam::geodesy`), converted through the ellipsoid.
//!
//! One Point feature a node, then one LineString a robot through its nodes in input order.
//! Positions are `[longitude, latitude]` (RFC 7946 order), rounded to 1e-9° (0.1 mm): RFC
//! 7946 advises fewer digits, but a map for surveying must round-trip to the millimetre.

use crate::EncodeError;
use serde_json::{Map, Value, json};
use slam::Pose2;
use slam::geodesy::GeoDatum;
use slam::nalgebra::Vector3;

/// A map node as GeoJSON shows it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GeoNode<'a> {
    /// The robot's id.
    pub robot: &'a str,
    /// The node's index in the map.
    pub node: usize,
    /// The robot's sequence number of the node, if it came over the wire.
    pub seq: Option<u64>,
    /// Pose east and north of the datum (m, rad counter-clockwise from east).
    pub pose: Pose2,
}

/// `[longitude, latitude]` of a point east-north of the datum (m), at the datum's height
/// plane (the map is planar).
pub fn lon_lat(datum: &GeoDatum, east_north_m: [f64; 2]) -> [f64; 2] {
    let g = datum.enu_to_geodetic(&Vector3::new(east_north_m[0], east_north_m[1], 0.0));
    let round = |deg: f64| (deg * 1e9).round() / 1e9;
    [round(g.longitude_deg), round(g.latitude_deg)]
}

/// A FeatureCollection of the nodes (Point; properties `kind: "node"`, `robot`, `node`,
/// `seq` when known, `yaw_rad`) and of each robot's trajectory (LineString; `kind:
/// "trajectory"`, `robot`, `nodes`), robots in order of first appearance. A robot with one
/// node has no trajectory: a LineString needs two positions.
pub fn to_geojson(datum: &GeoDatum, nodes: &[GeoNode<'_>]) -> Result<Value, EncodeError> {
    if let Some(index) = nodes.iter().position(|n| !n.pose.is_finite()) {
        return Err(EncodeError::NonFinitePose { index });
    }
    let mut features = Vec::with_capacity(nodes.len() + 4);
    let mut tracks: Vec<(&str, Vec<[f64; 2]>)> = Vec::new();
    for n in nodes {
        let position = lon_lat(datum, [n.pose.x, n.pose.y]);
        let mut properties = Map::new();
        properties.insert("kind".into(), "node".into());
        properties.insert("robot".into(), n.robot.into());
        properties.insert("node".into(), n.node.into());
        if let Some(seq) = n.seq {
            properties.insert("seq".into(), seq.into());
        }
        properties.insert("yaw_rad".into(), n.pose.theta.into());
        features.push(json!({
            "type": "Feature",
            "geometry": { "type": "Point", "coordinates": position },
            "properties": properties,
        }));
        match tracks.iter_mut().find(|t| t.0 == n.robot) {
            Some(track) => track.1.push(position),
            None => tracks.push((n.robot, vec![position])),
        }
    }
    for (robot, line) in tracks.into_iter().filter(|t| t.1.len() >= 2) {
        features.push(json!({
            "type": "Feature",
            "geometry": { "type": "LineString", "coordinates": line },
            "properties": { "kind": "trajectory", "robot": robot, "nodes": line.len() },
        }));
    }
    Ok(json!({ "type": "FeatureCollection", "features": features }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use slam::geodesy::Geodetic;

    const DATUM: GeoDatum = GeoDatum {
        origin: Geodetic {
            latitude_deg: 52.39,
            longitude_deg: 9.71,
            height_m: 55.0,
        },
    };

    fn nodes() -> Vec<GeoNode<'static>> {
        vec![
            GeoNode {
                robot: "r1",
                node: 0,
                seq: Some(7),
                pose: Pose2::new(0.0, 0.0, 0.1),
            },
            GeoNode {
                robot: "r2",
                node: 1,
                seq: None,
                pose: Pose2::new(-412.345_6, 803.210_9, -2.0),
            },
            GeoNode {
                robot: "r1",
                node: 2,
                seq: Some(8),
                pose: Pose2::new(123.456_7, -98.765_4, 1.0),
            },
        ]
    }

    #[test]
    fn coordinates_round_trip_to_a_millimetre() {
        let fc = to_geojson(&DATUM, &nodes()).unwrap();
        // Through text, as a client gets it.
        let fc: Value = serde_json::from_str(&fc.to_string()).unwrap();
        assert_eq!(fc["type"], "FeatureCollection");
        let features = fc["features"].as_array().unwrap();
        // Three nodes, then r1's trajectory (r2 has one node: none).
        assert_eq!(features.len(), 4);
        for (f, n) in features.iter().zip(nodes()) {
            assert_eq!(f["geometry"]["type"], "Point");
            let c = f["geometry"]["coordinates"].as_array().unwrap();
            let (lon, lat) = (c[0].as_f64().unwrap(), c[1].as_f64().unwrap());
            // RFC 7946 order: longitude first (9.7° E), latitude second (52.4° N).
            assert!((lon - 9.71).abs() < 0.01 && (lat - 52.39).abs() < 0.01);
            let back = DATUM.geodetic_to_enu(&Geodetic {
                latitude_deg: lat,
                longitude_deg: lon,
                height_m: DATUM.origin.height_m,
            });
            let err = (back.x - n.pose.x).hypot(back.y - n.pose.y);
            assert!(err < 1e-3, "node {}: {err} m", n.node);
            assert_eq!(f["properties"]["robot"], n.robot);
            assert_eq!(f["properties"]["node"], n.node);
            assert_eq!(f["properties"].get("seq").and_then(Value::as_u64), n.seq);
        }
        let track = &features[3];
        assert_eq!(track["geometry"]["type"], "LineString");
        assert_eq!(track["properties"]["robot"], "r1");
        assert_eq!(
            track["geometry"]["coordinates"],
            json!([
                features[0]["geometry"]["coordinates"],
                features[2]["geometry"]["coordinates"]
            ])
        );
    }

    #[test]
    fn non_finite_pose_is_an_error() {
        let mut n = nodes();
        n[1].pose.theta = f64::INFINITY;
        assert!(matches!(
            to_geojson(&DATUM, &n),
            Err(EncodeError::NonFinitePose { index: 1 })
        ));
        let empty = to_geojson(&DATUM, &[]).unwrap();
        assert_eq!(empty["features"], json!([]));
    }
}

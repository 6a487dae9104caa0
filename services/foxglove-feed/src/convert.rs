//! A fleet's view as a Foxglove scene, in the fleet's map frame (`{fleet}/map`): pure, no
//! I/O. The messages of single things (poses, grids, scans, clouds, fixes) are
//! `foxglove_schemas`'.

use fleetmap::FleetView;
use foxglove::messages::{Color, LinePrimitive, Point3, SceneEntity, SceneUpdate, line_primitive};
use foxglove_schemas::{map_frame, pose, timestamp};
use slam::{EdgeKind, Pose2};

/// The pose graph as a scene: its edges as line segments between the nodes' poses, the
/// odometry chains grey, scan matches and closures orange.
pub fn graph(view: &FleetView, stamp_ns: u64) -> SceneUpdate {
    let point = |k: usize| {
        let p = &view.poses[k];
        Point3 {
            x: p.x,
            y: p.y,
            z: 0.0,
        }
    };
    let (mut odometry, mut matched) = (Vec::new(), Vec::new());
    for e in view.edges.iter() {
        if e.from >= view.poses.len() || e.to >= view.poses.len() {
            continue;
        }
        let side = if e.kind == EdgeKind::Odometry {
            &mut odometry
        } else {
            &mut matched
        };
        side.extend([point(e.from), point(e.to)]);
    }
    let lines = |points: Vec<Point3>, color: Color| {
        let mut line = LinePrimitive {
            pose: Some(pose(&Pose2::IDENTITY)),
            thickness: 2.0,
            scale_invariant: true,
            points,
            color: Some(color),
            ..Default::default()
        };
        line.set_type(line_primitive::Type::LineList);
        line
    };
    let grey = Color {
        r: 0.6,
        g: 0.6,
        b: 0.6,
        a: 1.0,
    };
    let orange = Color {
        r: 1.0,
        g: 0.55,
        b: 0.1,
        a: 1.0,
    };
    SceneUpdate {
        deletions: Vec::new(),
        entities: vec![SceneEntity {
            timestamp: Some(timestamp(stamp_ns)),
            frame_id: map_frame(&view.id),
            id: "pose-graph".into(),
            frame_locked: true,
            lines: vec![lines(odometry, grey), lines(matched, orange)],
            ..Default::default()
        }],
    }
}

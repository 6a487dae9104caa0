//! A fleet's view as Foxglove's well-known messages, in the fleet's map frame
//! (`{fleet}/map`, x east, y north): pure, no I/O.

use fleetmap::FleetView;
use foxglove::messages::{
    Color, FrameTransform, Grid, LinePrimitive, PackedElementField, Point3, Pose, PoseInFrame,
    Quaternion, SceneEntity, SceneUpdate, Timestamp, Vector2, Vector3, line_primitive,
    packed_element_field,
};
use slam::{EdgeKind, OccupancyGrid, Pose2};

/// A fleet's map frame.
pub fn map_frame(fleet: &str) -> String {
    format!("{fleet}/map")
}

/// A robot's frame.
pub fn robot_frame(fleet: &str, robot: &str) -> String {
    format!("{fleet}/{robot}")
}

/// A time in ns since the Unix epoch as Foxglove's.
pub fn timestamp(ns: u64) -> Timestamp {
    let sec = u32::try_from(ns / 1_000_000_000).unwrap_or(u32::MAX);
    Timestamp::new(sec, (ns % 1_000_000_000) as u32)
}

/// A planar pose as a 3D one (z 0, a rotation about z).
pub fn pose(p: &Pose2) -> Pose {
    Pose {
        position: Some(Vector3 {
            x: p.x,
            y: p.y,
            z: 0.0,
        }),
        orientation: Some(yaw(p.theta)),
    }
}

fn yaw(theta: f64) -> Quaternion {
    Quaternion {
        x: 0.0,
        y: 0.0,
        z: (theta / 2.0).sin(),
        w: (theta / 2.0).cos(),
    }
}

/// A robot's pose in its fleet's map frame.
pub fn robot_pose(fleet: &str, p: &Pose2, stamp_ns: u64) -> PoseInFrame {
    PoseInFrame {
        timestamp: Some(timestamp(stamp_ns)),
        frame_id: map_frame(fleet),
        pose: Some(pose(p)),
    }
}

/// The map frame → robot frame transform.
pub fn robot_transform(fleet: &str, robot: &str, p: &Pose2, stamp_ns: u64) -> FrameTransform {
    FrameTransform {
        timestamp: Some(timestamp(stamp_ns)),
        parent_frame_id: map_frame(fleet),
        child_frame_id: robot_frame(fleet, robot),
        translation: Some(Vector3 {
            x: p.x,
            y: p.y,
            z: 0.0,
        }),
        rotation: Some(yaw(p.theta)),
    }
}

/// The occupancy grid as a `foxglove.Grid`: one INT8 field, `occupancy` (−1 never seen, else
/// 0–100 per cent, as `nav_msgs/OccupancyGrid`), row 0 at the grid's origin corner (lowest y).
pub fn grid(fleet: &str, g: &OccupancyGrid, stamp_ns: u64) -> Grid {
    let mut field = PackedElementField {
        name: "occupancy".into(),
        offset: 0,
        ..Default::default()
    };
    field.set_type(packed_element_field::NumericType::Int8);
    Grid {
        timestamp: Some(timestamp(stamp_ns)),
        frame_id: map_frame(fleet),
        pose: Some(pose(&Pose2::new(g.origin_m[0], g.origin_m[1], 0.0))),
        column_count: g.width as u32,
        cell_size: Some(Vector2 {
            x: g.resolution_m,
            y: g.resolution_m,
        }),
        row_stride: g.width as u32,
        cell_stride: 1,
        fields: vec![field],
        data: g.cells.iter().map(|&c| c as u8).collect::<Vec<u8>>().into(),
    }
}

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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pose_turns_about_z_and_a_grid_keeps_the_rows_and_cells_of_the_occupancy_grid() {
        let p = pose(&Pose2::new(1.0, -2.0, std::f64::consts::FRAC_PI_2));
        let q = p.orientation.unwrap();
        assert!((q.z - 0.5f64.sqrt()).abs() < 1e-12 && (q.w - 0.5f64.sqrt()).abs() < 1e-12);
        assert_eq!(p.position.unwrap().y, -2.0);

        let g = OccupancyGrid {
            resolution_m: 0.1,
            origin_m: [-1.0, 2.0],
            width: 3,
            height: 2,
            cells: vec![-1, 0, 100, 50, -1, 0],
            occupied_percent: 65,
            free_percent: 25,
        };
        let out = grid("park", &g, 1_500_000_000);
        assert_eq!(out.frame_id, "park/map");
        assert_eq!(
            (out.column_count, out.row_stride, out.cell_stride),
            (3, 3, 1)
        );
        assert_eq!(out.data.len(), 6);
        // Row-major from the origin's row, as the occupancy grid: -1 as 0xff.
        assert_eq!(&out.data[..], &[0xff, 0, 100, 50, 0xff, 0]);
        let origin = out.pose.unwrap().position.unwrap();
        assert_eq!((origin.x, origin.y), (-1.0, 2.0));
        assert_eq!(
            out.fields[0].r#type(),
            packed_element_field::NumericType::Int8
        );
        let t = out.timestamp.unwrap();
        assert_eq!(t, Timestamp::new(1, 500_000_000));
    }
}

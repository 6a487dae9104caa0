//! Parts of the network that nothing links yet (a robot that has met no other, without
//! GPS) each float in their own frame. The first closure between two parts moves one of
//! them rigidly onto the other, so that the optimization starts from where the closure
//! says the part is rather than from its own frame, which can be anywhere.

use super::Mapper2d;
use crate::se2::Pose2;

impl Mapper2d {
    /// Takes the edges and fixes added since the last call into [`Self::parts`].
    pub(super) fn sync_parts(&mut self) {
        self.parts.sync(&self.graph);
    }

    /// Before a closure `from → to` measuring `measurement` is added: when the two nodes
    /// are in different parts, moves one part so that the closure holds exactly. The part
    /// that moves is the one GPS does not anchor or, if neither or both are anchored, the
    /// one whose first node is later (the map keeps the frame of its first node).
    pub(super) fn join_parts(&mut self, from: usize, to: usize, measurement: &Pose2) {
        self.sync_parts();
        let parts = &self.parts;
        if parts.same_part(from, to) {
            return;
        }
        let (part_from, part_to) = (parts.part(from), parts.part(to));
        let move_to_part = match (parts.floats(from), parts.floats(to)) {
            (false, true) => true,
            (true, false) => false,
            _ => part_to > part_from,
        };
        let poses = &self.graph.poses;
        let (part, motion) = if move_to_part {
            let target = poses[from].compose(measurement);
            (part_to, target.compose(&poses[to].inverse()))
        } else {
            let target = poses[to].compose(&measurement.inverse());
            (part_from, target.compose(&poses[from].inverse()))
        };
        for (node, pose) in self.graph.poses.iter_mut().enumerate() {
            if parts.part(node) == part {
                *pose = motion.compose(pose);
            }
        }
        self.near.rebuild(&self.graph.poses);
        self.stats.parts_joined += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::super::tests::scan_at;
    use super::super::{Mapper2d, Mapper2dParams};
    use crate::se2::Pose2;

    #[test]
    fn a_closure_between_parts_moves_the_later_one_onto_the_map() {
        let mut mapper = Mapper2d::new(Mapper2dParams::default());
        let truth = |k: usize, y: f64| Pose2::new(-2.0 + 0.6 * k as f64, y, 0.0);
        for k in 0..4 {
            let pose = truth(k, 0.0);
            mapper
                .add_robot_scan(0, pose, scan_at(&pose, k as u64), &[])
                .expect("robot 0");
        }
        // Robot 1 drives beside robot 0, but its odometry frame is somewhere else entirely:
        // its part floats 40 m away, turned by 2 rad, nothing links it.
        let frame = Pose2::new(40.0, -25.0, 2.0);
        for k in 0..4 {
            let pose = truth(k, -0.5);
            let odometry = frame.inverse().compose(&pose);
            mapper
                .add_robot_scan(1, odometry, scan_at(&pose, 10 + k as u64), &[])
                .expect("robot 1");
        }
        assert_eq!(mapper.graph().component_count(), 2);
        // A closure from robot 0's node 1 to robot 1's first node (node 4), as measured.
        let measurement = truth(1, 0.0).between(&truth(0, -0.5));
        let robot0: Vec<Pose2> = mapper.graph().poses[..4].to_vec();
        mapper.join_parts(1, 4, &measurement);
        for k in 0..4 {
            let (got, want) = (mapper.graph().poses[4 + k], truth(k, -0.5));
            assert!(
                (got.x - want.x).hypot(got.y - want.y) < 0.05
                    && (got.theta - want.theta).abs() < 0.01,
                "robot 1 node {k}: {got:?}, truth {want:?}"
            );
        }
        assert_eq!(mapper.graph().poses[..4], robot0, "robot 0 stays");
        assert_eq!(mapper.stats().parts_joined, 1);
        // Joined parts are one: a second closure moves nothing.
        mapper.graph.edges.push(crate::network::RelativeEdge {
            from: 1,
            to: 4,
            measurement,
            information: crate::nalgebra::Matrix3::identity(),
            kind: crate::network::EdgeKind::InterRobot,
            robust: crate::robust::Robust::None,
        });
        let before = mapper.graph().poses.clone();
        mapper.join_parts(2, 5, &Pose2::new(3.0, 3.0, 1.0));
        assert_eq!(mapper.graph().poses, before);
    }
}

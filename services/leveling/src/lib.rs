//! From a 3D laser scan to the *leveled range scan* of Wulf, Brenneke and Wagner, "Using 3D
//! Laser Range Data for SLAM in Outdoor Environments" (the spec for every step here).
//!
//! The pipeline reads like the paper, one named step each:
//! [`deskew()`] (scanning while driving, 2.1) → [`Segmenter::segment`] (3.1, eqs. 3.2–3.3)
//! → [`project()`] (3.2, eq. 3.4). [`Leveler`] composes them. Pure: no I/O, no async.

pub mod deskew;
pub mod project;
pub mod scan;
pub mod score;
pub mod segment;

pub use deskew::{DeskewError, PoseTrack, TimedPose, deskew, heading_rad, leveled_frame};
pub use nalgebra;
pub use project::{Beam, LeveledScan, horizontal_cut, project};
pub use scan::{Column, CylPoint, Scan3d};
pub use score::Precision;
pub use segment::{ClassCounts, PointClass, SegmentParams, Segmenter, segment_column_reference};

use nalgebra::Isometry3;

/// Everything leveling produces for one scan.
#[derive(Clone, Debug, Default)]
pub struct Leveled {
    /// The motion-compensated cloud in the leveled frame at scan start.
    pub cloud: Scan3d,
    /// Class of every point of `cloud`, same order.
    pub classes: Vec<PointClass>,
    /// Per column, the index of the point projected into the leveled scan.
    pub first_landmarks: Vec<Option<u32>>,
    /// Points per class in `classes`.
    pub counts: ClassCounts,
    /// The leveled range scan: one beam per column.
    pub scan: LeveledScan,
}

/// The leveling pipeline with its buffers, reused from scan to scan.
#[derive(Clone, Debug, Default)]
pub struct Leveler {
    segmenter: Segmenter,
}

impl Leveler {
    /// A pipeline segmenting with `params`.
    pub fn new(params: SegmentParams) -> Leveler {
        Leveler {
            segmenter: Segmenter::new(params),
        }
    }

    /// The segmentation thresholds it uses.
    pub fn params(&self) -> &SegmentParams {
        self.segmenter.params()
    }

    /// deskew → segment → project, for a scan in the sensor frame with the dead-reckoning
    /// track covering its columns (a [`PoseTrack::stationary`] one for a standing robot).
    pub fn level(
        &mut self,
        raw: &Scan3d,
        track: &PoseTrack,
        sensor_in_robot: &Isometry3<f64>,
    ) -> Result<Leveled, DeskewError> {
        let cloud = deskew(raw, track, sensor_in_robot)?;
        Ok(self.segment_and_project(cloud))
    }

    /// segment → project, for a cloud already in the leveled frame.
    pub fn segment_and_project(&mut self, cloud: Scan3d) -> Leveled {
        let mut classes = Vec::new();
        let (first_landmarks, counts) = self.segmenter.segment(&cloud, &mut classes);
        let scan = project(&cloud, &first_landmarks, &classes);
        Leveled {
            cloud,
            classes,
            first_landmarks,
            counts,
            scan,
        }
    }
}

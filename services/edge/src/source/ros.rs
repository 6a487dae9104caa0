//! A ROS 2 robot's streams into the edge's events, whatever brings the samples (a recording,
//! `source::mcap`; live Zenoh keys): odometry, optionally an IMU's roll and pitch and a GNSS
//! receiver's fixes, and the lidar's clouds organized into columns. Pure: samples in,
//! events out. A scan waits until odometry covers its last column, a fix until odometry
//! covers its time; each bad sample is counted by topic and reason, never fatal.

use super::SourceEvent;
use crate::node::{GpsReading, SensorScan};
use leveling::nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use leveling::{PoseTrack, TimedPose};
use ros2msg::{CloudPoints, NavSatFix, NavSatStatus, Odometry, TfMessage};
use serde::{Deserialize, Serialize};
use slam::gnss::FixStatus;
use std::collections::{BTreeMap, VecDeque};

/// The ROS 2 types each topic must have.
pub const CLOUD_TYPE: &str = ros2msg::types::POINT_CLOUD2.name;
/// See [`CLOUD_TYPE`].
pub const ODOMETRY_TYPE: &str = ros2msg::types::ODOMETRY.name;
/// See [`CLOUD_TYPE`].
pub const IMU_TYPE: &str = ros2msg::types::IMU.name;
/// See [`CLOUD_TYPE`].
pub const GPS_TYPE: &str = ros2msg::types::NAV_SAT_FIX.name;
/// See [`CLOUD_TYPE`].
pub const TF_TYPE: &str = ros2msg::types::TF_MESSAGE.name;
/// The static transforms' topic.
pub const TF_STATIC_TOPIC: &str = "/tf_static";

/// Odometry kept for scans and fixes still to come (ns).
const ODOMETRY_KEPT_NS: u64 = 10_000_000_000;
/// Scans and fixes waiting for odometry, at most (the oldest go, counted).
const MAX_WAITING: usize = 8;
/// Fixes waiting for a scan, at most (the oldest go, counted).
const MAX_READINGS: usize = 64;
/// Static frames kept, at most (a robot has a handful).
const MAX_STATIC_FRAMES: usize = 256;

/// The streams of a ROS 2 source as configured (`[source.mcap]`, `[source.ros2]`): topics
/// as `ros2 topic list` prints them.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct RosStreams {
    /// The lidar's `sensor_msgs/PointCloud2`.
    pub cloud_topic: String,
    /// `nav_msgs/Odometry`: dead reckoning, and roll and pitch without an IMU.
    pub odometry_topic: String,
    /// `sensor_msgs/Imu` for roll and pitch (empty: none).
    pub imu_topic: String,
    /// `sensor_msgs/NavSatFix` (empty: none).
    pub gps_topic: String,
    /// The lidar on the robot, `[x, y, z, roll, pitch, yaw]` (m, rad); empty: from
    /// `/tf_static` (the cloud's frame as a child of the base).
    pub lidar_in_base: Vec<f64>,
    /// The GNSS antenna on the robot, `[x, y, z]` (m); empty: from `/tf_static`, else 0.
    pub antenna_in_base: Vec<f64>,
    /// Azimuth columns a cloud is organized into (a 1024-column Ouster: 1024).
    pub columns: usize,
}

impl Default for RosStreams {
    fn default() -> Self {
        RosStreams {
            cloud_topic: "/points".into(),
            odometry_topic: "/odom".into(),
            imu_topic: String::new(),
            gps_topic: String::new(),
            lidar_in_base: Vec::new(),
            antenna_in_base: Vec::new(),
            columns: 1024,
        }
    }
}

impl RosStreams {
    /// The assembler's inputs; an error, naming `table`, for a malformed pose or a key
    /// in `unknown`.
    pub fn inputs(
        &self,
        table: &str,
        unknown: &BTreeMap<String, toml::Value>,
    ) -> anyhow::Result<RosInputs> {
        if let Some(key) = unknown.keys().next() {
            anyhow::bail!("{table}: unknown key {key:?}");
        }
        let lidar_in_base = match self.lidar_in_base.as_slice() {
            [] => None,
            &[x, y, z, roll, pitch, yaw] => Some(Isometry3::from_parts(
                Translation3::new(x, y, z),
                UnitQuaternion::from_euler_angles(roll, pitch, yaw),
            )),
            other => anyhow::bail!("{table} lidar_in_base: 6 numbers, not {}", other.len()),
        };
        let antenna_in_base = match self.antenna_in_base.as_slice() {
            [] => None,
            &[x, y, z] => Some(Vector3::new(x, y, z)),
            other => anyhow::bail!("{table} antenna_in_base: 3 numbers, not {}", other.len()),
        };
        anyhow::ensure!(self.columns > 0, "{table} columns: at least 1");
        let optional = |t: &str| (!t.is_empty()).then(|| t.to_owned());
        Ok(RosInputs {
            cloud_topic: self.cloud_topic.clone(),
            odometry_topic: self.odometry_topic.clone(),
            imu_topic: optional(&self.imu_topic),
            gps_topic: optional(&self.gps_topic),
            lidar_in_base,
            antenna_in_base,
            columns: self.columns,
        })
    }
}

/// Which topics play which part, and the frames the messages do not give.
#[derive(Clone, Debug, PartialEq)]
pub struct RosInputs {
    /// The lidar's `PointCloud2`.
    pub cloud_topic: String,
    /// `nav_msgs/Odometry`: dead reckoning (and roll and pitch without an IMU).
    pub odometry_topic: String,
    /// `sensor_msgs/Imu`: roll and pitch.
    pub imu_topic: Option<String>,
    /// `sensor_msgs/NavSatFix`.
    pub gps_topic: Option<String>,
    /// The lidar on the robot; `None`: from `/tf_static` (the cloud's frame in the base).
    pub lidar_in_base: Option<Isometry3<f64>>,
    /// The GNSS antenna on the robot (m); `None`: from `/tf_static`, else the base's origin.
    pub antenna_in_base: Option<Vector3<f64>>,
    /// Azimuth columns a cloud is organized into.
    pub columns: usize,
}

/// What the assembler took and refused, by topic.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RosCounts {
    /// Samples used, by topic.
    pub used: BTreeMap<String, u64>,
    /// Samples refused, by "topic: reason".
    pub refused: BTreeMap<String, u64>,
}

/// See the module.
pub struct RosAssembler {
    inputs: RosInputs,
    odometry: VecDeque<TimedPose>,
    /// The IMU's latest attitude.
    imu: Option<UnitQuaternion<f64>>,
    /// Clouds organized, with their frame, waiting for odometry.
    scans: VecDeque<(leveling::Scan3d, String)>,
    fixes: VecDeque<NavSatFix>,
    /// Fixes with their odometry, for the next scan.
    readings: Vec<GpsReading>,
    /// `/tf_static`: child frame → (parent frame, child in parent).
    tf_static: BTreeMap<String, (String, Isometry3<f64>)>,
    out: VecDeque<SourceEvent>,
    counts: RosCounts,
}

impl RosAssembler {
    /// An assembler of `inputs`.
    pub fn new(inputs: RosInputs) -> RosAssembler {
        RosAssembler {
            inputs,
            odometry: VecDeque::new(),
            imu: None,
            scans: VecDeque::new(),
            fixes: VecDeque::new(),
            readings: Vec::new(),
            tf_static: BTreeMap::new(),
            out: VecDeque::new(),
            counts: RosCounts::default(),
        }
    }

    /// What was used and refused so far.
    pub fn counts(&self) -> &RosCounts {
        &self.counts
    }

    /// The next event, if one is ready.
    pub fn pop(&mut self) -> Option<SourceEvent> {
        self.out.pop_front()
    }

    /// Takes one sample of `topic`, whose ROS 2 type is `type_name`; other topics are
    /// ignored.
    pub fn push(&mut self, topic: &str, type_name: &str, sample: &[u8]) {
        let i = &self.inputs;
        let expected = if topic == i.cloud_topic {
            CLOUD_TYPE
        } else if topic == i.odometry_topic {
            ODOMETRY_TYPE
        } else if i.imu_topic.as_deref() == Some(topic) {
            IMU_TYPE
        } else if i.gps_topic.as_deref() == Some(topic) {
            GPS_TYPE
        } else if topic == TF_STATIC_TOPIC {
            TF_TYPE
        } else {
            return;
        };
        if type_name != expected {
            return self.refuse(topic, &format!("type {type_name}, not {expected}"));
        }
        let result = match expected {
            CLOUD_TYPE => self.take_cloud(sample),
            ODOMETRY_TYPE => self.take_odometry(sample),
            IMU_TYPE => ros2msg::decode::<ros2msg::Imu>(sample)
                .map_err(|e| e.to_string())
                .and_then(|m| {
                    let q = &m.orientation;
                    finite_rotation(q.w, q.x, q.y, q.z).map(|q| self.imu = Some(q))
                }),
            GPS_TYPE => ros2msg::decode::<NavSatFix>(sample)
                .map_err(|e| e.to_string())
                .and_then(|fix| self.take_fix(fix)),
            _ => ros2msg::decode::<TfMessage>(sample)
                .map_err(|e| e.to_string())
                .map(|tf| self.take_tf_static(tf)),
        };
        match result {
            Ok(()) => *self.counts.used.entry(topic.to_owned()).or_default() += 1,
            Err(reason) => self.refuse(topic, &reason),
        }
        self.release();
    }

    fn refuse(&mut self, topic: &str, reason: &str) {
        let key = format!("{topic}: {reason}");
        let count = self.counts.refused.entry(key.clone()).or_default();
        if *count == 0 {
            tracing::warn!("{key} (counted from now on)");
        }
        *count += 1;
    }

    fn take_cloud(&mut self, sample: &[u8]) -> Result<(), String> {
        let cloud = ros2msg::decode_cloud(sample).map_err(|e| e.to_string())?;
        let points = CloudPoints::from_cloud(&cloud).map_err(|e| e.to_string())?;
        let stamp_ns = cloud.header.stamp.to_ns().ok_or("a stamp before 1970")?;
        let scan = scanio::cloud::organize_timed(
            &points.xyz,
            points.offset_ns.as_deref(),
            stamp_ns,
            self.inputs.columns,
        );
        if self.scans.len() == MAX_WAITING {
            self.scans.pop_front();
            self.refuse(&self.inputs.cloud_topic.clone(), "no odometry after it");
        }
        self.scans.push_back((scan, cloud.header.frame_id));
        Ok(())
    }

    fn take_odometry(&mut self, sample: &[u8]) -> Result<(), String> {
        let m: Odometry = ros2msg::decode(sample).map_err(|e| e.to_string())?;
        let stamp_ns = m.header.stamp.to_ns().ok_or("a stamp before 1970")?;
        if self.odometry.back().is_some_and(|p| p.stamp_ns >= stamp_ns) {
            return Err("a stamp not after the previous one".into());
        }
        let (p, q) = (&m.pose.pose.position, &m.pose.pose.orientation);
        let mut rotation = finite_rotation(q.w, q.x, q.y, q.z)?;
        if !(p.x.is_finite() && p.y.is_finite() && p.z.is_finite()) {
            return Err("a position that is not finite".into());
        }
        // Roll and pitch from the IMU (gravity), the heading from odometry.
        if let Some(imu) = self.imu {
            let (roll, pitch, _) = imu.euler_angles();
            let (_, _, yaw) = rotation.euler_angles();
            rotation = UnitQuaternion::from_euler_angles(roll, pitch, yaw);
        }
        let pose = TimedPose {
            stamp_ns,
            pose: Isometry3::from_parts(Translation3::new(p.x, p.y, p.z), rotation),
        };
        self.odometry.push_back(pose);
        while self
            .odometry
            .front()
            .is_some_and(|f| f.stamp_ns + ODOMETRY_KEPT_NS < stamp_ns)
        {
            self.odometry.pop_front();
        }
        self.out.push_back(SourceEvent::Odometry(pose));
        Ok(())
    }

    fn take_fix(&mut self, fix: NavSatFix) -> Result<(), String> {
        if fix.status.status <= NavSatStatus::NO_FIX {
            return Err("no fix".into());
        }
        if !(fix.latitude.is_finite() && fix.longitude.is_finite() && fix.altitude.is_finite()) {
            return Err("a position that is not finite".into());
        }
        if self.fixes.len() == MAX_WAITING {
            self.fixes.pop_front();
        }
        self.fixes.push_back(fix);
        Ok(())
    }

    fn take_tf_static(&mut self, tf: TfMessage) {
        for t in tf.transforms {
            let (p, q) = (&t.transform.translation, &t.transform.rotation);
            let known = self.tf_static.contains_key(&t.child_frame_id);
            if !known && self.tf_static.len() == MAX_STATIC_FRAMES {
                continue;
            }
            if let Ok(rotation) = finite_rotation(q.w, q.x, q.y, q.z) {
                let pose = Isometry3::from_parts(Translation3::new(p.x, p.y, p.z), rotation);
                self.tf_static
                    .insert(t.child_frame_id, (t.header.frame_id, pose));
            }
        }
    }

    /// `frame` in the robot's base: configured, or one hop of `/tf_static`.
    fn frame_in_base(&self, frame: &str) -> Option<Isometry3<f64>> {
        self.tf_static.get(frame).map(|(_, pose)| *pose)
    }

    /// Moves fixes and scans that odometry now covers to the output.
    fn release(&mut self) {
        let Some(latest) = self.odometry.back().map(|p| p.stamp_ns) else {
            return;
        };
        while self
            .fixes
            .front()
            .is_some_and(|f| f.header.stamp.to_ns().is_some_and(|t| t <= latest))
        {
            let fix = self.fixes.pop_front().expect("checked");
            let stamp_ns = fix.header.stamp.to_ns().expect("checked");
            let topic = self.inputs.gps_topic.clone().unwrap_or_default();
            let track = PoseTrack::new(self.odometry.iter().copied().collect()).ok();
            let Some(at_fix) = track.and_then(|t| t.at(stamp_ns)) else {
                self.refuse(&topic, "older than the odometry kept");
                continue;
            };
            let antenna = self.inputs.antenna_in_base.unwrap_or_else(|| {
                self.frame_in_base(&fix.header.frame_id)
                    .map_or_else(Vector3::zeros, |p| p.translation.vector)
            });
            // Without scans (the lidar down), fixes must not pile up: the oldest go.
            if self.readings.len() == MAX_READINGS {
                self.readings.remove(0);
                self.refuse(&topic, "no scan after it");
            }
            self.readings
                .push(gps_reading(&fix, stamp_ns, antenna, at_fix));
        }
        while let Some((scan, _)) = self.scans.front() {
            let end = scan.columns.last().map_or(0, |c| c.stamp_ns);
            if end > latest {
                return;
            }
            let start = scan.start_stamp_ns();
            let (scan, frame) = self.scans.pop_front().expect("checked");
            let topic = self.inputs.cloud_topic.clone();
            let Some(lidar) = self
                .inputs
                .lidar_in_base
                .or_else(|| self.frame_in_base(&frame))
            else {
                self.refuse(
                    &topic,
                    &format!("no lidar_in_base and no /tf_static for {frame}"),
                );
                continue;
            };
            // The odometry around the scan, one sample beyond each end.
            let samples: Vec<TimedPose> = self.odometry.iter().copied().collect();
            let from = samples
                .partition_point(|p| p.stamp_ns <= start)
                .saturating_sub(1);
            let to = samples.partition_point(|p| p.stamp_ns < end) + 1;
            let covering = &samples[from..to.min(samples.len())];
            if covering.first().is_none_or(|p| p.stamp_ns > start) {
                self.refuse(&topic, "older than the odometry kept");
                continue;
            }
            let track = PoseTrack::new(covering.to_vec()).expect("odometry is in time order");
            let (gps, later): (Vec<GpsReading>, Vec<GpsReading>) =
                std::mem::take(&mut self.readings)
                    .into_iter()
                    .partition(|r| r.stamp_ns <= start);
            self.readings = later;
            self.out.push_back(SourceEvent::Scan(Box::new(SensorScan {
                raw: scan,
                track,
                sensor_in_robot: lidar,
                gps,
            })));
        }
    }
}

fn finite_rotation(w: f64, x: f64, y: f64, z: f64) -> Result<UnitQuaternion<f64>, String> {
    let q = Quaternion::new(w, x, y, z);
    if !(q.norm() > 0.5 && q.coords.iter().all(|v| v.is_finite())) {
        return Err("an orientation that is not a rotation".into());
    }
    Ok(UnitQuaternion::from_quaternion(q))
}

/// A fix as the node takes it: sigmas from the covariance (ENU, m²) when it is given.
fn gps_reading(
    fix: &NavSatFix,
    stamp_ns: u64,
    antenna: Vector3<f64>,
    odometry_at_fix: Isometry3<f64>,
) -> GpsReading {
    let c = &fix.position_covariance;
    let (horizontal, vertical) = if fix.position_covariance_type == 0 {
        // Unknown: a plain single-point fix's few metres.
        (3.0, 5.0)
    } else {
        (((c[0] + c[4]) / 2.0).max(0.0).sqrt(), c[8].max(0.0).sqrt())
    };
    GpsReading {
        stamp_ns,
        latitude_deg: fix.latitude,
        longitude_deg: fix.longitude,
        altitude_m: fix.altitude,
        sigma_horizontal_m: horizontal,
        sigma_vertical_m: vertical,
        // NavSatStatus cannot tell RTK float from fixed: GBAS is taken as the weaker.
        status: match fix.status.status {
            0 => FixStatus::Fix,
            1 => FixStatus::Dgps,
            _ => FixStatus::RtkFloat,
        },
        antenna_in_robot_m: antenna,
        odometry_at_fix,
    }
}

#[cfg(test)]
mod tests;

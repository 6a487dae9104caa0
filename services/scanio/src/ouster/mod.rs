//! Ouster OS sensors recorded as pcap + metadata JSON, read frame by frame into organized
//! [`leveling::Scan3d`]s.
//!
//! Packets of the metadata's lidar port are grouped by frame id; a frame missing a column of
//! its window is dropped and counted. Each pixel is projected with Ouster's documented
//! lookup table (beam angles, beam origin offset, `lidar_to_sensor_transform`) into the
//! sensor frame (x forward, away from the connector; y left; z up; m). The scan has one
//! column per measurement id, destaggered (`pixel_shift_by_row`) so that a column is one
//! azimuth, bottom-up (the packets are top-down).

pub mod meta;
pub mod packet;

pub use meta::{Profile, SensorMeta};
pub use packet::{ColumnHeader, PacketLayout};

use crate::pcap::{PcapCounts, PcapReader};
use crate::{LoadError, LoadedScan};
use leveling::nalgebra::Isometry3;
use leveling::{PoseTrack, Scan3d};
use std::fs::File;
use std::io::{BufReader, Read};
use std::path::Path;

/// One rotation as the packets hold it (staggered): row-major, row = beam (top-down),
/// column = measurement id.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    /// The sensor's frame id.
    pub frame_id: u16,
    /// Range per pixel (mm; 0: no return), `rows × columns_per_frame`.
    pub ranges_mm: Vec<u32>,
    /// Per column, the column header's timestamp (ns, sensor clock); 0 outside the window.
    pub stamps_ns: Vec<u64>,
    /// Per column, the sensor's valid flag (false outside the window).
    pub column_valid: Vec<bool>,
}

/// What a read met: packets kept and dropped, frames made and dropped.
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct OusterCounts {
    /// The capture's records and datagrams.
    pub pcap: PcapCounts,
    /// Datagrams on the lidar port, well formed.
    pub lidar_packets: u64,
    /// Datagrams on other ports (IMU, …).
    pub other_ports: u64,
    /// Lidar-port datagrams of the wrong size or type (dropped).
    pub bad_packets: u64,
    /// Complete frames returned.
    pub frames: u64,
    /// Frames dropped for a missing column (a capture's first and last often are).
    pub incomplete_frames: u64,
}

/// The first bad packet's reason and the truncation, if any, naming the file.
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct OusterReport {
    /// The counts.
    pub counts: OusterCounts,
    /// Why the first bad lidar packet was dropped.
    pub first_bad_packet: Option<String>,
    /// The capture ended inside a record: a partial read.
    pub truncated: Option<String>,
}

impl OusterReport {
    /// One line per thing worth a warning (drops, truncation), each naming the file.
    pub fn warnings(&self, pcap: &Path) -> Vec<String> {
        let c = &self.counts;
        let mut out = Vec::new();
        if c.incomplete_frames > 0 {
            out.push(format!(
                "{}: {} incomplete frame(s) dropped (a column of the window missing)",
                pcap.display(),
                c.incomplete_frames
            ));
        }
        if let Some(why) = &self.first_bad_packet {
            out.push(format!(
                "{}: {} bad lidar packet(s) dropped; the first: {why}",
                pcap.display(),
                c.bad_packets
            ));
        }
        out.extend(self.truncated.clone());
        out
    }
}

struct Partial {
    frame: Frame,
    seen: Vec<bool>,
    missing: usize,
}

/// Reads a capture frame by frame (a file, or any bytes: [`FrameReader::new`]).
pub struct FrameReader<R: Read = BufReader<File>> {
    pcap: PcapReader<R>,
    meta: SensorMeta,
    layout: PacketLayout,
    current: Option<Partial>,
    report: OusterReport,
}

impl FrameReader {
    /// Opens `pcap`, to be read with `meta`.
    pub fn open(pcap: &Path, meta: SensorMeta) -> Result<FrameReader, LoadError> {
        Ok(FrameReader::new(PcapReader::open(pcap)?, meta))
    }
}

impl<R: Read> FrameReader<R> {
    /// Reads the capture `pcap` (its global header read) with `meta`.
    pub fn new(pcap: PcapReader<R>, meta: SensorMeta) -> FrameReader<R> {
        FrameReader {
            pcap,
            layout: PacketLayout::of(&meta),
            meta,
            current: None,
            report: OusterReport::default(),
        }
    }

    /// The metadata the capture is read with.
    pub fn meta(&self) -> &SensorMeta {
        &self.meta
    }

    /// What the read met so far.
    pub fn report(&self) -> OusterReport {
        let mut report = self.report.clone();
        report.counts.pcap = self.pcap.counts().clone();
        report.truncated = self.pcap.truncated().map(str::to_owned);
        report
    }

    /// The next complete frame; `None` at the end of the capture.
    pub fn next_frame(&mut self) -> Option<Frame> {
        while let Some(datagram) = self.pcap.next_udp() {
            if datagram.dst_port != self.meta.udp_port_lidar {
                self.report.counts.other_ports += 1;
                continue;
            }
            let packet = &datagram.payload;
            // A bad packet is dropped whole: counted once, no column of it kept, and the
            // frame being filled goes on.
            let checked = self.layout.frame_id(packet).and_then(|id| {
                self.check_window(packet)?;
                Ok(id)
            });
            let frame_id = match checked {
                Ok(id) => id,
                Err(why) => {
                    self.bad_packet(why);
                    continue;
                }
            };
            self.report.counts.lidar_packets += 1;
            let mut done = None;
            if self
                .current
                .as_ref()
                .is_some_and(|p| p.frame.frame_id != frame_id)
            {
                done = self.finish();
            }
            self.add(frame_id, packet);
            if self.current.as_ref().is_some_and(|p| p.missing == 0) {
                // Complete: out now (a frame left over in `done` was incomplete).
                debug_assert!(done.is_none());
                done = self.finish();
            }
            if done.is_some() {
                return done;
            }
        }
        self.finish()
    }

    fn bad_packet(&mut self, why: String) {
        self.report.counts.bad_packets += 1;
        self.report.first_bad_packet.get_or_insert(why);
    }

    /// Takes the frame being filled: `Some` if complete, else counted as dropped.
    fn finish(&mut self) -> Option<Frame> {
        let partial = self.current.take()?;
        if partial.missing > 0 {
            self.report.counts.incomplete_frames += 1;
            return None;
        }
        self.report.counts.frames += 1;
        Some(partial.frame)
    }

    /// Every column of a packet (of the right size) has a measurement id in the window.
    fn check_window(&self, packet: &[u8]) -> Result<(), String> {
        let (first, last) = self.meta.column_window;
        for c in 0..self.layout.columns {
            let m = self.layout.column(packet, c).measurement_id as usize;
            if !(first..=last).contains(&m) {
                return Err(format!(
                    "measurement id {m} outside the column window {first}..={last}"
                ));
            }
        }
        Ok(())
    }

    /// Adds a packet checked by [`PacketLayout::frame_id`] and [`Self::check_window`].
    fn add(&mut self, frame_id: u16, packet: &[u8]) {
        let (w, rows) = (self.meta.columns_per_frame, self.meta.pixels_per_column);
        let (first, last) = self.meta.column_window;
        let partial = self.current.get_or_insert_with(|| Partial {
            frame: Frame {
                frame_id,
                ranges_mm: vec![0; w * rows],
                stamps_ns: vec![0; w],
                column_valid: vec![false; w],
            },
            seen: vec![false; w],
            missing: last + 1 - first,
        });
        for c in 0..self.layout.columns {
            let header = self.layout.column(packet, c);
            let m = header.measurement_id as usize;
            if !partial.seen[m] {
                partial.seen[m] = true;
                partial.missing -= 1;
            }
            let frame = &mut partial.frame;
            frame.stamps_ns[m] = header.stamp_ns;
            frame.column_valid[m] = header.valid;
            for row in 0..rows {
                frame.ranges_mm[row * w + m] = self.layout.range_mm(packet, c, row);
            }
        }
    }

    /// The path of the capture (for messages).
    pub fn path(&self) -> &Path {
        self.pcap.path()
    }
}

/// Ouster's XYZ lookup table: per staggered pixel, a direction and an offset (sensor frame),
/// so that a point is `direction · range + offset`.
#[derive(Clone, Debug)]
pub struct XyzLut {
    columns: usize,
    direction: Vec<[f64; 3]>,
    offset_m: Vec<[f64; 3]>,
}

impl XyzLut {
    /// The table of `meta` (Ouster's `make_xyz_lut`; ranges in mm, points in m).
    pub fn new(meta: &SensorMeta) -> XyzLut {
        let (w, h) = (meta.columns_per_frame, meta.pixels_per_column);
        let t = &meta.lidar_to_sensor;
        let rotate = |v: [f64; 3]| {
            [0, 1, 2].map(|r| t[4 * r] * v[0] + t[4 * r + 1] * v[1] + t[4 * r + 2] * v[2])
        };
        let (origin_x, origin_z) = meta.beam_origin_mm;
        let n = origin_x.hypot(origin_z);
        let mut direction = Vec::with_capacity(w * h);
        let mut offset_m = Vec::with_capacity(w * h);
        for row in 0..h {
            let azimuth = -meta.beam_azimuth_deg[row].to_radians();
            let altitude = meta.beam_altitude_deg[row].to_radians();
            for col in 0..w {
                let encoder = 2.0 * std::f64::consts::PI * (1.0 - col as f64 / w as f64);
                let d = [
                    (encoder + azimuth).cos() * altitude.cos(),
                    (encoder + azimuth).sin() * altitude.cos(),
                    altitude.sin(),
                ];
                let o = [
                    encoder.cos() * origin_x - d[0] * n,
                    encoder.sin() * origin_x - d[1] * n,
                    origin_z - d[2] * n,
                ];
                let (d, o) = (rotate(d), rotate(o));
                direction.push(d.map(|v| v * 1e-3));
                offset_m.push([0, 1, 2].map(|i| (o[i] + t[4 * i + 3]) * 1e-3));
            }
        }
        XyzLut {
            columns: w,
            direction,
            offset_m,
        }
    }

    /// The point of staggered pixel (`row`, `col`) at `range_mm` (m); `None` for no return.
    pub fn xyz_m(&self, row: usize, col: usize, range_mm: u32) -> Option<[f64; 3]> {
        if range_mm == 0 {
            return None;
        }
        let i = row * self.columns + col;
        let (d, o) = (self.direction[i], self.offset_m[i]);
        let r = range_mm as f64;
        Some([d[0] * r + o[0], d[1] * r + o[1], d[2] * r + o[2]])
    }
}

/// An organized scan of `frame`: destaggered columns, bottom-up, in the order of (and stamped
/// with) their middle beam's measurement. `file_index` holds each point's
/// staggered pixel index (row × columns_per_frame + measurement id), as the SDK lays them out.
pub fn to_scan(frame: &Frame, meta: &SensorMeta, lut: &XyzLut) -> LoadedScan {
    let (w, h) = (meta.columns_per_frame, meta.pixels_per_column);
    let (first, last) = meta.column_window;
    let staggered = |row: usize, v: usize| {
        (v as i64 - meta.pixel_shift_by_row[row]).rem_euclid(w as i64) as usize
    };
    let mut raw = Scan3d::with_capacity(w, h);
    let mut file_index = Vec::with_capacity(w * h);
    // Columns in the order of their middle beam's measurement, so stamps rise.
    let mid = h / 2;
    for k in 0..w {
        let v = (k as i64 + meta.pixel_shift_by_row[mid]).rem_euclid(w as i64) as usize;
        raw.begin_column(frame.stamps_ns[k.clamp(first, last)]);
        for row in (0..h).rev() {
            let m = staggered(row, v);
            let i = row * w + m;
            file_index.push(i as u32);
            let point = frame.column_valid[m]
                .then(|| lut.xyz_m(row, m, frame.ranges_mm[i]))
                .flatten();
            match point {
                Some([x, y, z]) => raw.push_xyz(x as f32, y as f32, z as f32),
                None => raw.push_invalid(),
            }
        }
    }
    LoadedScan {
        raw,
        track: PoseTrack::stationary(Isometry3::identity()),
        sensor_in_robot: Isometry3::identity(),
        file_index,
    }
}

/// A capture read scan by scan: [`FrameReader`] and [`to_scan`].
pub struct OusterScans {
    reader: FrameReader,
    lut: XyzLut,
}

impl OusterScans {
    /// Opens `pcap` with the metadata file `meta`.
    pub fn open(pcap: &Path, meta: &Path) -> Result<OusterScans, LoadError> {
        let meta = SensorMeta::load(meta)?;
        let lut = XyzLut::new(&meta);
        Ok(OusterScans {
            reader: FrameReader::open(pcap, meta)?,
            lut,
        })
    }

    /// The next complete frame as a scan, with its sensor frame id.
    pub fn next_scan(&mut self) -> Option<(u16, LoadedScan)> {
        let frame = self.reader.next_frame()?;
        Some((
            frame.frame_id,
            to_scan(&frame, self.reader.meta(), &self.lut),
        ))
    }

    /// What the read met so far.
    pub fn report(&self) -> OusterReport {
        self.reader.report()
    }

    /// The metadata the capture is read with.
    pub fn meta(&self) -> &SensorMeta {
        self.reader.meta()
    }
}

/// Reads every complete frame of `pcap`; an error naming the file if there is none.
pub fn load_all(pcap: &Path, meta: &Path) -> Result<(Vec<LoadedScan>, OusterReport), LoadError> {
    let mut scans = OusterScans::open(pcap, meta)?;
    let mut out = Vec::new();
    while let Some((_, scan)) = scans.next_scan() {
        out.push(scan);
    }
    let report = scans.report();
    if out.is_empty() {
        let mut why = report.warnings(pcap);
        if why.is_empty() {
            why.push(format!(
                "{}: no lidar packets on port {} ({} UDP datagrams)",
                pcap.display(),
                scans.meta().udp_port_lidar,
                report.counts.pcap.udp
            ));
        }
        return Err(LoadError::invalid(
            pcap,
            format!("no complete frame: {}", why.join("; ")),
        ));
    }
    Ok((out, report))
}

#[cfg(test)]
mod tests;

//! Ouster lidar packet layouts (Ouster's sensor docs, "Lidar Data Format"), little-endian.
//!
//! Legacy: `columns_per_packet` blocks of [timestamp u64, measurement id u16, frame id u16,
//! encoder u32, per pixel 12 bytes (range u32, low 20 bits, mm), status u32 (all ones:
//! valid)]. The profiles: a 32-byte packet header (type u16, frame id u16, …), per column
//! [timestamp u64, measurement id u16, status u16 (bit 0: valid)] and its pixels, then a
//! 32-byte footer. RNG19_RFL8_SIG16_NIR16 pixels are 12 bytes (range u32, low 19 bits, mm);
//! RNG15_RFL8_NIR8 pixels 4 bytes (range u16, low 15 bits, in units of 8 mm).

use super::meta::{Profile, SensorMeta};

/// One column's header.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ColumnHeader {
    /// The sensor's timestamp of the measurement (ns; its clock, not necessarily the epoch).
    pub stamp_ns: u64,
    /// The column's index in the rotation (0 .. columns_per_frame).
    pub measurement_id: u16,
    /// The sensor marked the column valid.
    pub valid: bool,
}

/// The byte layout of one sensor's lidar packets.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PacketLayout {
    /// The packet format.
    pub profile: Profile,
    /// Columns per packet.
    pub columns: usize,
    /// Pixels (beams) per column.
    pub rows: usize,
}

const HEADER: usize = 32;
const FOOTER: usize = 32;

impl PacketLayout {
    /// The layout `meta` describes.
    pub fn of(meta: &SensorMeta) -> PacketLayout {
        PacketLayout {
            profile: meta.profile,
            columns: meta.columns_per_packet,
            rows: meta.pixels_per_column,
        }
    }

    fn pixel_bytes(&self) -> usize {
        match self.profile {
            Profile::Legacy | Profile::Rng19Rfl8Sig16Nir16 => 12,
            Profile::Rng15Rfl8Nir8 => 4,
        }
    }

    fn column_bytes(&self) -> usize {
        match self.profile {
            Profile::Legacy => 16 + 12 * self.rows + 4,
            _ => 12 + self.pixel_bytes() * self.rows,
        }
    }

    fn column_start(&self, column: usize) -> usize {
        let header = if self.profile == Profile::Legacy {
            0
        } else {
            HEADER
        };
        header + column * self.column_bytes()
    }

    /// The size of every lidar packet (bytes).
    pub fn packet_bytes(&self) -> usize {
        let frame = if self.profile == Profile::Legacy {
            0
        } else {
            HEADER + FOOTER
        };
        frame + self.columns * self.column_bytes()
    }

    /// Checks a packet's size and type; the frame id it belongs to.
    pub fn frame_id(&self, packet: &[u8]) -> Result<u16, String> {
        if packet.len() != self.packet_bytes() {
            return Err(format!(
                "a lidar packet of {} bytes, expected {} ({:?}, {} columns of {} pixels)",
                packet.len(),
                self.packet_bytes(),
                self.profile,
                self.columns,
                self.rows
            ));
        }
        match self.profile {
            Profile::Legacy => Ok(u16_at(packet, 10)),
            _ => {
                let kind = u16_at(packet, 0);
                if kind != 1 {
                    return Err(format!("packet type {kind}, not a lidar packet (1)"));
                }
                Ok(u16_at(packet, 2))
            }
        }
    }

    /// The header of `column` of a packet whose size [`PacketLayout::frame_id`] checked.
    pub fn column(&self, packet: &[u8], column: usize) -> ColumnHeader {
        let at = self.column_start(column);
        let stamp_ns = u64::from_le_bytes(packet[at..at + 8].try_into().unwrap_or([0; 8]));
        let measurement_id = u16_at(packet, at + 8);
        let valid = match self.profile {
            Profile::Legacy => {
                let end = at + self.column_bytes() - 4;
                u32_at(packet, end) == u32::MAX
            }
            _ => u16_at(packet, at + 10) & 1 == 1,
        };
        ColumnHeader {
            stamp_ns,
            measurement_id,
            valid,
        }
    }

    /// The range of (`column`, `row`) in mm; 0 is no return.
    pub fn range_mm(&self, packet: &[u8], column: usize, row: usize) -> u32 {
        let first = if self.profile == Profile::Legacy {
            16
        } else {
            12
        };
        let at = self.column_start(column) + first + row * self.pixel_bytes();
        match self.profile {
            Profile::Legacy => u32_at(packet, at) & 0x000f_ffff,
            Profile::Rng19Rfl8Sig16Nir16 => u32_at(packet, at) & 0x0007_ffff,
            Profile::Rng15Rfl8Nir8 => (u16_at(packet, at) as u32 & 0x7fff) << 3,
        }
    }
}

fn u16_at(b: &[u8], i: usize) -> u16 {
    u16::from_le_bytes([b[i], b[i + 1]])
}

fn u32_at(b: &[u8], i: usize) -> u32 {
    u32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]])
}

/// Test helper: a packet of `layout` for `frame_id` whose columns start at `first_id`, with
/// each pixel's range (mm) from `range(column id, row)`.
#[cfg(test)]
pub(crate) fn build_packet(
    layout: &PacketLayout,
    frame_id: u16,
    first_id: u16,
    range: impl Fn(u16, usize) -> u32,
) -> Vec<u8> {
    let mut p = vec![0u8; layout.packet_bytes()];
    if layout.profile != Profile::Legacy {
        p[0..2].copy_from_slice(&1u16.to_le_bytes());
        p[2..4].copy_from_slice(&frame_id.to_le_bytes());
    }
    for c in 0..layout.columns {
        let id = first_id + c as u16;
        let at = layout.column_start(c);
        p[at..at + 8].copy_from_slice(&(1_000_000 + id as u64 * 97_656).to_le_bytes());
        p[at + 8..at + 10].copy_from_slice(&id.to_le_bytes());
        let first = match layout.profile {
            Profile::Legacy => {
                p[at + 10..at + 12].copy_from_slice(&frame_id.to_le_bytes());
                let end = at + layout.column_bytes() - 4;
                p[end..end + 4].copy_from_slice(&u32::MAX.to_le_bytes());
                16
            }
            _ => {
                p[at + 10] = 1;
                12
            }
        };
        for row in 0..layout.rows {
            let i = at + first + row * layout.pixel_bytes();
            let r = range(id, row);
            match layout.profile {
                Profile::Rng15Rfl8Nir8 => {
                    p[i..i + 2].copy_from_slice(&((r >> 3) as u16).to_le_bytes())
                }
                _ => p[i..i + 4].copy_from_slice(&r.to_le_bytes()),
            }
        }
    }
    p
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_three_layouts_have_their_documented_sizes_and_round_trip() {
        for (profile, size) in [
            (Profile::Legacy, 24896),
            (Profile::Rng19Rfl8Sig16Nir16, 24832),
            (Profile::Rng15Rfl8Nir8, 8448),
        ] {
            let layout = PacketLayout {
                profile,
                columns: 16,
                rows: 128,
            };
            assert_eq!(layout.packet_bytes(), size, "{profile:?}");
            let packet = build_packet(&layout, 9, 32, |id, row| 8 * (id as u32 * 200 + row as u32));
            assert_eq!(layout.frame_id(&packet), Ok(9));
            let h = layout.column(&packet, 3);
            assert_eq!((h.measurement_id, h.valid), (35, true));
            assert_eq!(layout.range_mm(&packet, 3, 127), 8 * 7_127, "{profile:?}");
            assert!(
                layout
                    .frame_id(&packet[1..])
                    .unwrap_err()
                    .contains("expected")
            );
        }
    }
}

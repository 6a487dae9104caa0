//! Writes the `pcap_ouster` target's seeds for its tiny sensors into the folder given
//! (README.md, "Corpora"): for each packet profile, a capture holding one whole frame (the
//! three packets of columns 2 to 13), a packet of the next frame, and an IMU datagram;
//! Ethernet, Ethernet with an 802.1Q tag, or Linux cooked (SLL) frames; one capture in big
//! endian with ns stamps. The excerpts of the shared capture come from `make-seeds.sh`.
//! Deterministic.
//!
//!     cargo run --manifest-path fuzz/Cargo.toml --example pcap_ouster_seeds -- DIR

use std::path::Path;

/// The target's tiny sensor: 2 beams, 4 columns a packet.
const ROWS: usize = 2;
const COLUMNS: usize = 4;

#[derive(Clone, Copy, PartialEq)]
enum Profile {
    Legacy,
    Rng19,
    Rng15,
}

#[derive(Clone, Copy)]
enum Link {
    Ethernet,
    Vlan,
    LinuxSll,
}

/// A lidar packet (Ouster's "Lidar Data Format"; `scanio/src/ouster/packet.rs`) of
/// `frame_id` with the columns from `first_id`.
fn packet(profile: Profile, frame_id: u16, first_id: u16) -> Vec<u8> {
    let pixel = if profile == Profile::Rng15 { 4 } else { 12 };
    let mut p = Vec::new();
    if profile != Profile::Legacy {
        p.extend(1u16.to_le_bytes());
        p.extend(frame_id.to_le_bytes());
        p.resize(32, 0);
    }
    for c in 0..COLUMNS as u16 {
        let id = first_id + c;
        p.extend((1_000_000 + u64::from(id) * 97_656).to_le_bytes());
        p.extend(id.to_le_bytes());
        match profile {
            Profile::Legacy => p.extend(frame_id.to_le_bytes()),
            _ => p.extend(1u16.to_le_bytes()),
        }
        if profile == Profile::Legacy {
            p.extend(90_000u32.to_le_bytes());
        }
        for row in 0..ROWS {
            let range_mm = 2_000 + 8 * (u32::from(id) * 10 + row as u32);
            let mut bytes = match profile {
                Profile::Rng15 => ((range_mm >> 3) as u16).to_le_bytes().to_vec(),
                _ => range_mm.to_le_bytes().to_vec(),
            };
            bytes.resize(pixel, 0x11);
            p.extend(bytes);
        }
        if profile == Profile::Legacy {
            p.extend(u32::MAX.to_le_bytes());
        }
    }
    if profile != Profile::Legacy {
        p.extend([0u8; 32]);
    }
    p
}

/// A link-layer frame holding an IPv4/UDP datagram to `port`.
fn frame(link: Link, port: u16, payload: &[u8]) -> Vec<u8> {
    let udp_len = 8 + payload.len() as u16;
    let mut f = match link {
        Link::Ethernet => [vec![0u8; 12], 0x0800u16.to_be_bytes().to_vec()].concat(),
        Link::Vlan => [
            vec![0u8; 12],
            0x8100u16.to_be_bytes().to_vec(),
            vec![0, 7],
            0x0800u16.to_be_bytes().to_vec(),
        ]
        .concat(),
        Link::LinuxSll => [vec![0u8; 14], 0x0800u16.to_be_bytes().to_vec()].concat(),
    };
    f.extend([0x45, 0]);
    f.extend((20 + udp_len).to_be_bytes());
    f.extend([0, 0, 0x40, 0, 64, 17, 0, 0]);
    f.extend([10, 5, 5, 87, 10, 5, 5, 1]);
    f.extend(7502u16.to_be_bytes());
    f.extend(port.to_be_bytes());
    f.extend(udp_len.to_be_bytes());
    f.extend([0, 0]);
    f.extend(payload);
    f
}

/// A capture of `frames` (record time, link frame) in the byte order asked.
fn capture(link: Link, big_endian: bool, frames: &[(u32, Vec<u8>)]) -> Vec<u8> {
    let u32s = |values: &[u32]| -> Vec<u8> {
        values
            .iter()
            .flat_map(|v| {
                if big_endian {
                    v.to_be_bytes()
                } else {
                    v.to_le_bytes()
                }
            })
            .collect()
    };
    // Magic (µs, or ns in big endian), version 2.4, zone, accuracy, snap length, link.
    let magic = if big_endian { 0xa1b2_3c4d } else { 0xa1b2_c3d4 };
    let link_type = match link {
        Link::LinuxSll => 113,
        Link::Ethernet | Link::Vlan => 1,
    };
    let version = (2u16, 4u16);
    let mut c = u32s(&[magic]);
    for v in [version.0, version.1] {
        c.extend(if big_endian {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        });
    }
    c.extend(u32s(&[0, 0, 65_535, link_type]));
    for (i, (secs, f)) in frames.iter().enumerate() {
        let len = f.len() as u32;
        c.extend(u32s(&[*secs, i as u32 * 2_500, len, len]));
        c.extend(f);
    }
    c
}

fn main() {
    let dir = std::env::args()
        .nth(1)
        .expect("usage: pcap_ouster_seeds DIR (the folder to write the seeds into)");
    let dir = Path::new(&dir);
    std::fs::create_dir_all(dir).expect("seed folder");
    for (name, profile, link, big_endian) in [
        ("tiny-legacy", Profile::Legacy, Link::Ethernet, false),
        ("tiny-rng19-vlan", Profile::Rng19, Link::Vlan, false),
        ("tiny-rng15-sll-be-ns", Profile::Rng15, Link::LinuxSll, true),
    ] {
        let lidar =
            |frame_id, first_id| (100, frame(link, 7502, &packet(profile, frame_id, first_id)));
        let frames = [
            lidar(7, 2),
            lidar(7, 6),
            (100, frame(link, 7503, &[0x5a; 48])),
            lidar(7, 10),
            lidar(8, 2),
        ];
        std::fs::write(dir.join(name), capture(link, big_endian, &frames)).expect("a seed written");
    }
}

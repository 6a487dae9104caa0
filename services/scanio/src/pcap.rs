//! Classic pcap capture files (not pcapng), read as a stream of UDP datagrams.
//!
//! Both byte orders and both time resolutions (magic `a1b2c3d4` µs, `a1b23c4d` ns); link
//! types Ethernet (with one optional 802.1Q tag), Linux cooked (SLL) and raw IPv4. IPv4
//! fragments are counted and skipped, not reassembled: the Ouster captures we read hold whole
//! datagrams (the capture host reassembled them). A file that ends inside a record is a
//! partial read, reported through [`PcapReader::truncated`], never a panic.

use crate::LoadError;
use std::io::{BufReader, Read};
use std::path::{Path, PathBuf};

/// One UDP datagram of the capture.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct UdpDatagram {
    /// The capture's record time (ns since the Unix epoch).
    pub stamp_ns: u64,
    /// UDP destination port.
    pub dst_port: u16,
    /// UDP payload.
    pub payload: Vec<u8>,
}

/// What the reader met besides UDP datagrams.
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct PcapCounts {
    /// Records read.
    pub records: u64,
    /// UDP datagrams returned.
    pub udp: u64,
    /// Records that are not IPv4 UDP (ARP, IPv6, TCP, …).
    pub not_udp: u64,
    /// IPv4 fragments (skipped: not reassembled).
    pub fragments: u64,
    /// Records shorter than their headers say (captured with a small snap length).
    pub short: u64,
}

/// Link-layer header kinds (pcap LINKTYPE_*).
#[derive(Clone, Copy, Debug)]
enum Link {
    Ethernet,
    LinuxSll,
    RawIp,
}

/// A streaming pcap reader over any byte source.
pub struct PcapReader<R: Read> {
    input: R,
    path: PathBuf,
    big_endian: bool,
    nanos: bool,
    link: Link,
    counts: PcapCounts,
    truncated: Option<String>,
    offset: u64,
}

impl PcapReader<BufReader<std::fs::File>> {
    /// Opens a pcap file and reads its global header.
    pub fn open(path: &Path) -> Result<Self, LoadError> {
        let file = std::fs::File::open(path).map_err(|error| LoadError::Io {
            path: path.to_owned(),
            error,
        })?;
        PcapReader::new(BufReader::with_capacity(1 << 16, file), path)
    }
}

impl<R: Read> PcapReader<R> {
    /// Reads the 24-byte global header from `input` (`path` names it in errors).
    pub fn new(mut input: R, path: &Path) -> Result<Self, LoadError> {
        let mut header = [0u8; 24];
        let got = read_full(&mut input, &mut header).map_err(|error| LoadError::Io {
            path: path.to_owned(),
            error,
        })?;
        if got == 0 {
            return Err(LoadError::Empty {
                path: path.to_owned(),
            });
        }
        if got < 24 {
            return Err(LoadError::invalid(
                path,
                format!("truncated pcap: {got} bytes, the global header alone is 24"),
            ));
        }
        let magic = u32::from_le_bytes([header[0], header[1], header[2], header[3]]);
        let (big_endian, nanos) = match magic {
            0xa1b2_c3d4 => (false, false),
            0xa1b2_3c4d => (false, true),
            0xd4c3_b2a1 => (true, false),
            0x4d3c_b2a1 => (true, true),
            0x0a0d_0d0a => {
                return Err(LoadError::invalid(
                    path,
                    "a pcapng file: only classic pcap is read (convert with `editcap -F pcap`)",
                ));
            }
            _ => {
                return Err(LoadError::invalid(
                    path,
                    format!("not a pcap file (magic {magic:#010x})"),
                ));
            }
        };
        let u32_at = |i: usize| read_u32(&header[i..i + 4], big_endian);
        let link = match u32_at(20) & 0x0fff_ffff {
            1 => Link::Ethernet,
            113 => Link::LinuxSll,
            101 | 228 => Link::RawIp,
            other => {
                return Err(LoadError::invalid(
                    path,
                    format!("pcap link type {other} is not read (Ethernet, Linux SLL, raw IPv4)"),
                ));
            }
        };
        Ok(PcapReader {
            input,
            path: path.to_owned(),
            big_endian,
            nanos,
            link,
            counts: PcapCounts::default(),
            truncated: None,
            offset: 24,
        })
    }

    /// The path the capture was opened with (for messages).
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The counts so far.
    pub fn counts(&self) -> &PcapCounts {
        &self.counts
    }

    /// Why the file ended early, naming it; `None` after a clean end.
    pub fn truncated(&self) -> Option<&str> {
        self.truncated.as_deref()
    }

    /// The next UDP datagram; `None` at the end of the file (clean or truncated).
    pub fn next_udp(&mut self) -> Option<UdpDatagram> {
        loop {
            let (stamp_ns, record) = self.next_record()?;
            self.counts.records += 1;
            match parse_udp(&record, self.link) {
                Parsed::Udp { dst_port, payload } => {
                    self.counts.udp += 1;
                    return Some(UdpDatagram {
                        stamp_ns,
                        dst_port,
                        payload: record[payload].to_vec(),
                    });
                }
                Parsed::NotUdp => self.counts.not_udp += 1,
                Parsed::Fragment => self.counts.fragments += 1,
                Parsed::Short => self.counts.short += 1,
            }
        }
    }

    fn next_record(&mut self) -> Option<(u64, Vec<u8>)> {
        if self.truncated.is_some() {
            return None;
        }
        let mut header = [0u8; 16];
        match read_full(&mut self.input, &mut header) {
            Ok(0) => return None,
            Ok(16) => {}
            Ok(n) => return self.cut(&format!("a record header of {n} of 16 bytes")),
            Err(e) => return self.cut(&format!("read error: {e}")),
        }
        let be = self.big_endian;
        let (secs, frac) = (read_u32(&header[0..4], be), read_u32(&header[4..8], be));
        let incl = read_u32(&header[8..12], be) as usize;
        // No link layer frame is near 256 KiB; a bigger length is a corrupt header.
        if incl > 1 << 18 {
            return self.cut(&format!("a record of {incl} bytes (corrupt header)"));
        }
        let mut data = vec![0u8; incl];
        match read_full(&mut self.input, &mut data) {
            Ok(n) if n == incl => {}
            Ok(n) => return self.cut(&format!("a record of {n} of {incl} bytes")),
            Err(e) => return self.cut(&format!("read error: {e}")),
        }
        self.offset += 16 + incl as u64;
        let frac_ns = if self.nanos {
            frac as u64
        } else {
            frac as u64 * 1000
        };
        Some((secs as u64 * 1_000_000_000 + frac_ns, data))
    }

    fn cut<T>(&mut self, what: &str) -> Option<T> {
        self.truncated = Some(format!(
            "{}: truncated pcap: ends in {what} at byte {} after {} records",
            self.path.display(),
            self.offset,
            self.counts.records
        ));
        None
    }
}

enum Parsed {
    Udp {
        dst_port: u16,
        payload: std::ops::Range<usize>,
    },
    NotUdp,
    Fragment,
    Short,
}

fn parse_udp(frame: &[u8], link: Link) -> Parsed {
    let be16 = |i: usize| {
        frame
            .get(i..i + 2)
            .map(|b| u16::from_be_bytes([b[0], b[1]]))
    };
    let ip = match link {
        Link::RawIp => 0,
        Link::LinuxSll => match be16(14) {
            Some(0x0800) => 16,
            Some(_) => return Parsed::NotUdp,
            None => return Parsed::Short,
        },
        Link::Ethernet => match (be16(12), be16(16)) {
            (Some(0x0800), _) => 14,
            (Some(0x8100), Some(0x0800)) => 18,
            (Some(_), _) => return Parsed::NotUdp,
            (None, _) => return Parsed::Short,
        },
    };
    let Some(&version_ihl) = frame.get(ip) else {
        return Parsed::Short;
    };
    let ihl = (version_ihl & 0x0f) as usize * 4;
    if version_ihl >> 4 != 4 {
        return Parsed::NotUdp;
    }
    let (Some(total), Some(flags), Some(&protocol)) =
        (be16(ip + 2), be16(ip + 6), frame.get(ip + 9))
    else {
        return Parsed::Short;
    };
    if protocol != 17 {
        return Parsed::NotUdp;
    }
    // More fragments, or a fragment offset: part of a datagram.
    if flags & 0x2000 != 0 || flags & 0x1fff != 0 {
        return Parsed::Fragment;
    }
    let udp = ip + ihl;
    let (Some(dst_port), Some(udp_len)) = (be16(udp + 2), be16(udp + 4)) else {
        return Parsed::Short;
    };
    let end = udp + udp_len as usize;
    if ihl < 20 || (udp_len as usize) < 8 || end > frame.len() || end > ip + total as usize {
        return Parsed::Short;
    }
    Parsed::Udp {
        dst_port,
        payload: udp + 8..end,
    }
}

fn read_u32(b: &[u8], big_endian: bool) -> u32 {
    let b = [b[0], b[1], b[2], b[3]];
    if big_endian {
        u32::from_be_bytes(b)
    } else {
        u32::from_le_bytes(b)
    }
}

/// Reads until `buf` is full or the input ends; the number of bytes read.
fn read_full(input: &mut impl Read, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut got = 0;
    while got < buf.len() {
        match input.read(&mut buf[got..]) {
            Ok(0) => break,
            Ok(n) => got += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(got)
}

/// Test helpers: builds capture bytes (used by this crate's tests).
#[cfg(test)]
pub(crate) mod build {
    /// A little-endian µs pcap header, Ethernet link.
    pub fn header() -> Vec<u8> {
        let mut h = Vec::new();
        h.extend(0xa1b2_c3d4u32.to_le_bytes());
        h.extend(2u16.to_le_bytes());
        h.extend(4u16.to_le_bytes());
        h.extend([0u8; 8]);
        h.extend(65535u32.to_le_bytes());
        h.extend(1u32.to_le_bytes());
        h
    }

    /// One Ethernet/IPv4/UDP record to `port` carrying `payload`, at `secs`.
    pub fn record(secs: u32, port: u16, payload: &[u8]) -> Vec<u8> {
        let udp_len = 8 + payload.len() as u16;
        let mut f = vec![0u8; 12];
        f.extend(0x0800u16.to_be_bytes());
        f.extend([0x45, 0]);
        f.extend((20 + udp_len).to_be_bytes());
        f.extend([0, 0, 0x40, 0, 64, 17, 0, 0]);
        f.extend([10, 0, 0, 1, 10, 0, 0, 2]);
        f.extend(7502u16.to_be_bytes());
        f.extend(port.to_be_bytes());
        f.extend(udp_len.to_be_bytes());
        f.extend([0, 0]);
        f.extend(payload);
        let mut r = Vec::new();
        r.extend(secs.to_le_bytes());
        r.extend(0u32.to_le_bytes());
        r.extend((f.len() as u32).to_le_bytes());
        r.extend((f.len() as u32).to_le_bytes());
        r.extend(f);
        r
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read_all(bytes: &[u8]) -> (Vec<UdpDatagram>, PcapCounts, Option<String>) {
        let mut reader = PcapReader::new(bytes, Path::new("t.pcap")).unwrap();
        let mut out = Vec::new();
        while let Some(d) = reader.next_udp() {
            out.push(d);
        }
        (
            out,
            reader.counts().clone(),
            reader.truncated().map(str::to_owned),
        )
    }

    #[test]
    fn datagrams_come_out_with_port_payload_and_time() {
        let mut bytes = build::header();
        bytes.extend(build::record(3, 7502, b"abc"));
        bytes.extend(build::record(4, 7503, b"de"));
        let (out, counts, cut) = read_all(&bytes);
        assert_eq!(cut, None);
        assert_eq!(counts.udp, 2);
        assert_eq!(out[0].payload, b"abc");
        assert_eq!((out[1].dst_port, out[1].stamp_ns), (7503, 4_000_000_000));
    }

    #[test]
    fn big_endian_nanosecond_files_are_read() {
        let mut bytes = build::header();
        bytes[..4].copy_from_slice(&0xa1b2_3c4du32.to_be_bytes());
        bytes[20..24].copy_from_slice(&1u32.to_be_bytes());
        let mut record = build::record(0, 7502, b"x");
        // Record header fields in big-endian: secs 2, 5 ns, lengths.
        let len = u32::from_le_bytes(record[8..12].try_into().unwrap());
        record[0..4].copy_from_slice(&2u32.to_be_bytes());
        record[4..8].copy_from_slice(&5u32.to_be_bytes());
        record[8..12].copy_from_slice(&len.to_be_bytes());
        record[12..16].copy_from_slice(&len.to_be_bytes());
        bytes.extend(record);
        let (out, _, cut) = read_all(&bytes);
        assert_eq!(cut, None);
        assert_eq!(out[0].stamp_ns, 2_000_000_005);
    }

    #[test]
    fn a_cut_file_is_a_reported_partial_read_naming_it() {
        let mut bytes = build::header();
        bytes.extend(build::record(3, 7502, b"abc"));
        bytes.extend(build::record(4, 7502, b"defg"));
        for cut in [bytes.len() - 2, bytes.len() - 40] {
            let (out, _, why) = read_all(&bytes[..cut]);
            assert_eq!(out.len(), 1);
            assert!(why.unwrap().starts_with("t.pcap: truncated pcap"));
        }
        let e = PcapReader::new(&bytes[..10], Path::new("t.pcap"))
            .err()
            .unwrap();
        assert!(e.to_string().starts_with("t.pcap: truncated pcap"), "{e}");
        assert!(PcapReader::new(&b"not a pcap file at all, no"[..], Path::new("t.pcap")).is_err());
    }

    #[test]
    fn fragments_and_other_protocols_are_counted_not_returned() {
        let mut bytes = build::header();
        let mut fragment = build::record(1, 7502, b"abc");
        fragment[16 + 20] = 0x20; // more fragments
        bytes.extend(fragment);
        let mut tcp = build::record(1, 7502, b"abc");
        tcp[16 + 23] = 6;
        bytes.extend(tcp);
        let (out, counts, _) = read_all(&bytes);
        assert!(out.is_empty());
        assert_eq!((counts.fragments, counts.not_udp), (1, 1));
    }
}

//! The bytes of a map version file, as `POST …/versions/import` and `levelmap map import`
//! take them (`wire::decode_map_version_file`), and what the mapper does with a version that
//! passes: it is written again (numbered, imported) and read back, its grid written as PGM
//! for map_server, its scans as point sets. The same bytes also go to the field checks
//! straight (`MapVersion` decoded and checked without the file around it): the file's CRC-32
//! refuses nearly every mutation before them.
#![no_main]

use libfuzzer_sys::fuzz_target;
use slam::matching::Scan2;
use wire::{MapVersion, Message, v1};

fuzz_target!(|data: &[u8]| {
    if let Ok(version) = wire::decode_map_version_file(data) {
        taken(version);
    }
    if let Ok(msg) = v1::MapVersion::decode(data)
        && let Ok(version) = wire::map_version_from_wire(&msg)
    {
        taken(version);
    }
});

/// A version that passed: stored under another number, read back as it was; its grid as a
/// PGM; each node's returns as a scan.
fn taken(mut version: MapVersion) {
    version.number = version.number.saturating_add(1);
    if let Ok(file) = wire::encode_map_version_file(&version) {
        let back = wire::decode_map_version_file(&file).expect("a version written reads back");
        assert_eq!(back, version, "a version read back differs");
    }
    let _ = graphio::gridmap::to_pgm(&version.grid);
    for node in &version.nodes {
        let (bearings, ranges): (Vec<f32>, Vec<f32>) = node.returns().unzip();
        Scan2::from_polar(&bearings, &ranges, f32::MAX).expect("returns come in pairs");
    }
}

//! CARMEN log text (`.clf`, `.log`; `levelmap slam2d LOG`): `graphio::carmen::parse`, the
//! function `read(path)` calls on the decompressed file. Decompression (`.gz`, `.bz2`) is
//! flate2's and bzip2's, not fuzzed here. A log read strictly must read the same when bad
//! lines are skipped, with none skipped; every scan must become a point set (`to_scan2`).
#![no_main]

use graphio::carmen::{ReadOptions, parse};
use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let path = Path::new("fuzz.clf");
    let strict = parse(data, path, &ReadOptions::default());
    let lenient = parse(
        data,
        path,
        &ReadOptions {
            skip_bad_lines: true,
            ..ReadOptions::default()
        },
    );
    if let Ok(log) = &strict {
        let lenient = lenient.as_ref().expect("a strict read reads leniently");
        assert!(lenient.bad_lines.is_empty());
        assert_eq!(lenient, log);
    }
    if let Ok(log) = lenient {
        for scan in &log.scans {
            let points = scan.to_scan2();
            assert!(points.len() <= scan.ranges_m.len());
        }
    }
});

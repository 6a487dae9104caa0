//! Kümmerle relations text (`levelmap slam2d LOG --relations FILE`):
//! `graphio::relations::parse`, the function `read(path)` calls on the decompressed file.
#![no_main]

use graphio::relations::parse;
use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    if let Ok(relations) = parse(data, Path::new("fuzz.relations")) {
        for r in &relations {
            assert!(r.t1_s.is_finite() && r.t2_s.is_finite() && r.delta.is_finite());
        }
    }
});

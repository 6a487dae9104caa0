//! The bytes of a `POST …/localize` request (`levelmap.v1.LocalizeRequest`, decoded by
//! `wire::decode_localize_request`, the API's own check), and what the mapper does with a
//! request that passes: the scan found on a small fixed map
//! (`LocalizationMap::relocalize`: the prior's window, then the whole map), and the answer put
//! on the wire as the API puts it. The same bytes also go to the edge's decoder of the
//! mapper's localizations (`wire::decode_localization`).
#![no_main]

use libfuzzer_sys::fuzz_target;
use slam::Pose2;
use slam::localize::{LocalizationMap, LocalizeParams, Prior, TrackStatus};
use slam::matching::Scan2;
use slam::matching::synthetic::{Scene, uniform_bearings};
use std::sync::OnceLock;
use wire::{Localized, Message};

/// The mapper's default range cut (`MapperConfig::max_range_m`): the API cuts a request's
/// scan there, and the map's scans were cut there.
const MAX_RANGE_M: f32 = 40.0;

fuzz_target!(|data: &[u8]| {
    if let Ok(query) = wire::decode_localize_request(data) {
        // What the API does with a request that passes: its scan cut at the mapper's range,
        // its prior's 3σ window.
        localized(&query.scan2(MAX_RANGE_M), query.prior_window().as_ref());
    }
    if let Ok(l) = wire::decode_localization(data) {
        let bytes = wire::localization_to_wire(&l).encode_to_vec();
        let back = wire::decode_localization(&bytes).expect("a localization re-encoded decodes");
        assert_eq!(back, l, "a localization re-encoded differs");
    }
});

/// The scan found on the map: a pose found is finite, its covariance finite and symmetric;
/// the answer, as the API sends it (`api/localize.rs`), passes the edge's decoder.
fn localized(scan: &Scan2, prior: Option<&Prior>) {
    let result = map().relocalize(scan, prior);
    if let Ok(found) = &result {
        assert!(
            found.pose.is_finite(),
            "a pose found is not finite: {found:?}"
        );
        let c = found.covariance;
        assert!(
            c.iter().flatten().all(|v| v.is_finite()),
            "a covariance is not finite: {found:?}"
        );
        // Symmetric to rounding (R Σ Rᵀ is computed, not mirrored: the last bits differ), a
        // variance not negative.
        let symmetric = |i: usize, j: usize| {
            let scale = c[i][j]
                .abs()
                .max(c[j][i].abs())
                .max((c[i][i] * c[j][j]).abs().sqrt());
            (c[i][j] - c[j][i]).abs() <= 1e-9 * scale
        };
        assert!(
            (0..3).all(|i| c[i][i] >= 0.0 && (0..3).all(|j| symmetric(i, j))),
            "a covariance is not symmetric: {found:?}"
        );
        assert!(found.score.is_finite(), "a score is not finite: {found:?}");
    }
    let answer = Localized {
        fleet: "park".into(),
        robot: String::new(),
        chain_id: 0,
        node_seq: 0,
        map_version: 1,
        status: match result {
            Ok(_) => TrackStatus::Localized,
            Err(_) => TrackStatus::Lost,
        },
        pose: result.as_ref().ok().map(|l| l.pose),
        covariance: result.as_ref().ok().map(|l| l.covariance),
        score: result.as_ref().map_or(0.0, |l| l.score),
        search: result.as_ref().ok().map(|l| l.search),
        sent_ns: 1,
        reason: result
            .as_ref()
            .err()
            .map_or(String::new(), |e| e.to_string()),
    };
    let bytes = wire::localization_to_wire(&answer).encode_to_vec();
    let back = wire::decode_localization(&bytes).expect("the API's answer passes the edge");
    assert_eq!(back, answer, "the API's answer differs at the edge");
}

/// The poses of the map's scans in the synthetic park (`Scene::park`), in its free middle.
const MAP_POSES: [(f64, f64, f64); 5] = [
    (-2.0, 0.0, 0.0),
    (-1.0, 0.5, 0.6),
    (0.0, 0.0, -0.4),
    (1.0, -0.5, 1.2),
    (2.0, 0.0, -1.0),
];

/// A small map built once: five scans of the synthetic park (360 beams, cut at the mapper's
/// range), in tiles of 4 m (the default grid), so that a global search takes milliseconds.
fn map() -> &'static LocalizationMap {
    static MAP: OnceLock<LocalizationMap> = OnceLock::new();
    MAP.get_or_init(|| {
        let scene = Scene::park();
        let bearings = uniform_bearings(360, -std::f64::consts::PI, std::f64::consts::TAU / 360.0);
        let scans = MAP_POSES
            .iter()
            .enumerate()
            .map(|(k, &(x, y, theta))| {
                let pose = Pose2::new(x, y, theta);
                let ranges = scene.scan(&pose, &bearings, MAX_RANGE_M, 0.01, k as u64);
                let scan = Scan2::from_polar(&bearings, &ranges, MAX_RANGE_M).expect("a scan");
                (pose, scan)
            })
            .collect();
        let params = LocalizeParams {
            tile_m: 4.0,
            ..LocalizeParams::default()
        };
        LocalizationMap::new(scans, params).expect("the park's map")
    })
}

//! Writes the seed inputs of the `localize` target into the folder given (README.md,
//! "Corpora"): localize requests whose scan is the synthetic park (`Scene::park`, the target's
//! map) seen from a place between the map's scans, without a prior, with a right one and with
//! one 3 m off (its default σ); and the mapper's localizations (found, carried forward by
//! odometry, lost). Each is encoded with wire's own conversions and checked to decode.
//! Deterministic.
//!
//!     cargo run --manifest-path fuzz/Cargo.toml --example localize_seeds -- DIR

use leveling::{Beam, ClassCounts, LeveledScan};
use slam::Pose2;
use slam::localize::{SearchKind, TrackStatus};
use slam::matching::synthetic::{Scene, uniform_bearings};
use std::path::Path;
use wire::{Localized, Message, v1};

/// The scan seen at `pose` in the park: `beams` beams all around, ranges to 30 m (none
/// beyond: no return).
fn scan(pose: &Pose2, beams: usize, seed: u64) -> v1::LeveledScan {
    let max_range = 30.0;
    let bearings = uniform_bearings(
        beams,
        -std::f64::consts::PI,
        std::f64::consts::TAU / beams as f64,
    );
    let ranges = Scene::park().scan(pose, &bearings, max_range, 0.01, seed);
    let scan = LeveledScan {
        stamp_ns: 1_700_000_000_000_000_000,
        beams: bearings
            .iter()
            .zip(&ranges)
            .map(|(&bearing_rad, &r)| Beam {
                bearing_rad,
                range_m: (r < max_range).then_some(r),
            })
            .collect(),
    };
    let counts = ClassCounts {
        invalid: 3,
        ground: 40,
        landmark: scan.return_count(),
        overhang: 1,
    };
    let header = v1::Header::new("park", "rover-4", 9, 0, 1_700_000_000_050_000_000);
    wire::leveled_scan_to_wire(&scan, Some(&counts), header)
}

fn request(
    scan: v1::LeveledScan,
    prior: Option<Pose2>,
    sigma: (f64, f64),
    map_version: u64,
) -> v1::LocalizeRequest {
    v1::LocalizeRequest {
        version: wire::WIRE_VERSION,
        scan: Some(scan),
        prior: prior.as_ref().map(wire::pose2_to_wire),
        prior_sigma_xy_m: sigma.0,
        prior_sigma_yaw_rad: sigma.1,
        map_version,
    }
}

fn found() -> Localized {
    Localized {
        fleet: "park".into(),
        robot: "rover-4".into(),
        chain_id: 0x5eed,
        node_seq: 42,
        map_version: 3,
        status: TrackStatus::Localized,
        pose: Some(Pose2::new(0.37, 0.12, 2.9)),
        covariance: Some([[1e-4, 2e-6, 0.0], [2e-6, 2e-4, 1e-6], [0.0, 1e-6, 1e-5]]),
        score: 0.71,
        search: Some(SearchKind::Window),
        sent_ns: 1_700_000_000_100_000_000,
        reason: String::new(),
    }
}

fn main() {
    let dir = std::env::args()
        .nth(1)
        .expect("usage: localize_seeds DIR (the folder to write the seeds into)");
    let dir = Path::new(&dir);
    std::fs::create_dir_all(dir).expect("seed folder");
    let truth = Pose2::new(0.37, 0.12, 2.9);
    let off = Pose2::new(truth.x - 3.0, truth.y, truth.theta);
    let requests = [
        (
            "request-global",
            request(scan(&truth, 180, 1), None, (0.0, 0.0), 0),
        ),
        (
            "request-prior",
            request(scan(&truth, 180, 2), Some(truth), (0.3, 0.05), 1),
        ),
        (
            "request-prior-off-default-sigma",
            request(scan(&truth, 90, 3), Some(off), (0.0, 0.0), 0),
        ),
    ];
    for (name, msg) in &requests {
        let bytes = msg.encode_to_vec();
        wire::decode_localize_request(&bytes).expect("a seed request decodes");
        std::fs::write(dir.join(name), bytes).expect("seed written");
    }
    let localizations = [
        ("localization-found", found()),
        (
            "localization-dead-reckoned",
            Localized {
                status: TrackStatus::DeadReckoned,
                covariance: None,
                score: 0.0,
                search: None,
                reason: "not found: no pose scores 0.55".into(),
                ..found()
            },
        ),
        (
            "localization-lost-http",
            Localized {
                robot: String::new(),
                chain_id: 0,
                node_seq: 0,
                status: TrackStatus::Lost,
                pose: None,
                covariance: None,
                score: 0.0,
                search: None,
                reason: "ambiguous: 0.700 here, 0.650 4.2 m away".into(),
                ..found()
            },
        ),
        (
            "localization-global",
            Localized {
                search: Some(SearchKind::Global),
                ..found()
            },
        ),
    ];
    for (name, l) in &localizations {
        let bytes = wire::localization_to_wire(l).encode_to_vec();
        assert_eq!(
            &wire::decode_localization(&bytes).expect("a seed localization decodes"),
            l
        );
        std::fs::write(dir.join(name), bytes).expect("seed written");
    }
}

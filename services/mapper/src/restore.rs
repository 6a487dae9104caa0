//! The store read back at start. The nodes (with the spans, chains, modes and versions) are
//! the record; the edges and the snapshot are derived from them by a mapping version
//! (`fleetmap::MAPPING_CODE` and the parameters, recorded per fleet in the store):
//! - a fleet mapped by the running version is restored from its newest snapshot and the
//!   nodes stored after it, or without a usable one replayed from all of its nodes; either
//!   way the nodes are mapped again through the same deterministic mapper, each stored solve
//!   taken and applied at its points, and the rebuilt edges are checked against the stored
//!   ones;
//! - a fleet mapped by another version (an upgrade, a changed `[mapping]` key, a store of
//!   format 0), or whose replay does not give the stored edges, is **rebuilt**: replayed from
//!   all of its nodes by the running version, and its edges, snapshot and mapping version
//!   written anew. The solve points stay: they record when solves ran (a matter of the
//!   clock, not of the nodes).
//!
//! Only rows that cannot be read or mapped quarantine a fleet.
//!
//! [`verify_store`] is the check behind `levelmap mapper --verify-store`: every fleet
//! replayed in full, ignoring its snapshot, and compared with the stored edges and with what
//! its snapshot restores; and which fleets a start would rebuild.

use crate::config::MapperConfig;
use crate::store::{MappingVersion, SolvePoint, Store, StoredFleet};
use crate::views::{Metrics, Shared};
use anyhow::{Context, Result};
use fleetmap::{FleetMap, SpanReplay};
use serde::Serialize;
use std::collections::HashMap;
use std::time::Instant;

/// The fleets restored, and how many nodes of each its snapshot covered (0: replayed in
/// full).
pub type Restored = (HashMap<String, FleetMap>, HashMap<String, usize>);

/// What a fleet whose store records no mapping version is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Unrecorded {
    /// Rows of a store of format 0: rebuilt by the running version.
    Rebuilt,
    /// Rows read from a site's log (cluster mode), which carry no mapping version: presumed
    /// the running one. The edges are checked all the same, and a site whose writer mapped
    /// otherwise is rebuilt.
    Running,
}

/// Restores the store, fleet by fleet ([`restore_fleet`]); a fleet that does not replay is
/// quarantined and the others restored. The configured fleets without rows yet are then
/// recorded as mapped by the running version.
pub fn restore(config: &MapperConfig, store: &Store, shared: &Shared) -> Result<Restored> {
    let (mut fleets, mut covered) = (HashMap::new(), HashMap::new());
    for id in store.fleet_ids()? {
        if let Ok((map, from)) = restore_fleet(config, store, shared, &id, Unrecorded::Rebuilt) {
            shared.publish_map(&map, 0.0);
            covered.insert(id.clone(), from);
            fleets.insert(id, map);
        }
    }
    let running = crate::mapping::mapping_version(config);
    let mut due = Vec::new();
    for id in &config.fleets {
        let unmapped = !fleets.contains_key(id) && shared.quarantine(id).is_none();
        if unmapped && store.mapping_version(id)?.as_ref() != Some(&running) {
            due.push(id.as_str());
        }
    }
    store.set_mapping_version(&due, &running)?;
    Ok((fleets, covered))
}

/// One fleet's map, for a start and a cluster host's takeover alike: from its snapshot if it
/// has a usable one, else replayed, else rebuilt (counted in `shared`'s metrics); its
/// mapping version then recorded; how many nodes the snapshot covered. A fleet with no rows
/// starts empty. One whose rows cannot be read or mapped is quarantined (its reason kept in
/// `shared`).
pub fn restore_fleet(
    config: &MapperConfig,
    store: &Store,
    shared: &Shared,
    id: &str,
    unrecorded: Unrecorded,
) -> Result<(FleetMap, usize)> {
    let running = crate::mapping::mapping_version(config);
    let restored = (|| {
        if unrecorded == Unrecorded::Running && store.mapping_version(id)?.is_none() {
            store.set_mapping_version(&[id], &running)?;
        }
        let stored = store.load_fleet(id)?;
        let restored = if stored.nodes.is_empty() && stored.localized.is_empty() {
            (crate::mapping::new_fleet(config, id), 0)
        } else {
            let (map, covered, rebuilt) = load(config, store, id, &running)?;
            if rebuilt {
                Metrics::bump(&shared.metrics.fleets_rebuilt);
            }
            (map, covered)
        };
        if store.mapping_version(id)?.as_ref() != Some(&running) {
            store.set_mapping_version(&[id], &running)?;
        }
        Ok(restored)
    })();
    restored.inspect_err(|e: &anyhow::Error| {
        let reason = format!("{e:#}");
        tracing::error!(fleet = %id, "quarantined: its stored map does not replay: {reason}");
        shared
            .quarantined
            .write()
            .expect("quarantine lock")
            .insert(id.to_owned(), reason);
    })
}

/// Why a fleet must be rebuilt rather than restored, if it must: its recorded mapping
/// version is not the running one.
pub fn rebuild_reason(
    recorded: Option<&MappingVersion>,
    running: &MappingVersion,
) -> Option<String> {
    match recorded {
        Some(version) if version == running => None,
        Some(version) => Some(format!("mapped by {version}; running {running}")),
        None => Some(format!(
            "no mapping version recorded (a store of format 0); running {running}"
        )),
    }
}

/// One fleet's map: from its snapshot if it has a usable one, else replayed in full, else
/// rebuilt; how many nodes its stored snapshot covers; whether it was rebuilt.
fn load(
    config: &MapperConfig,
    store: &Store,
    id: &str,
    running: &MappingVersion,
) -> Result<(FleetMap, usize, bool)> {
    let started = Instant::now();
    let stored = store.load_fleet(id)?;
    let recorded = store.mapping_version(id)?;
    let reason = match rebuild_reason(recorded.as_ref(), running) {
        Some(reason) => reason,
        None => match restore_same_version(config, store, &stored)? {
            Ok((map, covered)) => {
                tracing::info!(
                    fleet = %id,
                    nodes = stored.nodes.len(),
                    snapshot_nodes = covered,
                    edges = stored.edges.len(),
                    "restored in {:.0} ms",
                    started.elapsed().as_secs_f64() * 1e3
                );
                return Ok((map, covered, false));
            }
            Err(differ) => format!(
                "{differ} under the same mapping version ({running}): the mapping code \
                     changed without a new fleetmap::MAPPING_CODE"
            ),
        },
    };
    let map = replay_unchecked(config, &stored)?;
    let snapshot = (config.store.snapshot_every_nodes > 0)
        .then(|| map.snapshot())
        .flatten();
    let edges = crate::store::encode_edges(&map.graph().edges);
    store
        .put_rebuilt(id, &edges, snapshot.as_deref(), running)
        .with_context(|| format!("store: fleet {id}: writing its rebuilt map"))?;
    tracing::warn!(
        fleet = %id,
        nodes = stored.nodes.len(),
        stored_edges = stored.edges.len(),
        edges = edges.len(),
        "rebuilt from its nodes in {:.0} ms: {reason}",
        started.elapsed().as_secs_f64() * 1e3
    );
    let covered = snapshot.map_or(0, |_| stored.nodes.len());
    Ok((map, covered, true))
}

/// A fleet mapped by the running version: from its snapshot and the nodes after it, or
/// replayed in full; the inner error says how its edges differ from the stored ones (the
/// caller rebuilds it), the outer one that its rows cannot be read or mapped.
fn restore_same_version(
    config: &MapperConfig,
    store: &Store,
    stored: &StoredFleet,
) -> Result<Result<(FleetMap, usize), String>> {
    let id = &stored.id;
    // Snapshots off: none is trusted either (a way to replay every node on purpose).
    let snapshot = store.snapshot(id).unwrap_or_else(|e| {
        tracing::warn!(fleet = %id, "snapshot unreadable, replaying every node: {e}");
        None
    });
    if let Some(bytes) = snapshot.filter(|_| config.store.snapshot_every_nodes > 0) {
        match from_snapshot(config, stored, &bytes) {
            Ok(restored) => return Ok(Ok(restored)),
            Err(e) => tracing::warn!(fleet = %id, "snapshot not used, replaying every node: {e:#}"),
        }
    }
    let map = replay_unchecked(config, stored)?;
    Ok(match edges_differ(&map, stored) {
        None => Ok((map, 0)),
        Some(differ) => Err(differ),
    })
}

/// A fleet's map from its snapshot and the nodes after it, its edges checked; how many
/// nodes the snapshot covered. A snapshot that does not fit, or that makes the restore
/// panic, is an error here (the caller replays in full), never a crash.
pub fn from_snapshot(
    config: &MapperConfig,
    stored: &StoredFleet,
    bytes: &[u8],
) -> Result<(FleetMap, usize)> {
    let restoring = std::panic::AssertUnwindSafe(|| -> Result<(FleetMap, usize)> {
        let mut spans = SpanReplay::new(stored.localized.clone());
        let (mut map, covered) = crate::mapping::new_fleet(config, &stored.id).restore(
            bytes,
            &stored.nodes,
            &mut spans,
        )?;
        replay_tail(&mut map, stored, covered, &mut spans)?;
        spans.rest(&mut map);
        check_edges(&map, stored)?;
        Ok((map, covered))
    });
    std::panic::catch_unwind(restoring)
        .unwrap_or_else(|_| Err(anyhow::anyhow!("restoring from the snapshot panicked")))
}

/// One fleet's map replayed from all of its nodes; its edges checked against the stored ones.
pub fn replay(config: &MapperConfig, stored: &StoredFleet) -> Result<FleetMap> {
    let map = replay_unchecked(config, stored)?;
    check_edges(&map, stored)?;
    Ok(map)
}

/// One fleet's map replayed from all of its nodes by the running mapping version, whatever
/// edges it stored.
pub fn replay_unchecked(config: &MapperConfig, stored: &StoredFleet) -> Result<FleetMap> {
    let mut map = crate::mapping::new_fleet(config, &stored.id);
    let mut spans = SpanReplay::new(stored.localized.clone());
    replay_tail(&mut map, stored, 0, &mut spans)?;
    spans.rest(&mut map);
    Ok(map)
}

/// Maps the stored nodes from arrival index `from` on into `map`, which holds the first
/// `from` of them and the solves applied among them; each stored solve is taken and applied
/// at the nodes where it was; the localized spans of their chains before them (`spans`, which
/// the caller ends with [`SpanReplay::rest`]).
fn replay_tail(
    map: &mut FleetMap,
    stored: &StoredFleet,
    from: usize,
    spans: &mut SpanReplay,
) -> Result<()> {
    let id = &stored.id;
    let applied = map.solves_applied() as usize;
    anyhow::ensure!(
        applied <= stored.solve_points.len(),
        "store: fleet {id}: {applied} solves applied of {} stored",
        stored.solve_points.len()
    );
    let mut legacy = stored
        .legacy_solves
        .iter()
        .filter(|&&a| a >= from as u64)
        .peekable();
    let mut points = stored.solve_points[applied..].iter().peekable();
    // The solve taken and not applied yet.
    let mut out = None;
    if from > 0 {
        // The solves taken after the snapshot's last node, at that node.
        solve_points_at(
            map,
            from as u64 - 1,
            &mut points,
            &mut out,
            &stored.pass_fixes,
        )?;
    }
    for (arrival, bytes) in stored.nodes.iter().enumerate().skip(from) {
        let arrival = arrival as u64;
        let node = wire::decode_node(bytes)
            .with_context(|| format!("store: node {arrival} of fleet {id} is unreadable"))?;
        spans.before(map, &node);
        map.ingest(&node)
            .with_context(|| format!("store: replaying node {arrival} of fleet {id}"))?;
        if legacy.next_if_eq(&&arrival).is_some() {
            map.optimize_now()?;
        }
        solve_points_at(map, arrival, &mut points, &mut out, &stored.pass_fixes)?;
    }
    anyhow::ensure!(
        points.peek().is_none(),
        "store: fleet {id}: solves stored beyond its nodes"
    );
    Ok(())
}

/// Takes and applies the stored solves due after the node of arrival index `arrival`.
fn solve_points_at<'a>(
    map: &mut FleetMap,
    arrival: u64,
    points: &mut std::iter::Peekable<impl Iterator<Item = &'a SolvePoint>>,
    out: &mut Option<slam::BackgroundSolve>,
    pass_fixes: &std::collections::BTreeMap<u64, Vec<slam::GpsEdge>>,
) -> Result<()> {
    while let Some(point) = points.peek() {
        if out.is_none() && point.taken_after == arrival {
            *out = map.take_solve_now();
            anyhow::ensure!(
                out.is_some(),
                "store: fleet {}: solve {} taken twice",
                map.id(),
                point.seq
            );
        }
        if out.is_none() || point.applied_after != arrival {
            break;
        }
        let solved = out.take().expect("taken above").run();
        map.finish_solve(solved)?;
        // A replay takes passes as spans, so none waits here: the stored fixes are the ones.
        map.take_pass_fixes();
        if let Some(fixes) = pass_fixes.get(&point.seq) {
            map.restore_pass_fixes(fixes);
        }
        map.count_solve(point);
        points.next();
    }
    Ok(())
}

/// The map's edges against the stored ones.
fn check_edges(map: &FleetMap, stored: &StoredFleet) -> Result<()> {
    match edges_differ(map, stored) {
        None => Ok(()),
        Some(differ) => Err(anyhow::anyhow!("store: fleet {}: {differ}", stored.id)),
    }
}

/// How the map's edges differ from the stored ones, if they do.
fn edges_differ(map: &FleetMap, stored: &StoredFleet) -> Option<String> {
    let rebuilt = crate::store::encode_edges(&map.graph().edges);
    (rebuilt != stored.edges).then(|| {
        format!(
            "replays to {} edges that differ from the {} stored",
            rebuilt.len(),
            stored.edges.len()
        )
    })
}

/// How two maps of a fleet differ: empty when they hold the same nodes, robots, edges, GPS
/// edges, solves and mapping counts, and the same poses bit for bit.
pub fn differences(a: &FleetMap, b: &FleetMap) -> Vec<String> {
    let mut found = Vec::new();
    let mut differ = |what: &str, same: bool| {
        if !same {
            found.push(what.to_owned());
        }
    };
    let (ga, gb) = (a.graph(), b.graph());
    differ("nodes", a.nodes().len() == b.nodes().len());
    differ("edges", ga.edges == gb.edges);
    differ("gps edges", ga.gps == gb.gps);
    differ("solves applied", a.solves_applied() == b.solves_applied());
    differ("datum", a.datum() == b.datum());
    let robots = |m: &FleetMap| -> Vec<(String, u64, Vec<usize>)> {
        let r = m.robots();
        r.iter()
            .map(|r| (r.id.clone(), r.last_node_seq, r.nodes.clone()))
            .collect()
    };
    differ("robots", robots(a) == robots(b));
    // Solves taken live but not applied (a part not anchored) leave no solve point, so a
    // replay does not count them: not compared.
    let counts = |m: &FleetMap| slam::MapperStats {
        deferred_optimizations: 0,
        ..m.stats()
    };
    differ("mapping counts", counts(a) == counts(b));
    let bits = |m: &FleetMap| -> Vec<[u64; 3]> {
        let p = m.poses();
        p.iter()
            .map(|p| [p.x.to_bits(), p.y.to_bits(), p.theta.to_bits()])
            .collect()
    };
    if bits(a) != bits(b) {
        found.push(format!(
            "poses (largest difference {:.3e})",
            largest_pose_difference(a, b)
        ));
    }
    found
}

/// The largest difference of a coordinate of two maps' poses (m or rad; ∞ when their
/// counts differ).
pub fn largest_pose_difference(a: &FleetMap, b: &FleetMap) -> f64 {
    if a.poses().len() != b.poses().len() {
        return f64::INFINITY;
    }
    a.poses()
        .iter()
        .zip(b.poses())
        .map(|(p, q)| {
            let dtheta = slam::se2::wrap_angle(p.theta - q.theta).abs();
            (p.x - q.x).abs().max((p.y - q.y).abs()).max(dtheta)
        })
        .fold(0.0, f64::max)
}

/// What `--verify-store` found of one fleet.
#[derive(Debug, Serialize)]
pub struct FleetCheck {
    /// The fleet.
    pub fleet: String,
    /// Stored nodes, edges and solves.
    pub nodes: usize,
    /// See `nodes`.
    pub edges: usize,
    /// See `nodes`.
    pub solves: usize,
    /// The mapping version recorded for its edges (`None`: a store of format 0).
    pub mapping_version: Option<String>,
    /// Why a start of this mapper would rebuild it from its nodes; `None`: restored.
    pub rebuild: Option<String>,
    /// The full replay's time (ms).
    pub replay_ms: f64,
    /// Why the full replay failed (a start quarantines the fleet); `None`: it replays.
    pub replay_error: Option<String>,
    /// How the replayed edges differ from the stored ones; `None`: they match.
    pub edges_differ: Option<String>,
    /// The snapshot, if the fleet has one.
    pub snapshot: Option<SnapshotCheck>,
}

/// What `--verify-store` found of a fleet's snapshot.
#[derive(Debug, Serialize)]
pub struct SnapshotCheck {
    /// Nodes it covers (0 when unusable).
    pub covers: usize,
    /// Size (bytes).
    pub bytes: usize,
    /// The restore's time, snapshot and the nodes after it (ms).
    pub restore_ms: f64,
    /// Why it could not be restored; `None`: it was.
    pub error: Option<String>,
    /// What differs between the restored map and the full replay.
    pub differences: Vec<String>,
}

/// The whole store's check: every fleet, and whether all of it matched.
#[derive(Debug, Serialize)]
pub struct StoreCheck {
    /// The store's format number.
    pub format: u64,
    /// The running mapping version.
    pub mapping_version: String,
    /// Every fleet of the store.
    pub fleets: Vec<FleetCheck>,
    /// Every fleet replays; those of the running mapping version to their stored edges, and
    /// their snapshots to the replay. A fleet of another version is rebuilt at start: that
    /// is not a failure.
    pub ok: bool,
}

/// Replays every fleet of the store in full (its snapshot ignored), checks its edges against
/// the stored ones and what its snapshot restores against the replay, and says which fleets
/// a start would rebuild.
pub fn verify_store(config: &MapperConfig, store: &Store) -> Result<StoreCheck> {
    let running = crate::mapping::mapping_version(config);
    let mut fleets = Vec::new();
    for id in store.fleet_ids()? {
        let stored = store.load_fleet(&id)?;
        let recorded = store.mapping_version(&id)?;
        let started = Instant::now();
        let replayed = replay_unchecked(config, &stored);
        let replay_ms = started.elapsed().as_secs_f64() * 1e3;
        let edges_differ = replayed
            .as_ref()
            .ok()
            .and_then(|m| edges_differ(m, &stored));
        let rebuild = rebuild_reason(recorded.as_ref(), &running).or_else(|| {
            edges_differ
                .as_ref()
                .map(|d| format!("{d} under the same mapping version"))
        });
        let snapshot = store.snapshot(&id)?.map(|bytes| {
            let started = Instant::now();
            let restored = from_snapshot(config, &stored, &bytes);
            let restore_ms = started.elapsed().as_secs_f64() * 1e3;
            let (covers, error, differences) = match (&restored, &replayed) {
                (Ok((map, covers)), Ok(full)) => (*covers, None, differences(map, full)),
                (Ok((_, covers)), Err(_)) => {
                    (*covers, None, vec!["no full replay to compare".into()])
                }
                (Err(e), _) => (0, Some(format!("{e:#}")), Vec::new()),
            };
            SnapshotCheck {
                covers,
                bytes: bytes.len(),
                restore_ms,
                error,
                differences,
            }
        });
        fleets.push(FleetCheck {
            nodes: stored.nodes.len(),
            edges: stored.edges.len(),
            solves: stored.solve_points.len() + stored.legacy_solves.len(),
            fleet: id,
            mapping_version: recorded.map(|v| v.to_string()),
            rebuild,
            replay_ms,
            replay_error: replayed.err().map(|e| format!("{e:#}")),
            edges_differ,
            snapshot,
        });
    }
    let ok = fleets.iter().all(|f| {
        let same_version = f.mapping_version.as_deref() == Some(running.to_string().as_str());
        f.replay_error.is_none()
            && (!same_version
                || f.edges_differ.is_none()
                    && f.snapshot
                        .as_ref()
                        .is_none_or(|s| s.error.is_none() && s.differences.is_empty()))
    });
    Ok(StoreCheck {
        format: store.format()?,
        mapping_version: running.to_string(),
        fleets,
        ok,
    })
}

#[cfg(test)]
mod tests;

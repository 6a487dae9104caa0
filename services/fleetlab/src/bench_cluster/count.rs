//! After a `bench-cluster` run: each robot's nodes as its site's map holds them, read
//! through the gateway as users read them.

use crate::bench_fleet::agent;
use anyhow::{Context, Result};
use std::collections::HashMap;

/// The robots' nodes as the sites' maps hold them afterwards.
pub(super) struct Counted {
    pub taken: u64,
    pub acked_lost: u64,
    pub duplicated: u64,
    pub not_taken: u64,
}

/// Counts through `http`: each robot's chain (1) in its site's robot list, whose range
/// (first to `acked_node_seq`) holds every node the mapper took, mapped or passed over
/// covered ground (it takes a chain's nodes only in sequence); and each site's graph, where
/// a node mapped twice would show.
pub(super) fn count_nodes(
    http: &str,
    sites: &[String],
    robots: &[(String, usize)],
    acked: &[Option<u64>],
    last_seq: &dyn Fn(usize) -> Option<u64>,
) -> Result<Counted> {
    let get = |path: String| -> Result<serde_json::Value> {
        let body = agent()
            .get(format!("http://{http}{path}"))
            .call()
            .with_context(|| format!("GET {path}"))?
            .body_mut()
            .read_to_vec()
            .with_context(|| format!("GET {path}"))?;
        serde_json::from_slice(&body).with_context(|| format!("GET {path}: not JSON"))
    };
    let mut chains: HashMap<String, (u64, u64)> = HashMap::new();
    let mut counted = Counted {
        taken: 0,
        acked_lost: 0,
        duplicated: 0,
        not_taken: 0,
    };
    for site in sites {
        let list = get(format!("/api/v1/fleets/{site}/robots"))?;
        for robot in list["robots"].as_array().context("robots")? {
            let id = robot["id"].as_str().unwrap_or_default();
            for chain in robot["chains"].as_array().into_iter().flatten() {
                if chain["chain_id"] == 1 {
                    let range = (
                        chain["first_node_seq"].as_u64().unwrap_or_default(),
                        chain["acked_node_seq"].as_u64().unwrap_or_default(),
                    );
                    chains.insert(id.to_owned(), range);
                }
            }
        }
        let graph = get(format!("/api/v1/fleets/{site}/graph"))?;
        let mut times: HashMap<(String, u64), u64> = HashMap::new();
        for node in graph["nodes"].as_array().context("graph nodes")? {
            let key = (
                node["robot"].as_str().unwrap_or_default().to_owned(),
                node["node_seq"].as_u64().unwrap_or_default(),
            );
            *times.entry(key).or_default() += 1;
        }
        counted.duplicated += times.values().map(|n| n - 1).sum::<u64>();
    }
    for (r, (name, _)) in robots.iter().enumerate() {
        let count = |last: Option<u64>| last.map_or(0, |s| s + 1);
        // Nodes from the chain's first on, up to its last, are in; none is taken before 0.
        let (first, taken_to) = match chains.get(name) {
            Some(&(first, last)) => (first, Some(last)),
            None => (0, None),
        };
        let taken = count(taken_to).saturating_sub(first);
        counted.taken += taken;
        counted.acked_lost += count(acked[r]).saturating_sub(taken);
        counted.not_taken += count(last_seq(r)).saturating_sub(taken);
    }
    Ok(counted)
}

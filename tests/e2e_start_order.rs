//! Robots that boot before the mapper (out of radio range, or the server restarting) record
//! from the start: their nodes wait in the outbox and are all mapped once the mapper is up.

mod common;

use common::*;
use std::time::Duration;

const ROUNDS: usize = 5;
const ROBOTS: usize = 3;

#[test]
fn robots_started_before_the_mapper_lose_nothing() {
    for round in 0..ROUNDS {
        let dir = temp_dir(&format!("start-order-{round}"));
        let zenoh = format!("tcp/127.0.0.1:{}", free_port());
        // Each robot starts 0.2-3 s before the mapper (the leads differ by round and robot).
        let leads_ms: Vec<u64> = (0..ROBOTS)
            .map(|r| 200 + ((round * 7 + r * 11) as u64 * 397) % 2800)
            .collect();
        let first = *leads_ms.iter().max().unwrap();
        let mut edges = Vec::new();
        let mut order: Vec<usize> = (0..ROBOTS).collect();
        order.sort_by_key(|&r| std::cmp::Reverse(leads_ms[r]));
        let mut waited = 0;
        for &r in &order {
            std::thread::sleep(Duration::from_millis(first - leads_ms[r] - waited));
            waited = first - leads_ms[r];
            // 20 s of park at 4x: each robot drives for 5 s.
            edges.push((r, spawn_edge(&dir, r, &zenoh, 20.0, 4.0)));
        }
        std::thread::sleep(Duration::from_millis(first - waited));
        let mapper = MapperProcess::start_on(&dir, zenoh);
        for (r, edge) in edges {
            let report = edge_report(edge, Duration::from_secs(120));
            let made = report["nodes"].as_u64().expect("nodes made");
            assert!(made >= 5, "round {round}, robot{r}: {report}");
            assert_eq!(report["outbox_pending"], 0, "{report}");
            let seqs = node_seqs(&mapper.http, "park", &format!("robot{r}"));
            assert_eq!(
                seqs,
                (0..made).collect::<Vec<_>>(),
                "round {round}, robot{r} ({} ms early): {report}",
                leads_ms[r]
            );
        }
        drop(mapper);
        std::fs::remove_dir_all(&dir).ok();
    }
}

//! A flood: one sender puts nodes far faster than the mapper maps them. The ingest queue is
//! bounded: what does not fit is shed and counted (`queue_full`), never queued without end,
//! and what the mapper took is still one contiguous run of the chain (a shed node is a gap to
//! the mapper, which asks for it again; this sender does not re-send, so the run stops there).

mod common;

use common::*;
use std::time::Duration;
use wire::Message;
use zenoh::qos::CongestionControl;

/// More than the ingest queue holds (1,024).
const FLOOD: u64 = 6_000;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_flood_is_shed_at_the_bounded_queue_and_the_chain_stays_contiguous() {
    let dir = temp_dir("flood");
    let (mapper, session, http) = in_process_mapper(&dir, "").await;
    let key = wire::node_key("park", "robot0").unwrap();
    let mut template = real_nodes(1).remove(0);
    template.cloud = None;
    template.chain_id = 77;
    let publisher = session
        .declare_publisher(key)
        .congestion_control(CongestionControl::Block)
        .await
        .expect("publisher");
    // Node 0 until the mapper's subscription has reached us (as the edge re-sends).
    let seqs = || {
        let h = http.clone();
        async move {
            tokio::task::spawn_blocking(move || node_seqs(&h, "park", "robot0"))
                .await
                .unwrap()
        }
    };
    while seqs().await.is_empty() {
        publisher.put(template.encode_to_vec()).await.expect("put");
        tokio::time::sleep(Duration::from_millis(300)).await;
    }
    let stamp = template.header.as_ref().unwrap().stamp_ns;
    for seq in 1..FLOOD {
        let mut node = template.clone();
        node.node_seq = seq;
        for h in node.headers_mut() {
            h.stamp_ns = stamp + seq * 10_000_000;
        }
        publisher.put(node.encode_to_vec()).await.expect("put");
    }
    let metrics = {
        let h = http.clone();
        tokio::task::spawn_blocking(move || {
            // Until the worker has drained what it took: each node of the flood (1.. after
            // node 0) accounted for, mapped or refused (shed at the queue, out of order after
            // a shed node), and every node counted as accepted in the map. No quiet period is
            // trusted: a loaded machine can stall the worker for seconds mid-batch. (Node 0's
            // repeats count as duplicates, not here.)
            wait_for(Duration::from_secs(120), || {
                let text = http_get(&h, "/metrics")?.1;
                let accepted = metric(&text, "levelmap_nodes_accepted_total");
                let counted = accepted.saturating_sub(1) + node_rejections(&text);
                let drained = node_seqs(&h, "park", "robot0").len() as u64 == accepted;
                if counted == FLOOD - 1 && drained {
                    return Some(text);
                }
                std::thread::sleep(Duration::from_millis(200));
                None
            })
        })
        .await
        .unwrap()
        .expect("every put accounted for")
    };
    let shed = metric(
        &metrics,
        "levelmap_rejected_total{topic=\"node\",reason=\"queue_full\"}",
    );
    let accepted = metric(&metrics, "levelmap_nodes_accepted_total");
    eprintln!("{FLOOD} nodes put: {accepted} mapped, {shed} shed at the full queue");
    assert!(shed > 0, "the queue never filled: {metrics}");
    let mapped = seqs().await;
    assert_eq!(
        mapped,
        (0..mapped.len() as u64).collect::<Vec<_>>(),
        "one contiguous run"
    );
    assert_eq!(mapped.len() as u64, accepted);
    mapper.stop().await.expect("stops");
    std::fs::remove_dir_all(&dir).ok();
}

/// Every node refused, whatever the reason (`levelmap_rejected_total{topic="node",…}`).
fn node_rejections(metrics: &str) -> u64 {
    metrics
        .lines()
        .filter(|l| l.starts_with("levelmap_rejected_total{topic=\"node\""))
        .filter_map(|l| l.rsplit(' ').next()?.parse::<u64>().ok())
        .sum()
}

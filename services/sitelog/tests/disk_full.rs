//! A NATS server's disk full while a writer appends to a site's log: the stream leader's
//! store on a small tmpfs, filled by a file. Its JetStream stops (nats-server disables it on
//! a write error); the log goes on on the other two with every acked record read back once,
//! in order. Freed and restarted, the server catches up and is a replica again: the log
//! survives the loss of another server after. Needs root for `mount` (CI runs as root);
//! fails otherwise.

mod common;

use async_nats::jetstream;
use bytes::Bytes;
use common::tmpfs::{Tmpfs, fill};
use common::{Cluster, TempDir, open_when_ready, stream_replicas, when_ready};
use sitelog::{RecordId, SiteLog};
use std::io::Write;
use std::time::{Duration, Instant};

/// Appends records `range` to `log`, each acked at the next sequence; their ids.
async fn append(
    log: &mut SiteLog,
    range: std::ops::Range<u64>,
    mut before: impl FnMut(u64),
) -> Vec<String> {
    let mut acked = Vec::new();
    for seq in range {
        before(seq);
        let id = RecordId::node("r1", 0, seq);
        let started = Instant::now();
        let appended = log
            .append(&id, payload(seq))
            .await
            .unwrap_or_else(|e| panic!("append {seq}: {e}"));
        if started.elapsed() > Duration::from_millis(500) {
            eprintln!(
                "append {seq} acked after {:.1} s",
                started.elapsed().as_secs_f64()
            );
        }
        assert_eq!(appended.sequence(), seq + 1, "{id}");
        acked.push(id.to_string());
    }
    acked
}

/// GET `path` from `address` (HTTP/1.0, the whole answer).
fn http_get(address: &str, path: &str) -> String {
    use std::io::Read;
    let mut stream = std::net::TcpStream::connect(address).expect("the monitoring port");
    write!(stream, "GET {path} HTTP/1.0\r\nHost: {address}\r\n\r\n").expect("request");
    let mut answer = String::new();
    stream.read_to_string(&mut answer).expect("answer");
    answer
}

fn payload(seq: u64) -> Bytes {
    Bytes::from(vec![(seq % 251) as u8; 4096])
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_server_whose_disk_fills_loses_no_acked_record_and_catches_up_once_freed() {
    let dir = TempDir::new("sitelog-disk-full");
    let disks: Vec<Tmpfs> = ["n1", "n2", "n3"]
        .iter()
        .map(|n| Tmpfs::mount(&dir.path().join(n), "64m"))
        .collect();
    let mut cluster = Cluster::start_in(dir, None);
    let js = jetstream::new(cluster.client().await);
    let mut log = open_when_ready(js.clone(), "park").await;
    let (leader, _) = stream_replicas(&js, "park").await;
    let filler = disks
        .iter()
        .find(|d| d.0.ends_with(&leader))
        .expect("the leader's disk")
        .0
        .join("filler");

    // The leader's disk filled a third of the way: the log goes on on the other two.
    let mut acked = append(&mut log, 0..400, |seq| {
        if seq == 130 {
            let bytes = fill(&filler);
            eprintln!("{leader}, the stream's leader: its disk filled ({bytes} bytes) after {seq} acked appends");
        }
    })
    .await;
    let (new_leader, peers) = stream_replicas(&js, "park").await;
    eprintln!("after: leader {new_leader}, replicas {peers:?}");
    assert_ne!(new_leader, leader, "the full server no longer leads");
    assert!(
        peers.contains(&(leader.clone(), false)),
        "the full server is behind: {peers:?}"
    );
    // Its monitoring port says so, where an operator's health check looks.
    let index = cluster
        .names()
        .iter()
        .position(|n| *n == leader)
        .expect("named");
    let health = http_get(&cluster.monitors()[index], "/healthz?js-enabled-only=true");
    eprintln!("{leader}'s /healthz?js-enabled-only=true: {health}");
    assert!(!health.contains("200 OK"), "{health}");

    // Freed and restarted: it catches up with every record.
    std::fs::remove_file(&filler).expect("filler removed");
    let freed = Instant::now();
    cluster.restart(&leader).expect("restart the server");
    let caught_up = loop {
        let (_, peers) = stream_replicas(&js, "park").await;
        if peers.contains(&(leader.clone(), true)) {
            break freed.elapsed();
        }
        assert!(
            freed.elapsed() < Duration::from_secs(60),
            "{leader} not current 60 s after its restart: {peers:?}"
        );
        tokio::time::sleep(Duration::from_millis(250)).await;
    };
    eprintln!(
        "{leader} freed, restarted and current after {:.1} s",
        caught_up.as_secs_f64()
    );

    // A replica again: the log survives another server's loss, appends and reads included.
    let (other, _) = stream_replicas(&js, "park").await;
    eprintln!("SIGKILL {other}, the stream's leader now");
    cluster.kill(&other);
    acked.extend(append(&mut log, 400..500, |_| {}).await);
    let js = jetstream::new(cluster.client().await);
    let reader = when_ready(|| SiteLog::open(js.clone(), "park", 3, Default::default())).await;
    let entries = reader.read_from(1).await.expect("read the log");
    let ids: Vec<String> = entries.iter().map(|e| e.id.clone()).collect();
    assert_eq!(ids, acked, "every acked record once, in order");
    for (k, entry) in entries.iter().enumerate() {
        assert_eq!(entry.payload, payload(k as u64), "record {}", k + 1);
    }
    drop(cluster);
}

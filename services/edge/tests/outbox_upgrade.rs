//! Upgrades: an outbox written by the previous release (`tests/fixtures/outbox-format-0/`,
//! written by `scripts/make-outbox-fixture.sh`) is taken by today's edge, marked with its
//! format, and every node in it is sent as it was written: a robot that is updated while
//! nodes wait for the mapper loses none.

use edge::{OUTBOX_FORMAT, Outbox};
use std::path::Path;

const FIXTURE: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/tests/fixtures/outbox-format-0"
);

#[test]
fn an_outbox_of_the_previous_release_is_taken_and_its_nodes_sent_as_written() {
    let expected: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(Path::new(FIXTURE).join("expected.json")).unwrap(),
    )
    .unwrap();
    let dir = std::env::temp_dir().join(format!("edge-outbox-upgrade-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("outbox.redb");
    let unzipped = std::process::Command::new("gzip")
        .args(["-dc"])
        .arg(Path::new(FIXTURE).join("outbox.redb.gz"))
        .output()
        .expect("gzip runs");
    assert!(unzipped.status.success(), "gunzip the fixture");
    std::fs::write(&path, unzipped.stdout).unwrap();

    let outbox = Outbox::open(&path).expect("the previous release's outbox opens");
    assert_eq!(
        outbox.format().unwrap(),
        OUTBOX_FORMAT,
        "marked with today's format"
    );
    let pending = outbox.pending(0, 1000).unwrap();
    assert_eq!(
        pending.len() as u64,
        expected["outbox_pending"].as_u64().unwrap()
    );
    assert_eq!(outbox.next_node_seq().unwrap(), pending.len() as u64);
    let chain = outbox.chain_id().unwrap();
    for (i, (seq, bytes)) in pending.iter().enumerate() {
        assert_eq!(*seq, i as u64, "in order, from the first");
        // As the mapper decodes what it takes.
        let node = wire::decode_node(bytes).unwrap_or_else(|e| panic!("node {seq}: {e}"));
        assert_eq!(node.node_seq, *seq);
        assert_eq!(node.robot, expected["robot"].as_str().unwrap());
        assert_eq!(node.fleet, expected["fleet"].as_str().unwrap());
        assert_eq!(node.chain_id, chain, "node {seq}: the outbox's chain");
    }
    // Opened again, as after a restart: the same.
    drop(outbox);
    let again = Outbox::open(&path).unwrap();
    assert_eq!(again.pending(0, 1000).unwrap(), pending);
    assert_eq!(again.chain_id().unwrap(), chain);
    std::fs::remove_dir_all(&dir).unwrap();
}

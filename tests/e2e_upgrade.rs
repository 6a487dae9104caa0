//! Upgrades: a store written by the previous release (the fixture under
//! `services/mapper/tests/fixtures/`, written by `scripts/make-store-fixture.sh` with main
//! at 67c63cc: store format 0, no mapping version) opens in this mapper with every record
//! (every robot's nodes in map order, their chains, the localized and passed spans, the
//! modes, the map version), its map rebuilt from its nodes, and no fleet quarantined. The
//! next start restores the rebuilt map from its snapshot; a start with a changed
//! `[mapping.idc]` key rebuilds it again, and `--verify-store` says so before.

mod common;

use common::*;
use redb::{ReadableDatabase, ReadableTable, TableDefinition};
use serde_json::Value;
use std::path::{Path, PathBuf};

const FIXTURE: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../mapper/tests/fixtures/store-format-0"
);
/// The store's row of a span: (fleet, robot, chain, first node_seq) → its last node_seq and
/// passes (`mapper::store`'s `localized_spans`).
type SpanKey = (&'static str, &'static str, u64, u64);
type SpanRow = (u64, u64, f64, f64, f64, f64);
const SPANS: TableDefinition<SpanKey, SpanRow> = TableDefinition::new("localized_spans");

/// The fixture's mapper config, as it was written (the shipped defaults), with `extra`.
fn config(dir: &Path, zenoh: &str, extra: &str) -> String {
    format!(
        "store_path = {:?}\nfleets = [\"park\"]\ntoken = \"fixture\"\n{extra}\n\
         [zenoh]\nmode = \"router\"\nlisten = [{zenoh:?}]\n",
        dir.join("mapper.redb")
    )
}

/// The store's localized and passed spans, every column.
fn spans(store: &Path) -> Vec<String> {
    let db = redb::Database::open(store).expect("the store opens");
    let txn = db.begin_read().unwrap();
    let table = txn.open_table(SPANS).unwrap();
    table
        .iter()
        .unwrap()
        .map(|row| {
            let (k, v) = row.unwrap();
            format!("{:?} {:?}", k.value(), v.value())
        })
        .collect()
}

/// What the mapper serves of the fleet's record, as the fixture's expected.json has it.
fn record(http: &str) -> Value {
    let get = |path: &str| {
        get_json(http, &format!("/api/v1/fleets/park/{path}"))
            .unwrap_or_else(|| panic!("GET {path}"))
    };
    let graph = get("graph");
    let nodes: Vec<Value> = graph["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| serde_json::json!({"robot": n["robot"], "node_seq": n["node_seq"]}))
        .collect();
    let robots: Vec<Value> = get("robots")["robots"]
        .as_array()
        .unwrap()
        .iter()
        .map(robot_record)
        .collect();
    serde_json::json!({
        "nodes": nodes,
        "robots": robots,
        "modes": get("modes")["modes"],
        "versions": get("versions"),
    })
}

/// A robot's record: its id, nodes, last node and chains (not its live pose or times), with
/// the fields the fixture's release served (later ones add to them).
fn robot_record(r: &Value) -> Value {
    let chains: Vec<Value> = r["chains"]
        .as_array()
        .expect("chains")
        .iter()
        .map(|c| {
            serde_json::json!({
                "chain_id": c["chain_id"], "first_node_seq": c["first_node_seq"],
                "last_node_seq": c["last_node_seq"],
            })
        })
        .collect();
    serde_json::json!({
        "id": r["id"], "nodes": r["nodes"], "last_node_seq": r["last_node_seq"],
        "chains": chains,
    })
}

/// The fixture's store, unzipped into a scratch folder (a start writes to it), and what its
/// mapper served.
fn fixture_copy(name: &str) -> (PathBuf, Value) {
    let dir = temp_dir(name);
    let fixture = Path::new(FIXTURE);
    let zipped = fixture.join("mapper.redb.gz");
    let out = std::process::Command::new("gzip")
        .arg("-dc")
        .arg(&zipped)
        .output()
        .expect("gzip runs");
    assert!(
        out.status.success(),
        "{}: gzip -dc failed",
        zipped.display()
    );
    std::fs::write(dir.join("mapper.redb"), &out.stdout).unwrap();
    let expected = std::fs::read(fixture.join("expected.json")).expect("expected.json");
    (
        dir,
        serde_json::from_slice(&expected).expect("expected.json parses"),
    )
}

/// Fleets rebuilt at the mapper's start.
fn rebuilt(http: &str) -> u64 {
    let (_, text) = http_get(http, "/metrics").expect("/metrics");
    metric(&text, "levelmap_fleets_rebuilt_total")
}

#[test]
fn a_store_of_the_previous_release_opens_with_every_record_and_its_map_rebuilt() {
    let (dir, expected) = fixture_copy("upgrade");
    let store = dir.join("mapper.redb");
    let spans_before = spans(&store);
    assert!(
        spans_before.len() >= 2,
        "the fixture has localized and passed spans: {spans_before:?}"
    );
    let zenoh = format!("tcp/127.0.0.1:{}", free_port());

    let mapper = MapperProcess::start_config(&dir, zenoh.clone(), &config(&dir, &zenoh, ""));
    let fleets = get_json(&mapper.http, "/api/v1/fleets").expect("fleets");
    assert_eq!(fleets["quarantined"], serde_json::json!([]), "{fleets}");
    assert_eq!(fleets["fleets"], serde_json::json!(["park"]), "{fleets}");
    assert_eq!(
        rebuilt(&mapper.http),
        1,
        "the fleet is rebuilt from its nodes"
    );
    let served = record(&mapper.http);
    let wanted = serde_json::json!({
        "nodes": expected["nodes"],
        "robots": expected["robots"]["robots"].as_array().unwrap().iter().map(robot_record).collect::<Vec<_>>(),
        "modes": expected["modes"]["modes"],
        "versions": expected["versions"],
    });
    for key in ["nodes", "robots", "modes", "versions"] {
        assert_eq!(served[key], wanted[key], "{key}");
    }
    let summary = get_json(&mapper.http, "/api/v1/fleets/park/summary").expect("summary");
    assert_eq!(summary["nodes"], expected["summary"]["nodes"], "{summary}");
    // A version's file and a node's cloud, as stored.
    let (status, _) = http_get(&mapper.http, "/api/v1/fleets/park/versions/1/file").unwrap();
    assert_eq!(status, 200);
    let nodes = served["nodes"].as_array().unwrap();
    let robot1 = nodes.iter().position(|n| n["robot"] == "robot1").unwrap();
    let robot2 = nodes.iter().position(|n| n["robot"] == "robot2").unwrap();
    let cloud = |node: usize| {
        let path = format!("/api/v1/fleets/park/nodes/{node}/cloud");
        http_get(&mapper.http, &path).unwrap().0
    };
    assert_eq!(cloud(robot1), 200, "robot1's nodes came with their clouds");
    assert_eq!(cloud(robot2), 404, "robot2's without");
    mapper.stop();
    assert_eq!(spans(&store), spans_before, "the spans are the record");

    // The next start restores what the first rebuilt.
    let mapper = MapperProcess::start_config(&dir, zenoh.clone(), &config(&dir, &zenoh, ""));
    assert_eq!(rebuilt(&mapper.http), 0, "restored, not rebuilt again");
    assert_eq!(record(&mapper.http)["nodes"], served["nodes"]);
    mapper.stop();

    // One `[mapping.idc]` key changed: --verify-store says it will rebuild; the start does.
    let changed = config(&dir, &zenoh, "[mapping.idc]\nfinal_max_distance_m = 0.45\n");
    std::fs::write(dir.join("mapper.toml"), &changed).unwrap();
    let (code, check) = verify_store(&dir.join("mapper.toml"));
    assert_eq!(code, Some(0), "{check}");
    assert!(check["fleets"][0]["rebuild"].is_string(), "{check}");
    let mapper = MapperProcess::start_config(&dir, zenoh.clone(), &changed);
    let fleets = get_json(&mapper.http, "/api/v1/fleets").expect("fleets");
    assert_eq!(fleets["quarantined"], serde_json::json!([]), "{fleets}");
    assert_eq!(rebuilt(&mapper.http), 1);
    let again = record(&mapper.http);
    for key in ["nodes", "robots", "modes", "versions"] {
        assert_eq!(again[key], served[key], "{key}");
    }
    mapper.stop();
    let (code, check) = verify_store(&dir.join("mapper.toml"));
    assert_eq!(code, Some(0), "{check}");
    assert!(check["fleets"][0]["rebuild"].is_null(), "{check}");
    std::fs::remove_dir_all(&dir).ok();
}

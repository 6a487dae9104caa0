//! Backup and restore while the fleet drives: two robots publish, a backup of the running
//! mapper is taken (`levelmap backup`, the write token), the robots go on, the mapper is
//! killed (SIGKILL) and its store deleted, and a new mapper starts from the backup
//! (`levelmap mapper --restore`). Every node of the backup is there at once, and the robots'
//! outboxes bring back every node acked after it (they keep their newest acked nodes, and
//! the mapper asks for them from the gap): at the end each robot's nodes are 0..made, once.

mod common;

use common::*;
use std::time::Duration;

const ROBOTS: usize = 2;
const TOKEN: &str = "backup-drill-write-token";

fn mapped(http: &str) -> u64 {
    get_json(http, "/api/v1/fleets/park/summary").map_or(0, |s| s["nodes"].as_u64().unwrap_or(0))
}

#[test]
fn a_backup_of_a_running_mapper_restored_after_its_store_is_lost_loses_nothing() {
    let dir = temp_dir("backup");
    let zenoh = format!("tcp/127.0.0.1:{}", free_port());
    let mapper = MapperProcess::start_with(&dir, zenoh, &format!("token = {TOKEN:?}"));
    // 160 s of driving at 4× speed: about 40 nodes a robot over 40 s.
    let edges: Vec<_> = (0..ROBOTS)
        .map(|r| spawn_edge(&dir, r, &mapper.zenoh, 160.0, 4.0))
        .collect();
    let http = mapper.http.clone();
    wait_for(Duration::from_secs(60), || {
        (mapped(&http) >= 10).then_some(())
    })
    .expect("the robots' nodes reach the map");

    // Without the write token: refused, nothing written.
    let out = dir.join("backup.redb");
    let refused = backup(&http, &out, None);
    assert!(!refused.status.success());
    let why = String::from_utf8_lossy(&refused.stderr);
    assert!(why.contains("401"), "{why}");
    assert!(!out.exists());

    let (report, in_backup) = backed_up(&backup(&http, &out, Some(TOKEN)));
    assert!(in_backup >= 10, "{report}");
    // A backup does not overwrite a file.
    let again = backup(&http, &out, Some(TOKEN));
    assert!(!again.status.success());

    // The robots go on; the mapper acks nodes the backup does not hold, then dies with its
    // store.
    let acked_at_kill = wait_for(Duration::from_secs(60), || {
        let n = mapped(&http);
        (n >= in_backup + 10).then_some(n)
    })
    .expect("nodes acked after the backup");
    let stopped = mapper.kill();
    let store = dir.join("mapper.redb");
    std::fs::remove_file(&store).expect("the store deleted");

    let mapper = MapperProcess::restore(stopped, &out);
    let restored = mapped(&mapper.http);
    assert!(
        restored >= in_backup,
        "the backup's {in_backup} nodes are there at once: {restored}"
    );
    let mut made_total = 0;
    for (r, edge) in edges.into_iter().enumerate() {
        let report = edge_report(edge, Duration::from_secs(180));
        let made = report["nodes"].as_u64().expect("nodes");
        made_total += made;
        assert_eq!(report["outbox_pending"], 0, "robot{r}: {report}");
        let seqs = node_seqs(&mapper.http, "park", &format!("robot{r}"));
        assert_eq!(
            seqs,
            (0..made).collect::<Vec<_>>(),
            "robot{r}: every node made, once, in order"
        );
    }
    let in_map = mapped(&mapper.http);
    eprintln!(
        "backup drill: {in_backup} nodes in the backup, {acked_at_kill} acked when the mapper \
         was killed ({} of them after the backup), {restored} in the map at the restore, \
         {made_total} made, {in_map} in the map at the end, lost {}",
        acked_at_kill - in_backup,
        made_total - in_map
    );
    assert_eq!(in_map, made_total);
    drop(mapper);
    std::fs::remove_dir_all(&dir).ok();
}

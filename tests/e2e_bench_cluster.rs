//! `levelmap bench-cluster`, small and short, with a host killed halfway: three
//! nats-servers, three mapper hosts, a gateway and twelve robots over three sites, all real
//! processes and sessions. Every acked node must be in its site's map afterwards, none
//! twice, every published node taken, and every site the dead host owned served again
//! through the gateway and acking.

mod common;
#[path = "../services/sitelog/tests/common/servers.rs"]
mod nats;

use common::*;

#[test]
fn a_host_killed_under_load_loses_and_duplicates_no_node() {
    let dir = temp_dir("bench-cluster");
    let report = json_report(
        levelmap()
            .args([
                "bench-cluster",
                "--robots",
                "12",
                "--sites",
                "3",
                "--hosts",
                "3",
            ])
            .args(["--duration", "40", "--query-rate", "100", "--sessions", "6"])
            .args(["--kill-host", "--json", "--dir"])
            .arg(dir.join("run"))
            .arg("--nats-server")
            .arg(nats::nats_server()),
    );
    let count = |key: &str| report[key].as_u64().unwrap_or_else(|| panic!("{key}"));
    assert!(count("nodes_published") >= 12 * 40, "{report:#}");
    assert_eq!(count("acked_nodes_lost"), 0, "{report:#}");
    assert_eq!(count("nodes_duplicated"), 0, "{report:#}");
    assert_eq!(count("nodes_not_taken"), 0, "{report:#}");
    assert_eq!(count("nodes_taken"), count("nodes_published"), "{report:#}");
    let kill = &report["kill"];
    let moved = kill["sites"].as_array().expect("the killed host's sites");
    assert!(
        !moved.is_empty(),
        "the killed host owned no site: {report:#}"
    );
    for site in moved {
        for figure in ["first_ack_ms", "first_http_200_ms"] {
            let ms = site[figure].as_f64();
            assert!(
                ms.is_some_and(|ms| ms < 30_000.0),
                "{}: {figure} {ms:?}",
                site["site"]
            );
        }
    }
    // Each site served by one living host at the end.
    let mut served: Vec<&str> = report["owners_at_end"]
        .as_object()
        .expect("owners")
        .values()
        .flat_map(|sites| sites.as_array().expect("sites"))
        .map(|site| site.as_str().expect("site"))
        .collect();
    served.sort();
    assert_eq!(served, ["site0", "site1", "site2"], "{report:#}");
    let _ = std::fs::remove_dir_all(dir);
}

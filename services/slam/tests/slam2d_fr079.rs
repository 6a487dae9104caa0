//! The whole 2D pipeline on the Freiburg building 079 log, scored with its 1,685 relations.
//! Places revisited after ten minutes sit 6–8 m off in the dead-reckoned estimate, beyond
//! IDC's basin: without the correlative submap search they were never closed (relation
//! error 1.14 ± 2.31 m, max 7.9 m). Cartographer reports 0.0452 m.

mod common;

use common::MappedLog;

#[test]
fn fr079_revisits_are_closed_by_the_submap_search() {
    let run = MappedLog::map("fr079");
    let m = run.score(&run.relations);
    let stats = run.mapper.stats();
    println!(
        "FR079: {} nodes, {} loop closures ({} by submap search); relation error {:.4} ± {:.4} m (max {:.3})",
        stats.nodes,
        stats.loop_closures,
        stats.submap_closures,
        m.translation_mean_m,
        m.translation_std_m,
        m.translation_max_m,
    );
    assert_eq!(m.count, 1685);
    assert!(stats.submap_closures > 0, "{stats:?}");
    assert!(
        m.translation_mean_m <= 0.06,
        "mean {}",
        m.translation_mean_m
    );
    assert!(m.translation_max_m <= 1.0, "max {}", m.translation_max_m);
}

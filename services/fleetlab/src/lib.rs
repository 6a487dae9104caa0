//! The fleet lab: simulated robots of the hilly park against a real mapper, over Zenoh TCP on
//! loopback. [`demo`] runs edge services and scores the map against the simulator's ground
//! truth, beside [`fixed2d`], the same run mapped from a fixed horizontal 2D scanner (the
//! paper's baseline). [`bench_fleet`] loads one mapper with many robots and measures it from
//! outside, through HTTP; [`bench_cluster`] does so for the cluster mode; [`bench_growth`] grows
//! one site to many nodes in compressed time and measures what grows with it. The `levelmap` command line calls these (its `lab` feature); a
//! robot's build has none of it.

pub mod bench_cluster;
pub mod bench_fleet;
pub mod bench_growth;
pub mod bench_incremental;
pub mod demo;
pub mod fixed2d;
pub mod lab_dir;
pub mod localize_demo;
pub mod map_score;

pub use bench_cluster::BenchClusterArgs;
pub use bench_fleet::BenchFleetArgs;
pub use bench_growth::BenchGrowthArgs;
pub use bench_incremental::BenchIncrementalArgs;
pub use demo::DemoArgs;
pub use localize_demo::LocalizeDemoArgs;

/// The fleet (site) every lab run maps.
pub const FLEET: &str = "park";

/// Zenoh needs Tokio's multi-thread runtime.
pub fn runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    Ok(tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()?)
}

/// A mapper of the park for a lab run: its store in `dir` (made, or emptied if a lab run made
/// it: [`lab_dir::prepare`]),
/// the park's datum, the simulated robots' mapping ([`sim_mapping_params`]), HTTP on `http`,
/// a Zenoh router on `zenoh`. Callers add their tokens.
pub fn park_mapper_config(
    dir: &std::path::Path,
    http: &str,
    zenoh: &str,
) -> anyhow::Result<mapper::MapperConfig> {
    lab_dir::prepare(dir)?;
    Ok(mapper::MapperConfig {
        zenoh: runtime::session::SessionConfig::router(zenoh),
        http_listen: http.to_owned(),
        store_path: dir.join("mapper.redb"),
        datum: Some(sim::PARK_DATUM.origin),
        mapping: sim_mapping_params(),
        ..mapper::MapperConfig::default()
    })
}

/// The simulated robots' dead reckoning is precise (a fibre-optic-class gyro).
pub fn sim_mapping_params() -> slam::Mapper2dParams {
    slam::Mapper2dParams::precise_dead_reckoning()
}

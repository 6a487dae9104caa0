//! `levelmap`: the command line of the levelmap outdoor SLAM system.

//! Cargo features choose the commands: `edge` (the robot's service), `mapper` (the mapping
//! server and the offline solver tools, optimize and slam2d: faer), `lab` (the simulator and
//! the fleet lab: demo, bench-fleet, simulate, pavilion, level's sim format). `level` is in
//! every build. A command not compiled in is not in `--help` either.

#[cfg(feature = "mapper")]
mod backup;
mod level;
#[cfg(feature = "mapper")]
mod map_versions;
#[cfg(feature = "mapper")]
mod mapper_http;
#[cfg(feature = "mapper")]
mod optimize;
#[cfg(feature = "lab")]
mod pavilion;
#[cfg(any(feature = "edge", feature = "mapper"))]
mod record;
#[cfg(any(feature = "edge", feature = "mapper"))]
mod services;
#[cfg(feature = "lab")]
mod simulate;
#[cfg(feature = "mapper")]
mod site_log;
#[cfg(feature = "mapper")]
mod slam2d;
mod svg;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

/// Outdoor SLAM for robot fleets from 3D laser scans, via leveled range scans
/// (Wulf, Brenneke & Wagner). Every command has --help.
#[derive(Parser)]
#[command(name = "levelmap", version)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    #[cfg(feature = "mapper")]
    Backup(backup::BackupArgs),
    #[cfg(feature = "lab")]
    BenchCluster(fleetlab::BenchClusterArgs),
    #[cfg(feature = "lab")]
    BenchFleet(fleetlab::BenchFleetArgs),
    #[cfg(feature = "lab")]
    BenchGrowth(fleetlab::BenchGrowthArgs),
    #[cfg(feature = "lab")]
    BenchIncremental(fleetlab::BenchIncrementalArgs),
    #[cfg(feature = "lab")]
    Demo(fleetlab::DemoArgs),
    #[cfg(feature = "lab")]
    DemoLocalize(fleetlab::LocalizeDemoArgs),
    #[cfg(feature = "edge")]
    Edge(services::EdgeArgs),
    #[cfg(feature = "mapper")]
    Gateway(services::GatewayArgs),
    Level(level::LevelArgs),
    #[cfg(feature = "mapper")]
    Map(map_versions::MapArgs),
    #[cfg(feature = "mapper")]
    Mapper(services::MapperArgs),
    /// Print the mapping server's OpenAPI document (JSON), as it serves it at
    /// /api/v1/openapi.json: made from its routes.
    #[cfg(feature = "mapper")]
    Openapi,
    #[cfg(feature = "mapper")]
    Optimize(optimize::OptimizeArgs),
    #[cfg(feature = "lab")]
    Pavilion(pavilion::PavilionArgs),
    #[cfg(any(feature = "edge", feature = "mapper"))]
    Record(record::RecordArgs),
    #[cfg(feature = "lab")]
    Simulate(simulate::SimulateArgs),
    #[cfg(feature = "mapper")]
    SiteLog(site_log::SiteLogArgs),
    #[cfg(feature = "mapper")]
    Slam2d(slam2d::Slam2dArgs),
}

fn main() -> ExitCode {
    let result = match Cli::parse().command {
        #[cfg(feature = "mapper")]
        Command::Backup(args) => backup::run(&args),
        #[cfg(feature = "lab")]
        Command::BenchCluster(args) => fleetlab::bench_cluster::run(&args),
        #[cfg(feature = "lab")]
        Command::BenchFleet(args) => fleetlab::bench_fleet::run(&args),
        #[cfg(feature = "lab")]
        Command::BenchGrowth(args) => fleetlab::bench_growth::run(&args),
        #[cfg(feature = "lab")]
        Command::BenchIncremental(args) => fleetlab::bench_incremental::run(&args),
        #[cfg(feature = "lab")]
        Command::Demo(args) => fleetlab::demo::run(&args),
        #[cfg(feature = "lab")]
        Command::DemoLocalize(args) => fleetlab::localize_demo::run(&args),
        #[cfg(feature = "edge")]
        Command::Edge(args) => services::run_edge(&args),
        #[cfg(feature = "mapper")]
        Command::Gateway(args) => services::run_gateway(&args),
        #[cfg(feature = "mapper")]
        Command::Map(args) => map_versions::run(&args),
        #[cfg(feature = "mapper")]
        Command::Mapper(args) => services::run_mapper(&args),
        #[cfg(feature = "lab")]
        Command::Pavilion(args) => pavilion::run(&args),
        Command::Level(args) => level::run(&args),
        #[cfg(feature = "mapper")]
        Command::Openapi => {
            println!("{}", mapper::api::openapi_json());
            Ok(())
        }
        #[cfg(feature = "mapper")]
        Command::Optimize(args) => optimize::run(&args),
        #[cfg(any(feature = "edge", feature = "mapper"))]
        Command::Record(args) => record::run(&args),
        #[cfg(feature = "lab")]
        Command::Simulate(args) => simulate::run(&args),
        #[cfg(feature = "mapper")]
        Command::SiteLog(args) => site_log::run(&args),
        #[cfg(feature = "mapper")]
        Command::Slam2d(args) => slam2d::run(&args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

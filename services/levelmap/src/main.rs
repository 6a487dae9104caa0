//! `levelmap`: the command line of the levelmap outdoor SLAM system.

mod bench_fleet;
mod demo;
mod level;
mod optimize;
mod pavilion;
mod services;
mod simulate;
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
    BenchFleet(bench_fleet::BenchFleetArgs),
    Demo(demo::DemoArgs),
    Edge(services::EdgeArgs),
    Level(level::LevelArgs),
    Mapper(services::MapperArgs),
    Optimize(optimize::OptimizeArgs),
    Pavilion(pavilion::PavilionArgs),
    Simulate(simulate::SimulateArgs),
    Slam2d(slam2d::Slam2dArgs),
}

fn main() -> ExitCode {
    let result = match Cli::parse().command {
        Command::BenchFleet(args) => bench_fleet::run(&args),
        Command::Demo(args) => demo::run(&args),
        Command::Edge(args) => services::run_edge(&args),
        Command::Mapper(args) => services::run_mapper(&args),
        Command::Pavilion(args) => pavilion::run(&args),
        Command::Level(args) => level::run(&args),
        Command::Optimize(args) => optimize::run(&args),
        Command::Simulate(args) => simulate::run(&args),
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

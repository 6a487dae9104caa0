//! `levelmap simulate`: write a simulated 3D scan of the synthetic park as JSON, with the
//! dead reckoning over it and ground truth per point (input for `levelmap level`).

use anyhow::Result;
use clap::{Args, ValueEnum};
use serde::Serialize;
use sim::SimScanFile;
use std::path::PathBuf;

/// Which simulated scene to scan.
#[derive(Clone, Copy, Debug, ValueEnum, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Scene {
    /// Standing at the foot of the pavilion hill, facing the pavilion (paper Fig. 4).
    Pavilion,
    /// Driving past a long wall during the 4 s scan (paper 2.1: scanning while driving).
    Wall,
    /// Walking along a footpath with trees, the pavilion and the bridge in view.
    Demo,
}

/// Simulate one 3D scan (the paper's yawing scanner: 270° × 100°, 27,000 points in 4 s).
#[derive(Args, Debug)]
pub struct SimulateArgs {
    /// Where to write the scan (JSON; read it with `levelmap level FILE --format sim`).
    #[arg(long, value_name = "FILE.json")]
    pub out: PathBuf,
    #[arg(long, value_enum, default_value_t = Scene::Demo)]
    pub scene: Scene,
    /// Seed of every random draw (sensor noise, dead-reckoning errors); same seed, same scan.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Driving speed for the wall scene (m/s, 0–2).
    #[arg(long, default_value_t = 1.4)]
    pub speed_mps: f64,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

#[derive(Serialize)]
struct SimulateReport {
    file: String,
    scene: Scene,
    seed: u64,
    points: usize,
    columns: usize,
    valid_points: usize,
    odometry_samples: usize,
}

/// The scan of a scene.
pub fn scene_scan(scene: Scene, seed: u64, speed_mps: f64) -> SimScanFile {
    match scene {
        Scene::Pavilion => sim::scenario::pavilion_hill_scan(seed).0,
        Scene::Wall => sim::scenario::wall_drive_scan(seed, speed_mps),
        Scene::Demo => sim::scenario::demo_scan(seed),
    }
}

pub fn run(args: &SimulateArgs) -> Result<()> {
    if !(0.0..=sim::scenario::WALL_DRIVE_MAX_SPEED_MPS).contains(&args.speed_mps) {
        anyhow::bail!(
            "--speed-mps must lie in 0..={} m/s, got {}",
            sim::scenario::WALL_DRIVE_MAX_SPEED_MPS,
            args.speed_mps
        );
    }
    let file = scene_scan(args.scene, args.seed, args.speed_mps);
    sim::scan_file::save(&args.out, &file)?;
    let report = SimulateReport {
        file: args.out.display().to_string(),
        scene: args.scene,
        seed: args.seed,
        points: file.raw.points.len(),
        columns: file.raw.columns.len(),
        valid_points: file.raw.valid_points(),
        odometry_samples: file.odometry.len(),
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        println!(
            "wrote {} ({:?} scene, seed {}): {} points in {} columns, {} dead-reckoning samples",
            report.file,
            args.scene,
            args.seed,
            report.points,
            report.columns,
            report.odometry_samples
        );
    }
    Ok(())
}

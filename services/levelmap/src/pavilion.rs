//! `levelmap pavilion`: the paper's Fig. 4, live. A robot at the foot of the simulated pavilion
//! hill takes a 3D scan; levelmap levels it and draws it over what a fixed 2D scanner sees.

use crate::level::level_timed;
use anyhow::{Context, Result};
use clap::Args;
use leveling::SegmentParams;
use serde::Serialize;
use sim::SurfaceKind;
use std::path::PathBuf;

/// Level a simulated scan of the hilly park and write its picture (paper Fig. 4).
#[derive(Args, Debug)]
pub struct PavilionArgs {
    /// Folder for the scan (JSON) and the picture (SVG); created if missing.
    #[arg(long, value_name = "DIR", default_value = "levelmap-pavilion")]
    pub out_dir: PathBuf,
    /// Seed of every random draw; same seed, same scan.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

#[derive(Serialize)]
struct PavilionReport {
    scan_file: String,
    svg_file: String,
    points: usize,
    landmark: usize,
    overhang: usize,
    /// Leveled beams with a return.
    beams: usize,
    /// Leveled beams on the pavilion, and on the ground (hill slope or bridge deck).
    beams_on_pavilion: usize,
    beams_on_ground: usize,
    /// The fixed horizontal 2D scanner 1 m above the ground, from the same pose.
    fixed2d_returns: usize,
    fixed2d_on_pavilion: usize,
    fixed2d_on_ground: usize,
    /// Segmentation + projection, median of 10 runs (ms).
    elapsed_ms: f64,
    /// Share of landmark points that are not ground (simulator truth).
    landmark_precision: f64,
}

fn is_pavilion(kind: SurfaceKind) -> bool {
    matches!(
        kind,
        SurfaceKind::PavilionPillar | SurfaceKind::PavilionRoof
    )
}

pub fn run(args: &PavilionArgs) -> Result<()> {
    std::fs::create_dir_all(&args.out_dir)
        .with_context(|| format!("{}: cannot create", args.out_dir.display()))?;
    let scan_path = args.out_dir.join("pavilion-scan.json");
    let svg_path = args.out_dir.join("pavilion.svg");

    let (file, fixed2d) = sim::scenario::pavilion_hill_scan(args.seed);
    sim::scan_file::save(&scan_path, &file)?;
    let (loaded, truth) = sim::scan_file::into_loaded(file).map_err(anyhow::Error::msg)?;
    let (leveled, _, elapsed_ms) = level_timed(&loaded, SegmentParams::default(), 10)?;
    let beam_kinds: Vec<SurfaceKind> = leveled
        .first_landmarks
        .iter()
        .flatten()
        .filter_map(|&i| truth[i as usize])
        .collect();
    let precision = leveling::Precision::score(&leveled.classes, &leveled.first_landmarks, |i| {
        truth[i].map(|k| k.is_ground())
    });
    let picture = crate::svg::fig4(
        &loaded.raw,
        &leveled,
        "levelmap pavilion: the pavilion hill",
    );
    std::fs::write(&svg_path, picture)
        .with_context(|| format!("{}: cannot write", svg_path.display()))?;

    let fixed_kinds: Vec<SurfaceKind> = fixed2d.iter().filter_map(|b| b.kind).collect();
    let report = PavilionReport {
        scan_file: scan_path.display().to_string(),
        svg_file: svg_path.display().to_string(),
        points: loaded.raw.points.len(),
        landmark: leveled.counts.landmark,
        overhang: leveled.counts.overhang,
        beams: leveled.scan.return_count(),
        beams_on_pavilion: beam_kinds.iter().filter(|k| is_pavilion(**k)).count(),
        beams_on_ground: beam_kinds.iter().filter(|k| k.is_ground()).count(),
        fixed2d_returns: fixed_kinds.len(),
        fixed2d_on_pavilion: fixed_kinds.iter().filter(|k| is_pavilion(**k)).count(),
        fixed2d_on_ground: fixed_kinds.iter().filter(|k| k.is_ground()).count(),
        elapsed_ms,
        landmark_precision: precision.landmark_precision(),
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        println!(
            "levelmap pavilion: a robot at the foot of the pavilion hill (simulated park, seed {})",
            args.seed
        );
        println!(
            "  3D scan          {} points, {} landmark, {} overhang",
            report.points, report.landmark, report.overhang
        );
        println!(
            "  leveled scan     {} beams: {} on the pavilion, {} on the ground",
            report.beams, report.beams_on_pavilion, report.beams_on_ground
        );
        println!(
            "  fixed 2D scanner {} returns: {} on the pavilion, {} on the ground (the slope)",
            report.fixed2d_returns, report.fixed2d_on_pavilion, report.fixed2d_on_ground
        );
        println!(
            "  leveling took    {:.3} ms (segmentation + projection)",
            report.elapsed_ms
        );
        println!("  picture          {}", report.svg_file);
        println!(
            "  scan             {} (try: levelmap level {} --svg out.svg)",
            report.scan_file, report.scan_file
        );
    }
    Ok(())
}

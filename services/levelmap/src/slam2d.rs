//! `levelmap slam2d`: the whole 2D pipeline on a CARMEN log (nodes, odometry and IDC edges,
//! loop closures, optimization), scored with the Kümmerle et al. relations when given.

use anyhow::{Context, Result, bail};
use clap::Args;
use graphio::{carmen, gridmap};
use serde::Serialize;
use slam::matching::metric::return_to_start;
use slam::{
    GridParams, Mapper2d, Mapper2dParams, MapperStats, OccupancyGrid, WrongClosures, WrongMatches,
};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Build a 2D map from a CARMEN laser log (.clf, .clf.bz2, .log, .log.gz).
#[derive(Args, Debug)]
pub struct Slam2dArgs {
    /// The CARMEN log.
    pub log: PathBuf,
    /// Kümmerle et al. relations file: adds relation_trans_error_mean/std and
    /// relation_rot_error_mean (rad) and _mean_deg/_max_deg (poses at every relation timestamp).
    #[arg(long, value_name = "FILE")]
    pub relations: Option<PathBuf>,
    /// Write the occupancy grid (node scans at optimized poses) as PNG: free white,
    /// occupied black, unknown grey, north up.
    #[arg(long, value_name = "OUT.png")]
    pub png: Option<PathBuf>,
    /// Write the occupancy grid as ROS map_server reads it: OUT.pgm and OUT.yaml beside it.
    #[arg(long, value_name = "OUT.pgm")]
    pub pgm: Option<PathBuf>,
    /// Write every scan's optimized pose as a TUM trajectory (`t x y z qx qy qz qw`, as evo
    /// reads it).
    #[arg(long, value_name = "OUT.tum")]
    pub trajectory: Option<PathBuf>,
    /// Cell size of the occupancy grid (m); default slam::GridParams' (0.1).
    #[arg(long, value_name = "M")]
    pub resolution_m: Option<f64>,
    /// TOML file with a [mapper] table overriding the mapper's parameters (slam::Mapper2dParams).
    #[arg(long, value_name = "FILE.toml")]
    pub config: Option<PathBuf>,
    /// Inject wrong loop closures to see the consistency check work: this many per
    /// loop-closure match (0.1: one for every ten), each between the newest node and a random
    /// earlier one, their estimated relative pose off by 0.5–2 m and 3–15°.
    #[arg(long, value_name = "FRACTION")]
    pub inject_false_closures: Option<f64>,
    /// Inject wrong sequential matches to see the mapper find them: this many per node
    /// (0.01: one in a hundred), each a node's match with its robot's last node moved off
    /// by 0.3–1 m and 2–10° before the mapper's checks.
    #[arg(long, value_name = "FRACTION")]
    pub inject_wrong_matches: Option<f64>,
    /// Seed of the injected wrong closures and matches.
    #[arg(long, value_name = "N", default_value_t = 1)]
    pub seed: u64,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Mapper parameters from `--config` (a `[mapper]` table), or the defaults.
fn load_params(config: Option<&std::path::Path>) -> Result<Mapper2dParams> {
    #[derive(serde::Deserialize, Default)]
    #[serde(deny_unknown_fields)]
    struct File {
        #[serde(default)]
        mapper: Mapper2dParams,
    }
    match config {
        None => Ok(Mapper2dParams::default()),
        Some(path) => {
            let text =
                std::fs::read_to_string(path).with_context(|| format!("{}", path.display()))?;
            Ok(toml::from_str::<File>(&text)
                .with_context(|| format!("{}", path.display()))?
                .mapper)
        }
    }
}

#[derive(Serialize)]
struct Report {
    log: String,
    scans: usize,
    nodes: usize,
    loop_closures: usize,
    stats: MapperStats,
    final_chi2: f64,
    elapsed_ms: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    false_closures_injected: Option<usize>,
    /// Of the injected wrong closures, those that became edges.
    #[serde(skip_serializing_if = "Option::is_none")]
    false_closures_accepted: Option<usize>,
    /// Wrong sequential matches injected, and of them those that became edges.
    #[serde(skip_serializing_if = "Option::is_none")]
    wrong_matches_injected: Option<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    wrong_matches_accepted: Option<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    relations: Option<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    relation_trans_error_mean: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    relation_trans_error_std: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    relation_trans_error_max: Option<f64>,
    /// Mean absolute rotational relation error (rad), and in degrees as Kümmerle et al. and
    /// Hess et al. (Table II) give it.
    #[serde(skip_serializing_if = "Option::is_none")]
    relation_rot_error_mean: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    relation_rot_error_mean_deg: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    relation_rot_error_max_deg: Option<f64>,
    /// The last pose's distance from the first (m), and the last scan matched against the
    /// first from there: how far the match moves it (m, rad; null when they do not match).
    /// For a run that ends where it started, a closed loop needs a small correction.
    return_to_start_m: f64,
    return_correction_m: Option<f64>,
    return_correction_rad: Option<f64>,
}

pub fn run(args: &Slam2dArgs) -> Result<()> {
    let log = carmen::read(&args.log)?;
    if log.scans.is_empty() {
        bail!(
            "{}: no laser scans (FLASER or ROBOTLASER1)",
            args.log.display()
        );
    }
    let t0 = Instant::now();
    let params = load_params(args.config.as_deref())?;
    let mut mapper = Mapper2d::new(params.clone());
    let mut placed = Vec::with_capacity(log.scans.len());
    let mut wrong = args
        .inject_false_closures
        .map(|fraction| WrongClosures::new(fraction, args.seed));
    let mut wrong_matches = args
        .inject_wrong_matches
        .map(|fraction| WrongMatches::new(fraction, args.seed));
    for scan in &log.scans {
        placed.push(mapper.add_scan(scan.laser_pose, scan.to_scan2())?);
        if let Some(wrong) = &mut wrong {
            wrong.inject(&mut mapper)?;
        }
        if let Some(wrong) = &mut wrong_matches {
            wrong.inject(&mut mapper);
        }
    }
    let report = mapper.finish()?;
    let elapsed_ms = t0.elapsed().as_secs_f64() * 1e3;
    let pose_of_scan = |k: usize| mapper.pose_of(placed[k]);

    let metric = match &args.relations {
        None => None,
        Some(path) => {
            let relations = graphio::relations::read(path)?;
            let metric =
                graphio::relations::score(&relations, &log.scans, pose_of_scan).map_err(|e| {
                    anyhow::anyhow!("{}: {e} (scans of {})", path.display(), args.log.display())
                })?;
            Some((relations.len(), metric))
        }
    };
    if let Some(out) = &args.trajectory {
        let stamped = log.scans.iter().enumerate();
        let text = graphio::trajectory::to_tum(stamped.map(|(k, s)| (s.stamp_s, pose_of_scan(k))))?;
        write(out, text.as_bytes())?;
    }
    if args.png.is_some() || args.pgm.is_some() {
        let mut params = GridParams::default();
        if let Some(r) = args.resolution_m {
            params.resolution_m = r;
        }
        let grid = OccupancyGrid::from_scans(mapper.node_scans_at_poses(), &params)?;
        if let Some(out) = &args.png {
            write(out, &gridmap::to_png(&grid)?)?;
        }
        if let Some(out) = &args.pgm {
            let yaml_path = out.with_extension("yaml");
            let image = out.file_name().map_or_else(
                || out.display().to_string(),
                |n| n.to_string_lossy().into_owned(),
            );
            write(out, &gridmap::to_pgm(&grid)?)?;
            write(&yaml_path, gridmap::to_map_yaml(&grid, &image).as_bytes())?;
        }
    }
    let last = log.scans.len() - 1;
    let ends = [0, last].map(|k| (pose_of_scan(k), log.scans[k].to_scan2()));
    let back = return_to_start(
        (&ends[0].0, &ends[0].1),
        (&ends[1].0, &ends[1].1),
        &params.idc,
        &params.gate,
    );
    let stats = mapper.stats();
    let r = Report {
        log: args.log.display().to_string(),
        scans: log.scans.len(),
        nodes: stats.nodes,
        loop_closures: stats.loop_closures,
        stats,
        final_chi2: report.final_chi2,
        elapsed_ms,
        false_closures_injected: wrong.as_ref().map(WrongClosures::injected),
        false_closures_accepted: wrong.as_ref().map(|w| w.accepted(mapper.graph())),
        wrong_matches_injected: wrong_matches.as_ref().map(|w| w.injected(&mapper)),
        wrong_matches_accepted: wrong_matches.as_ref().map(|w| w.accepted(&mapper)),
        relations: metric.map(|m| m.0),
        relation_trans_error_mean: metric.map(|m| m.1.translation_mean_m),
        relation_trans_error_std: metric.map(|m| m.1.translation_std_m),
        relation_trans_error_max: metric.map(|m| m.1.translation_max_m),
        relation_rot_error_mean: metric.map(|m| m.1.rotation_mean_rad),
        relation_rot_error_mean_deg: metric.map(|m| m.1.rotation_mean_rad.to_degrees()),
        relation_rot_error_max_deg: metric.map(|m| m.1.rotation_max_rad.to_degrees()),
        return_to_start_m: back.distance_m,
        return_correction_m: back.correction_m,
        return_correction_rad: back.correction_rad,
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        println!(
            "{}: {} scans → {} nodes, {} loop closures ({} rejected as inconsistent), {:.0} ms",
            r.log, r.scans, r.nodes, r.loop_closures, r.stats.loop_closures_rejected, r.elapsed_ms
        );
        if let (Some(injected), Some(accepted)) =
            (r.false_closures_injected, r.false_closures_accepted)
        {
            println!("  wrong closures: {injected} injected, {accepted} became edges");
        }
        if let (Some(injected), Some(accepted)) =
            (r.wrong_matches_injected, r.wrong_matches_accepted)
        {
            println!("  wrong matches: {injected} injected, {accepted} became edges");
        }
        if let (Some(m), Some(s)) = (r.relation_trans_error_mean, r.relation_trans_error_std) {
            println!("  relations: translation error {m:.4} ± {s:.4} m");
        }
        if let Some(deg) = r.relation_rot_error_mean_deg {
            println!("  relations: rotation error {deg:.3}°");
        }
        let correction = r
            .return_correction_m
            .map_or("the scans do not match".into(), |c| format!("{c:.2} m"));
        println!(
            "  last pose {:.2} m from the first; last scan matched to the first: {correction}",
            r.return_to_start_m
        );
    }
    Ok(())
}

fn write(out: &Path, bytes: &[u8]) -> Result<()> {
    std::fs::write(out, bytes).with_context(|| format!("{}: cannot write", out.display()))
}

//! `levelmap slam2d`: the whole 2D pipeline on a CARMEN log (nodes, odometry and IDC edges,
//! loop closures, optimization), scored with the Kümmerle et al. relations when given.

use anyhow::{Context, Result, bail};
use clap::Args;
use graphio::carmen;
use serde::Serialize;
use slam::{Mapper2d, Mapper2dParams, MapperStats};
use std::path::PathBuf;
use std::time::Instant;

/// Build a 2D map from a CARMEN laser log (.clf, .clf.bz2, .log, .log.gz).
#[derive(Args, Debug)]
pub struct Slam2dArgs {
    /// The CARMEN log.
    pub log: PathBuf,
    /// Kümmerle et al. relations file: adds relation_trans_error_mean/std and
    /// relation_rot_error_mean (poses at every relation timestamp).
    #[arg(long, value_name = "FILE")]
    pub relations: Option<PathBuf>,
    /// Draw the map (scans at optimized node poses) as PNG.
    #[arg(long, value_name = "OUT.png")]
    pub png: Option<PathBuf>,
    /// Write every scan's optimized pose as a TUM trajectory (`t x y z qx qy qz qw`, as evo
    /// reads it).
    #[arg(long, value_name = "OUT.tum")]
    pub trajectory: Option<PathBuf>,
    /// Map resolution of the PNG (m per pixel).
    #[arg(long, default_value_t = 0.05)]
    pub resolution_m: f64,
    /// TOML file with a [mapper] table overriding the mapper's parameters (slam::Mapper2dParams).
    #[arg(long, value_name = "FILE.toml")]
    pub config: Option<PathBuf>,
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
    relations: Option<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    relation_trans_error_mean: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    relation_trans_error_std: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    relation_trans_error_max: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    relation_rot_error_mean: Option<f64>,
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
    let mut mapper = Mapper2d::new(load_params(args.config.as_deref())?);
    let mut placed = Vec::with_capacity(log.scans.len());
    for scan in &log.scans {
        placed.push(mapper.add_scan(scan.laser_pose, scan.to_scan2())?);
    }
    let report = mapper.finish()?;
    let elapsed_ms = t0.elapsed().as_secs_f64() * 1e3;
    let graph = mapper.graph();
    let pose_of_scan = |k: usize| mapper.pose_of(placed[k]);

    let metric = match &args.relations {
        None => None,
        Some(path) => {
            let relations = graphio::relations::read(path)?;
            let metric =
                graphio::relations::score(&relations, &log.scans, pose_of_scan).map_err(|e| {
                    anyhow::anyhow!(
                        "{}: {e} (no scan with that timestamp in {})",
                        path.display(),
                        args.log.display()
                    )
                })?;
            Some((relations.len(), metric))
        }
    };
    if let Some(out) = &args.trajectory {
        let mut text = String::with_capacity(log.scans.len() * 64);
        for (k, scan) in log.scans.iter().enumerate() {
            let p = pose_of_scan(k);
            let (s, c) = (0.5 * p.theta).sin_cos();
            text.push_str(&format!(
                "{:.6} {:.6} {:.6} 0 0 0 {s:.9} {c:.9}\n",
                scan.stamp_s, p.x, p.y
            ));
        }
        std::fs::write(out, text).with_context(|| format!("{}: cannot write", out.display()))?;
    }
    if let Some(out) = &args.png {
        let points: Vec<[f64; 2]> = (0..graph.poses.len())
            .flat_map(|n| {
                mapper
                    .node_scan(n)
                    .points()
                    .iter()
                    .map(move |p| graph.poses[n].transform_point(*p))
            })
            .collect();
        let path: Vec<[f64; 2]> = graph.poses.iter().map(|p| [p.x, p.y]).collect();
        write_png(out, &points, &path, args.resolution_m)?;
    }
    let stats = mapper.stats();
    let r = Report {
        log: args.log.display().to_string(),
        scans: log.scans.len(),
        nodes: stats.nodes,
        loop_closures: stats.loop_closures,
        stats,
        final_chi2: report.final_chi2,
        elapsed_ms,
        relations: metric.map(|m| m.0),
        relation_trans_error_mean: metric.map(|m| m.1.translation_mean_m),
        relation_trans_error_std: metric.map(|m| m.1.translation_std_m),
        relation_trans_error_max: metric.map(|m| m.1.translation_max_m),
        relation_rot_error_mean: metric.map(|m| m.1.rotation_mean_rad),
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        println!(
            "{}: {} scans → {} nodes, {} loop closures, {:.0} ms",
            r.log, r.scans, r.nodes, r.loop_closures, r.elapsed_ms
        );
        if let (Some(m), Some(s)) = (r.relation_trans_error_mean, r.relation_trans_error_std) {
            println!("  relations: translation error {m:.4} ± {s:.4} m");
        }
    }
    Ok(())
}

/// Scan points (black) and the node path (blue) on white, x east → right, y north → up.
fn write_png(
    out: &PathBuf,
    points: &[[f64; 2]],
    path: &[[f64; 2]],
    resolution_m: f64,
) -> Result<()> {
    let all = points.iter().chain(path);
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in all {
        for d in 0..2 {
            lo[d] = lo[d].min(p[d]);
            hi[d] = hi[d].max(p[d]);
        }
    }
    let resolution = resolution_m.max(((hi[0] - lo[0]).max(hi[1] - lo[1]) / 4000.0).max(1e-3));
    let (w, h) = (
        ((hi[0] - lo[0]) / resolution) as usize + 3,
        ((hi[1] - lo[1]) / resolution) as usize + 3,
    );
    let mut rgb = vec![255u8; w * h * 3];
    let mut put = |p: &[f64; 2], color: [u8; 3]| {
        let (x, y) = (
            ((p[0] - lo[0]) / resolution) as usize + 1,
            ((hi[1] - p[1]) / resolution) as usize + 1,
        );
        if x < w && y < h {
            rgb[(y * w + x) * 3..(y * w + x) * 3 + 3].copy_from_slice(&color);
        }
    };
    points.iter().for_each(|p| put(p, [20, 20, 20]));
    path.iter().for_each(|p| put(p, [30, 90, 220]));
    let file =
        std::fs::File::create(out).with_context(|| format!("{}: cannot create", out.display()))?;
    let mut encoder = png::Encoder::new(std::io::BufWriter::new(file), w as u32, h as u32);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.write_header()?.write_image_data(&rgb)?;
    Ok(())
}

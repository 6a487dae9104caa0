//! `levelmap level`: turn one 3D scan file into its leveled range scan.

use anyhow::{Context, Result, bail};
use clap::Args;
use leveling::{Leveled, Leveler, Precision, SegmentParams};
use scanio::labels::Labels;
use scanio::{LoadedScan, ScanFormat};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

mod ouster;

/// A scan file's format: scanio's real ones and, in the lab build, the simulator's JSON.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    Scan(ScanFormat),
    /// An Ouster pcap capture (many scans), read with `--meta`.
    Ouster,
    #[cfg(feature = "lab")]
    Sim,
}

impl Format {
    /// As the report names it.
    fn name(self) -> &'static str {
        match self {
            Format::Scan(ScanFormat::Kitti) => "kitti",
            Format::Scan(ScanFormat::ThreeDtk) => "threedtk",
            Format::Ouster => "ouster",
            #[cfg(feature = "lab")]
            Format::Sim => "sim",
        }
    }
}

#[cfg(feature = "lab")]
const FORMATS: (&str, &str) = ("kitti, 3dtk, ouster or sim", "kitti|3dtk|ouster|sim");
#[cfg(not(feature = "lab"))]
const FORMATS: (&str, &str) = ("kitti, 3dtk or ouster", "kitti|3dtk|ouster");

/// The format named by `--format`, or guessed from the file's extension.
pub fn scan_format(file: &Path, format: Option<&str>) -> Result<Format> {
    match format {
        Some("kitti") => Ok(Format::Scan(ScanFormat::Kitti)),
        Some("3dtk") => Ok(Format::Scan(ScanFormat::ThreeDtk)),
        Some("ouster") => Ok(Format::Ouster),
        #[cfg(feature = "lab")]
        Some("sim") => Ok(Format::Sim),
        Some(other) => bail!(
            "{}: unknown format {other:?} (expected {})",
            file.display(),
            FORMATS.0
        ),
        #[cfg(feature = "lab")]
        None if file.extension().is_some_and(|e| e == "json") => Ok(Format::Sim),
        None if file.extension().is_some_and(|e| e == "pcap") => Ok(Format::Ouster),
        None => ScanFormat::from_extension(file)
            .map(Format::Scan)
            .with_context(|| {
                format!(
                    "{}: cannot tell the format from the extension; pass --format {}",
                    file.display(),
                    FORMATS.1
                )
            }),
    }
}

/// Level one 3D scan: motion compensation, segmentation (eqs. 3.2–3.3), projection (eq. 3.4).
#[derive(Args, Debug)]
pub struct LevelArgs {
    /// The 3D scan file (an Ouster capture: every complete frame).
    pub file: PathBuf,
    /// File format: kitti (Velodyne .bin, float32 x y z reflectance), 3dtk (.3d text in cm,
    /// with FILE.pose beside it if present), ouster (pcap capture, with --meta) or sim
    /// (levelmap simulator JSON; lab builds only). Guessed from the extension (.bin, .3d,
    /// .pcap, .json) when omitted.
    #[cfg_attr(feature = "lab", arg(long, value_name = "kitti|3dtk|ouster|sim"))]
    #[cfg_attr(not(feature = "lab"), arg(long, value_name = "kitti|3dtk|ouster"))]
    pub format: Option<String>,
    /// The sensor's metadata JSON for an Ouster capture (required with one).
    #[arg(long, value_name = "FILE.json")]
    pub meta: Option<PathBuf>,
    /// SemanticKITTI .label file for the scan: adds landmark_precision and beam_precision.
    #[arg(long, value_name = "FILE.label")]
    pub labels: Option<PathBuf>,
    /// TOML file with a `[segment]` table overriding the thresholds (see deploy/leveling.toml).
    #[arg(long, value_name = "FILE.toml")]
    pub config: Option<PathBuf>,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
    /// Draw the leveled scan over a horizontal 2D cut of the same cloud (paper Fig. 4).
    #[arg(long, value_name = "OUT.svg")]
    pub svg: Option<PathBuf>,
    /// Time segmentation + projection over this many runs and report the median.
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u32).range(1..=10_000))]
    pub repeat: u32,
}

/// The `--json` report.
#[derive(Serialize, Debug)]
pub struct LevelReport {
    pub file: String,
    pub format: String,
    pub points: usize,
    pub columns: usize,
    pub invalid: usize,
    pub ground: usize,
    pub landmark: usize,
    pub overhang: usize,
    /// Beams with a return.
    pub beams: usize,
    /// Segmentation + projection, median over `repeat` runs (ms).
    pub elapsed_ms: f64,
    pub repeat: u32,
    pub load_ms: f64,
    pub deskew_ms: f64,
    pub params: SegmentParams,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub landmark_precision: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub beam_precision: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub scoring: Option<Precision>,
    pub warnings: Vec<String>,
}

/// Segment thresholds from `--config` (a `[segment]` table), or the defaults.
pub fn load_params(config: Option<&Path>) -> Result<SegmentParams> {
    #[derive(serde::Deserialize, Default)]
    #[serde(deny_unknown_fields)]
    struct File {
        #[serde(default)]
        segment: SegmentParams,
    }
    let params = match config {
        None => SegmentParams::default(),
        Some(path) => {
            let text =
                std::fs::read_to_string(path).with_context(|| format!("{}", path.display()))?;
            toml::from_str::<File>(&text)
                .with_context(|| format!("{}", path.display()))?
                .segment
        }
    };
    params
        .validate()
        .map_err(anyhow::Error::msg)
        .context("invalid [segment] thresholds")?;
    Ok(params)
}

pub fn run(args: &LevelArgs) -> Result<()> {
    let params = load_params(args.config.as_deref())?;
    let format = scan_format(&args.file, args.format.as_deref())?;
    if format == Format::Ouster {
        return ouster::run(args, params);
    }
    if args.meta.is_some() {
        bail!(
            "--meta is for Ouster captures (.pcap), not {} files",
            format.name()
        );
    }
    let t0 = Instant::now();
    let (loaded, sim_truth): (LoadedScan, Option<Vec<Option<bool>>>) = match format {
        Format::Ouster => unreachable!("read above"),
        #[cfg(feature = "lab")]
        Format::Sim => sim::scan_file::load(&args.file).map(|(scan, truth)| {
            // Per point: on the ground or not (None: no surface, no return).
            (
                scan,
                Some(truth.iter().map(|k| k.map(|k| k.is_ground())).collect()),
            )
        })?,
        Format::Scan(format) => (scanio::load(&args.file, format)?, None),
    };
    let load_ms = ms(t0);
    let labels = args
        .labels
        .as_deref()
        .map(|path| Labels::load(path, loaded.file_index.len()))
        .transpose()?;

    let (leveled, deskew_ms, elapsed_ms) = level_timed(&loaded, params, args.repeat)?;
    // Ground truth per scan point: the labels if given, else the simulator's truth.
    let precision = if let Some(labels) = &labels {
        Some(Precision::score(
            &leveled.classes,
            &leveled.first_landmarks,
            |i| labels.is_ground(loaded.file_index[i] as usize),
        ))
    } else {
        sim_truth
            .as_ref()
            .map(|truth| Precision::score(&leveled.classes, &leveled.first_landmarks, |i| truth[i]))
    };

    let report = report(
        &args.file,
        format.name(),
        &loaded,
        &leveled,
        (load_ms, deskew_ms, elapsed_ms),
        args.repeat,
        params,
        precision,
    );
    if let Some(out) = &args.svg {
        let picture = crate::svg::fig4(&loaded.raw, &leveled, &args.file.display().to_string());
        std::fs::write(out, picture)
            .with_context(|| format!("{}: cannot write the SVG", out.display()))?;
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print_text(&report);
    }
    Ok(())
}

/// The report of one leveled scan; its warnings also go to stderr.
#[allow(clippy::too_many_arguments)]
pub fn report(
    file: &Path,
    format: &str,
    loaded: &LoadedScan,
    leveled: &Leveled,
    (load_ms, deskew_ms, elapsed_ms): (f64, f64, f64),
    repeat: u32,
    params: SegmentParams,
    precision: Option<Precision>,
) -> LevelReport {
    let mut warnings = Vec::new();
    if leveled.counts.invalid == loaded.raw.points.len() {
        warnings.push(format!(
            "{}: none of the {} points is a valid return (NaN, or outside {}..{} m)",
            file.display(),
            loaded.raw.points.len(),
            params.min_range_m,
            params.max_range_m
        ));
    }
    if leveled.scan.return_count() == 0 {
        warnings.push(format!(
            "{}: no landmark found: the leveled scan has no beams",
            file.display()
        ));
    }
    for w in &warnings {
        eprintln!("warning: {w}");
    }

    LevelReport {
        file: file.display().to_string(),
        format: format.into(),
        points: loaded.raw.points.len(),
        columns: loaded.raw.columns.len(),
        invalid: leveled.counts.invalid,
        ground: leveled.counts.ground,
        landmark: leveled.counts.landmark,
        overhang: leveled.counts.overhang,
        beams: leveled.scan.return_count(),
        elapsed_ms,
        repeat,
        load_ms,
        deskew_ms,
        params,
        landmark_precision: precision.map(|p| p.landmark_precision()),
        beam_precision: precision.map(|p| p.beam_precision()),
        scoring: precision,
        warnings,
    }
}

/// Levels `loaded`; returns the result, the deskew time and the median segmentation +
/// projection time (ms) over `repeat` runs.
pub fn level_timed(
    loaded: &LoadedScan,
    params: SegmentParams,
    repeat: u32,
) -> Result<(Leveled, f64, f64)> {
    let mut leveler = Leveler::new(params);
    let t0 = Instant::now();
    let cloud = leveling::deskew(&loaded.raw, &loaded.track, &loaded.sensor_in_robot)?;
    let deskew_ms = ms(t0);
    let mut times = Vec::with_capacity(repeat as usize);
    let mut leveled = None;
    for _ in 0..repeat {
        let input = cloud.clone();
        let t = Instant::now();
        let out = leveler.segment_and_project(input);
        times.push(ms(t));
        leveled = Some(out);
    }
    let Some(leveled) = leveled else {
        bail!("--repeat must be at least 1")
    };
    times.sort_by(f64::total_cmp);
    Ok((leveled, deskew_ms, times[times.len() / 2]))
}

pub fn ms(since: Instant) -> f64 {
    since.elapsed().as_secs_f64() * 1e3
}

pub fn print_text(r: &LevelReport) {
    println!("{} ({})", r.file, r.format);
    println!(
        "  points     {:>8} in {} columns ({} invalid)",
        r.points, r.columns, r.invalid
    );
    println!("  landmark   {:>8}", r.landmark);
    println!("  overhang   {:>8}", r.overhang);
    println!("  ground     {:>8}", r.ground);
    println!(
        "  beams      {:>8} of {} columns have a return",
        r.beams, r.columns
    );
    println!(
        "  time       {:>8.3} ms segmentation + projection (median of {})",
        r.elapsed_ms, r.repeat
    );
    if let (Some(l), Some(b)) = (r.landmark_precision, r.beam_precision) {
        println!("  precision  landmark {l:.4}, beams {b:.4} (share not on ground classes)");
    }
}

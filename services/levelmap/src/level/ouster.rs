//! `levelmap level FILE.pcap --meta FILE.json`: every complete frame of an Ouster capture,
//! leveled and reported as `level` reports one scan.

use super::{LevelArgs, LevelReport, level_timed, ms, print_text, report};
use anyhow::{Context, Result, bail};
use leveling::SegmentParams;
use scanio::ouster::{OusterCounts, OusterScans};
use serde::Serialize;
use std::time::Instant;

/// One frame's report: the sensor's frame id and the figures of `level`.
#[derive(Serialize, Debug)]
struct FrameReport {
    frame_id: u16,
    #[serde(flatten)]
    level: LevelReport,
}

/// The `--json` report of a capture.
#[derive(Serialize, Debug)]
struct CaptureReport {
    file: String,
    meta: String,
    format: &'static str,
    frames: Vec<FrameReport>,
    /// Packets and frames kept and dropped.
    counts: OusterCounts,
    /// Drops and truncation, each naming the file.
    warnings: Vec<String>,
}

pub fn run(args: &LevelArgs, params: SegmentParams) -> Result<()> {
    let file = &args.file;
    let Some(meta) = args.meta.as_deref() else {
        bail!(
            "{}: an Ouster capture needs --meta FILE.json (the sensor's metadata)",
            file.display()
        );
    };
    if args.labels.is_some() {
        bail!("--labels is for KITTI scans, not Ouster captures");
    }
    let mut scans = OusterScans::open(file, meta)?;
    let mut frames = Vec::new();
    loop {
        let t0 = Instant::now();
        let Some((frame_id, loaded)) = scans.next_scan() else {
            break;
        };
        let load_ms = ms(t0);
        let (leveled, deskew_ms, elapsed_ms) = level_timed(&loaded, params, args.repeat)?;
        let times = (load_ms, deskew_ms, elapsed_ms);
        let level = report(
            file,
            "ouster",
            &loaded,
            &leveled,
            times,
            args.repeat,
            params,
            None,
        );
        if frames.is_empty()
            && let Some(out) = &args.svg
        {
            let title = format!("{} frame {frame_id}", file.display());
            std::fs::write(out, crate::svg::fig4(&loaded.raw, &leveled, &title))
                .with_context(|| format!("{}: cannot write the SVG", out.display()))?;
        }
        frames.push(FrameReport { frame_id, level });
    }
    let read = scans.report();
    let warnings = read.warnings(file);
    if frames.is_empty() {
        // One error line, with what went wrong folded in.
        let mut why = vec![format!(
            "{} lidar packets on port {}",
            read.counts.lidar_packets,
            scans.meta().udp_port_lidar
        )];
        why.extend(warnings);
        bail!("{}: no complete frame ({})", file.display(), why.join("; "));
    }
    for w in &warnings {
        eprintln!("warning: {w}");
    }
    let capture = CaptureReport {
        file: file.display().to_string(),
        meta: meta.display().to_string(),
        format: "ouster",
        frames,
        counts: read.counts,
        warnings,
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&capture)?);
    } else {
        for f in &capture.frames {
            print!("frame {}: ", f.frame_id);
            print_text(&f.level);
        }
        let c = &capture.counts;
        println!(
            "{} frames ({} incomplete dropped), {} lidar packets ({} bad), {} on other ports",
            c.frames, c.incomplete_frames, c.lidar_packets, c.bad_packets, c.other_ports
        );
    }
    Ok(())
}

//! `levelmap backup`: a consistent copy of a running mapper's store, over its HTTP API
//! (POST /api/v1/store/backup, the write token), without stopping it. The copy is written
//! beside OUT, synced, checked (it opens as a store; each fleet's nodes counted) and only
//! then renamed to OUT. `levelmap mapper --restore OUT` starts a mapper from it.

use crate::mapper_http::{MapperArgs, agent, refused};
use anyhow::{Context, Result, bail};
use clap::Args;
use serde::Serialize;
use std::path::PathBuf;
use std::time::Instant;

/// Take a backup of a running mapper's store (needs the write token) into one file, while
/// it maps: every table as one commit left it. Start a mapper from it with `levelmap
/// mapper --restore FILE`.
#[derive(Args, Debug)]
pub struct BackupArgs {
    /// The file to write (refused if it exists).
    out: PathBuf,
    #[command(flatten)]
    mapper: MapperArgs,
    /// Print the report as JSON.
    #[arg(long)]
    json: bool,
}

/// What a backup wrote.
#[derive(Debug, Serialize)]
struct BackupReport {
    out: PathBuf,
    bytes: u64,
    /// (fleet, nodes) in the copy, as the copy itself counts them.
    fleets: Vec<(String, u64)>,
    seconds: f64,
}

pub fn run(args: &BackupArgs) -> Result<()> {
    let started = Instant::now();
    let out = &args.out;
    if out.exists() {
        bail!(
            "{}: exists; a backup does not overwrite a file",
            out.display()
        );
    }
    let url = args.mapper.url("/api/v1/store/backup");
    let mut request = agent().post(&url);
    if let Some(t) = &args.mapper.token {
        request = request.header("Authorization", format!("Bearer {t}"));
    }
    let response = request
        .send_empty()
        .with_context(|| format!("{url}: no answer"))?;
    let status = response.status().as_u16();
    if status != 200 {
        let body = response.into_body().read_to_vec().unwrap_or_default();
        return Err(refused(&url, status, &body));
    }
    let mut partial = out.as_os_str().to_owned();
    partial.push(".partial");
    let partial = PathBuf::from(partial);
    let written = (|| -> Result<()> {
        let mut file = std::fs::File::create(&partial)?;
        std::io::copy(&mut response.into_body().into_reader(), &mut file)
            .context("the mapper's answer ended early")?;
        file.sync_all()?;
        Ok(())
    })();
    if let Err(e) = written {
        let _ = std::fs::remove_file(&partial);
        return Err(e.context(format!("{}: not written", out.display())));
    }
    // Checked as the mapper will open it; only a whole store is renamed to OUT.
    let report = match mapper::store::restore_backup(&partial, out) {
        Ok(report) => report,
        Err(e) => {
            let _ = std::fs::remove_file(&partial);
            bail!("{url}: the copy does not open as a store: {e}; nothing written");
        }
    };
    let _ = std::fs::remove_file(&partial);
    let report = BackupReport {
        out: out.clone(),
        bytes: report.bytes,
        fleets: report.fleets,
        seconds: started.elapsed().as_secs_f64(),
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        let fleets: Vec<String> = report
            .fleets
            .iter()
            .map(|(f, n)| format!("{f}: {n} nodes"))
            .collect();
        println!(
            "{} bytes in {:.1} s → {} ({})",
            report.bytes,
            report.seconds,
            out.display(),
            fleets.join(", ")
        );
    }
    Ok(())
}

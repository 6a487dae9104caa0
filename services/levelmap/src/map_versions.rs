//! `levelmap map export` and `levelmap map import`: a map version between a running mapper's
//! HTTP API and one file (`wire::encode_map_version_file`). Both check the file whole
//! (`wire::decode_map_version_file`) before they write or send anything.

use anyhow::{Context, Result, bail};
use clap::{Args, Subcommand};
use serde::Serialize;
use std::path::{Path, PathBuf};
use wire::MAX_MAP_VERSION_BYTES;

use crate::mapper_http::{MapperArgs, agent, refused};

/// Map versions (a fleet's map frozen: POST /api/v1/fleets/{fleet}/versions) between a
/// running mapper and one file: export from one mapper, import into another.
#[derive(Args, Debug)]
pub struct MapArgs {
    #[command(subcommand)]
    command: MapCommand,
}

#[derive(Subcommand, Debug)]
enum MapCommand {
    Export(ExportArgs),
    Import(ImportArgs),
}

/// Save a version of a fleet's map from a running mapper into one file (protobuf,
/// levelmap.v1.MapVersionFile). The file is checked whole before it is written.
#[derive(Args, Debug)]
pub struct ExportArgs {
    /// The fleet.
    fleet: String,
    /// The version's number in the fleet.
    version: u64,
    /// The file to write.
    out: PathBuf,
    #[command(flatten)]
    mapper: MapperArgs,
    /// Print the report as JSON.
    #[arg(long)]
    json: bool,
}

/// Take a version file into a running mapper, as the fleet's next version there (its number
/// in the answer). A damaged or cut file, or one of another format version, is refused
/// before anything is sent; the mapper checks it again.
#[derive(Args, Debug)]
pub struct ImportArgs {
    /// The version file (`levelmap map export`).
    file: PathBuf,
    /// Take it into this fleet (default: the fleet it was exported from).
    #[arg(long)]
    fleet: Option<String>,
    #[command(flatten)]
    mapper: MapperArgs,
    /// Print the mapper's answer (the version's summary) as JSON.
    #[arg(long)]
    json: bool,
}

/// Asks the mapper whether the token may write before a file is sent: a mapper refuses
/// an upload before reading it, which the client would see as a broken pipe, not why.
fn may_write(mapper: &MapperArgs) -> Result<()> {
    let url = mapper.url("/api/v1/auth");
    let mut request = agent().get(&url);
    if let Some(t) = &mapper.token {
        request = request.header("Authorization", format!("Bearer {t}"));
    }
    let (status, body) = answer(
        request
            .call()
            .with_context(|| format!("{url}: no answer"))?,
    )?;
    let state: serde_json::Value = match status {
        200 => serde_json::from_slice(&body).unwrap_or_default(),
        // An older mapper: its answer to the upload will say.
        _ => return Ok(()),
    };
    match state["authorized"].as_bool() {
        Some(false) => bail!(
            "{}: {}; nothing sent",
            mapper.mapper,
            state["reason"]
                .as_str()
                .unwrap_or("the token may not write")
        ),
        _ => Ok(()),
    }
}

/// What an export wrote.
#[derive(Debug, Serialize)]
struct ExportReport {
    out: PathBuf,
    fleet: String,
    version: u64,
    created_ns: u64,
    robots: usize,
    nodes: usize,
    file_bytes: usize,
}

pub fn run(args: &MapArgs) -> Result<()> {
    match &args.command {
        MapCommand::Export(a) => export(a),
        MapCommand::Import(a) => import(a),
    }
}

/// The answer's status and body, read up to a version file's bound.
fn answer(response: ureq::http::Response<ureq::Body>) -> Result<(u16, Vec<u8>)> {
    let status = response.status().as_u16();
    let body = response
        .into_body()
        .with_config()
        .limit(MAX_MAP_VERSION_BYTES as u64 + 1)
        .read_to_vec()
        .context("reading the mapper's answer")?;
    Ok((status, body))
}

fn export(args: &ExportArgs) -> Result<()> {
    let url = args.mapper.url(&format!(
        "/api/v1/fleets/{}/versions/{}/file",
        args.fleet, args.version
    ));
    let mut request = agent().get(&url);
    if let Some(t) = &args.mapper.token {
        request = request.header("Authorization", format!("Bearer {t}"));
    }
    let (status, file) = answer(
        request
            .call()
            .with_context(|| format!("{url}: no answer"))?,
    )?;
    if status != 200 {
        return Err(refused(&url, status, &file));
    }
    let version = wire::decode_map_version_file(&file).map_err(|e| {
        anyhow::anyhow!("{url}: the mapper's file does not read back: {e}; nothing written")
    })?;
    write_whole(&args.out, &file)?;
    let robots: std::collections::BTreeSet<&str> =
        version.nodes.iter().map(|n| n.robot.as_str()).collect();
    let report = ExportReport {
        out: args.out.clone(),
        fleet: version.fleet.clone(),
        version: version.number,
        created_ns: version.created_ns,
        robots: robots.len(),
        nodes: version.nodes.len(),
        file_bytes: file.len(),
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        println!(
            "{} version {}: {} nodes of {} robot(s), {} bytes → {}",
            report.fleet,
            report.version,
            report.nodes,
            report.robots,
            report.file_bytes,
            report.out.display()
        );
    }
    Ok(())
}

/// Writes `bytes` to `path` through a temporary file beside it, so `path` is whole or absent.
fn write_whole(path: &Path, bytes: &[u8]) -> Result<()> {
    let mut part = path.as_os_str().to_owned();
    part.push(".part");
    let part = PathBuf::from(part);
    std::fs::write(&part, bytes).with_context(|| format!("{}: cannot write", part.display()))?;
    std::fs::rename(&part, path).with_context(|| format!("{}: cannot write", path.display()))
}

fn import(args: &ImportArgs) -> Result<()> {
    let name = args.file.display();
    let len = std::fs::metadata(&args.file)
        .with_context(|| format!("{name}: cannot read"))?
        .len();
    if len > MAX_MAP_VERSION_BYTES as u64 {
        bail!("{name}: {len} bytes, over the {MAX_MAP_VERSION_BYTES} a version file may have");
    }
    let file = std::fs::read(&args.file).with_context(|| format!("{name}: cannot read"))?;
    // Formatted here: the error's own source would repeat its last words.
    let version = wire::decode_map_version_file(&file)
        .map_err(|e| anyhow::anyhow!("{name}: not a map version file: {e}; nothing sent"))?;
    let fleet = args.fleet.as_deref().unwrap_or(&version.fleet);
    wire::validate_id("fleet", fleet)?;
    may_write(&args.mapper)?;
    let url = args
        .mapper
        .url(&format!("/api/v1/fleets/{fleet}/versions/import"));
    let mut request = agent()
        .post(&url)
        .header("Content-Type", "application/x-protobuf");
    if let Some(t) = &args.mapper.token {
        request = request.header("Authorization", format!("Bearer {t}"));
    }
    let sent = request.send(&file[..]);
    let (status, body) = answer(sent.with_context(|| format!("{url}: no answer"))?)?;
    if status != 201 {
        return Err(refused(&url, status, &body));
    }
    let summary: serde_json::Value =
        serde_json::from_slice(&body).with_context(|| format!("{url}: not a version summary"))?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        println!(
            "{name} ({} version {}) → {fleet} version {}: {} nodes",
            version.fleet, version.number, summary["version"], summary["nodes"]
        );
    }
    Ok(())
}

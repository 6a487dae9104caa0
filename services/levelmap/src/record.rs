//! `levelmap record`: a fleet's levelmap traffic from Zenoh into an MCAP file
//! (`runtime::recording`: one channel per key, the protobuf schemas embedded), until SIGINT,
//! SIGTERM or `--duration`. Zenoh callbacks never wait on the disk: samples cross a bounded
//! queue to a writer thread, and a full queue drops (and counts) them.

use anyhow::{Context, Result};
use clap::Args;
use runtime::recording::{RecordingWriter, SchemaOf};
use runtime::session::{DEFAULT_CLIENT_CONNECT, Role, SessionConfig, now_ns};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::io::{BufWriter, Seek, Write};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, mpsc};
use std::time::{Duration, Instant};

/// Samples waiting for the writer; one more is dropped. At the edge's default 10 Hz odometry
/// and a node per second, 4,096 samples are minutes of a fleet of ten.
const QUEUE: usize = 4096;
/// How often progress goes to stderr.
const PROGRESS_EVERY: Duration = Duration::from_secs(5);

/// Record a fleet's levelmap traffic (nodes, odometry, acks, corrected poses) into an MCAP
/// file with the protobuf schemas embedded: Foxglove opens it, `levelmap mapper
/// --from-recording` replays it.
#[derive(Args, Debug)]
pub struct RecordArgs {
    /// The fleet: everything under levelmap/{fleet}/** is recorded.
    #[arg(long)]
    pub fleet: String,
    /// A mapper.toml or edge.toml: its `[zenoh]` table (endpoints, TLS, config_file); every
    /// other key is ignored. The recorder is always a client: it connects to `connect`, else
    /// to the router's `listen` endpoints (a mapper's file, on its host).
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Connect to this endpoint instead (e.g. tcp/127.0.0.1:7447).
    #[arg(long, value_name = "ENDPOINT")]
    pub connect: Option<String>,
    /// The MCAP file to write.
    #[arg(long, value_name = "FILE.mcap")]
    pub out: PathBuf,
    /// Stop after this many seconds (else on Ctrl-C or SIGTERM).
    #[arg(long, value_name = "S")]
    pub duration: Option<f64>,
    /// Also write the traffic in Foxglove's well-known schemas, on topics of their own:
    /// each node's scan (LaserScan), cloud (PointCloud) and fixes (LocationFix), the live
    /// scans, and the robots' frames on /tf (odometry, and each solve's map → odometry).
    #[arg(long)]
    pub foxglove: bool,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
}

/// What a recording holds.
#[derive(Clone, Debug, Default, Serialize)]
pub struct RecordReport {
    /// The file written.
    pub out: PathBuf,
    /// Messages written.
    pub messages: u64,
    /// Messages written per key.
    pub topics: BTreeMap<String, u64>,
    /// Samples lost to a full queue (the disk was behind).
    pub dropped: u64,
    /// Samples on keys that carry no levelmap message: not written.
    pub skipped: u64,
    /// Messages written in Foxglove's schemas (`--foxglove`).
    pub foxglove_messages: u64,
    /// Messages recorded that made no Foxglove message as they did not decode or check
    /// (`--foxglove`; the message itself is recorded as it came).
    pub foxglove_unreadable: u64,
    /// Payload bytes written.
    pub payload_bytes: u64,
    /// The file's size (bytes).
    pub file_bytes: u64,
    /// How long it recorded (s).
    pub duration_s: f64,
}

/// The `[zenoh]` table of a service's config; the rest of the file is not the recorder's.
#[derive(Default, Deserialize)]
struct ServiceFile {
    #[serde(default)]
    zenoh: SessionConfig,
}

/// The recorder's session from a service's: a client (it listens on nothing, so it can run
/// beside the mapper) of `connect`, else of the file's connect endpoints, else of the
/// router's listen endpoints (any-address as loopback), else of a mapper on this machine.
/// TLS files and `config_file` are kept.
pub fn recorder_session(service: SessionConfig, connect: Option<String>) -> SessionConfig {
    let from_listen = || {
        let listen = service.listen.clone().unwrap_or_default();
        let local = listen.iter().map(|e| {
            e.replace("/0.0.0.0:", "/127.0.0.1:")
                .replace("/[::]:", "/[::1]:")
        });
        Some(local.collect::<Vec<_>>()).filter(|l| !l.is_empty())
    };
    let connect = match connect {
        Some(endpoint) => vec![endpoint],
        None => service
            .connect
            .clone()
            .filter(|c| !c.is_empty())
            .or_else(from_listen)
            .unwrap_or_else(|| vec![DEFAULT_CLIENT_CONNECT.to_owned()]),
    };
    SessionConfig {
        mode: Some("client".into()),
        listen: Some(Vec::new()),
        connect: Some(connect),
        ..service
    }
}

/// A recording being written, and its tally (no clock, no network).
pub struct Recorder<W: Write + Seek> {
    writer: RecordingWriter<W>,
    report: RecordReport,
    /// The traffic in Foxglove's schemas too (`--foxglove`).
    foxglove: Option<foxglove_schemas::traffic::Traffic>,
}

impl<W: Write + Seek> Recorder<W> {
    /// An empty recording over `out`; with `foxglove`, the traffic in Foxglove's schemas too.
    pub fn new(out: W, foxglove: bool) -> Result<Self> {
        Ok(Recorder {
            writer: RecordingWriter::new(out)?,
            report: RecordReport::default(),
            foxglove: foxglove.then(Default::default),
        })
    }

    /// Writes one sample received at `log_time_ns`, or counts it skipped.
    pub fn record(&mut self, key: &str, payload: &[u8], log_time_ns: u64) -> Result<()> {
        if !self.writer.write(key, payload, log_time_ns)? {
            self.report.skipped += 1;
            return Ok(());
        }
        self.report.messages += 1;
        *self.report.topics.entry(key.to_owned()).or_default() += 1;
        self.report.payload_bytes += payload.len() as u64;
        let Some(traffic) = &mut self.foxglove else {
            return Ok(());
        };
        let Ok(made) = traffic.translate(key, payload, log_time_ns) else {
            self.report.foxglove_unreadable += 1;
            return Ok(());
        };
        for m in made {
            let schema = SchemaOf {
                name: &m.schema_name,
                encoding: &m.schema_encoding,
                data: &m.schema_data,
            };
            let at = m.stamp_ns;
            self.writer
                .write_other(&m.topic, &schema, &m.data, log_time_ns, at)?;
            self.report.foxglove_messages += 1;
            *self.report.topics.entry(m.topic).or_default() += 1;
            self.report.payload_bytes += m.data.len() as u64;
        }
        Ok(())
    }

    /// The tally so far.
    pub fn report(&self) -> &RecordReport {
        &self.report
    }

    /// Ends the file (summary, chunk indexes, footer).
    pub fn finish(self) -> Result<(W, RecordReport)> {
        Ok((self.writer.finish()?, self.report))
    }
}

/// A sample as the Zenoh callback hands it over: key, payload, receive time.
type Sample = (String, Vec<u8>, u64);

pub fn run(args: &RecordArgs) -> Result<()> {
    wire::validate_id("fleet", &args.fleet)?;
    if let Some(s) = args.duration {
        anyhow::ensure!(
            s.is_finite() && s >= 0.0,
            "--duration {s}: seconds, 0 or more"
        );
    }
    let service: ServiceFile = match &args.config {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("{}: cannot read", path.display()))?;
            toml::from_str(&text).with_context(|| format!("{}", path.display()))?
        }
        None => ServiceFile::default(),
    };
    let session = recorder_session(service.zenoh, args.connect.clone());
    session.to_zenoh(Role::Client)?;
    let file = std::fs::File::create(&args.out)
        .with_context(|| format!("{}: cannot create", args.out.display()))?;
    let recorder = Recorder::new(BufWriter::new(file), args.foxglove)?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()?;
    let mut report = runtime.block_on(record(args, &session, recorder))?;
    report.out = args.out.clone();
    report.file_bytes = std::fs::metadata(&args.out)?.len();
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        let foxglove = match args.foxglove {
            true => format!(
                " (and {} in Foxglove's schemas, {} unreadable)",
                report.foxglove_messages, report.foxglove_unreadable
            ),
            false => String::new(),
        };
        println!(
            "{}: {} messages{foxglove} on {} topics, {} dropped, {} skipped, {} bytes in {:.1} s",
            report.out.display(),
            report.messages,
            report.topics.len(),
            report.dropped,
            report.skipped,
            report.file_bytes,
            report.duration_s
        );
    }
    Ok(())
}

/// Subscribes, records until a stop signal, `--duration` or a write error, then finishes the
/// file with everything queued.
async fn record(
    args: &RecordArgs,
    session: &SessionConfig,
    mut recorder: Recorder<BufWriter<std::fs::File>>,
) -> Result<RecordReport> {
    let started = Instant::now();
    let session = session.open(Role::Client).await?;
    let (queue, samples) = mpsc::sync_channel::<Sample>(QUEUE);
    let dropped = Arc::new(AtomicU64::new(0));
    let stop = Arc::new(AtomicBool::new(false));
    let key_expr = format!("{}/{}/**", wire::KEY_ROOT, args.fleet);
    let lost = dropped.clone();
    let subscriber = session
        .declare_subscriber(&key_expr)
        .callback(move |sample| {
            let key = sample.key_expr().as_str().to_owned();
            let payload = sample.payload().to_bytes().into_owned();
            if queue.try_send((key, payload, now_ns())).is_err() {
                lost.fetch_add(1, Ordering::Relaxed);
            }
        })
        .await
        .map_err(anyhow::Error::from_boxed)?;
    eprintln!("recording {key_expr} into {}", args.out.display());

    let (lost, stopping) = (dropped.clone(), stop.clone());
    let writer = tokio::task::spawn_blocking(move || -> Result<RecordReport> {
        let mut last_progress = Instant::now();
        loop {
            match samples.recv_timeout(Duration::from_millis(200)) {
                Ok((key, payload, at)) => recorder.record(&key, &payload, at)?,
                Err(mpsc::RecvTimeoutError::Timeout) if stopping.load(Ordering::SeqCst) => break,
                Err(mpsc::RecvTimeoutError::Timeout) => {}
                Err(mpsc::RecvTimeoutError::Disconnected) => break,
            }
            if last_progress.elapsed() >= PROGRESS_EVERY {
                last_progress = Instant::now();
                let r = recorder.report();
                let dropped = lost.load(Ordering::Relaxed);
                let (messages, bytes) = (r.messages, r.payload_bytes);
                eprintln!("recorded {messages} messages ({bytes} bytes), {dropped} dropped");
            }
        }
        let (mut out, report) = recorder.finish()?;
        out.flush()?;
        Ok(report)
    });
    tokio::pin!(writer);

    let until = async {
        match args.duration {
            Some(s) => tokio::time::sleep(Duration::from_secs_f64(s)).await,
            None => std::future::pending().await,
        }
    };
    let early = tokio::select! {
        _ = runtime::session::shutdown_signal() => None,
        _ = until => None,
        ended = &mut writer => Some(ended),
    };
    subscriber
        .undeclare()
        .await
        .map_err(anyhow::Error::from_boxed)?;
    // The writer takes what is queued, then finishes the file.
    stop.store(true, Ordering::SeqCst);
    let ended = match early {
        Some(ended) => ended,
        None => writer.await,
    };
    session.close().await.map_err(anyhow::Error::from_boxed)?;
    let mut report = ended?.with_context(|| format!("{}: recording", args.out.display()))?;
    report.dropped = dropped.load(Ordering::Relaxed);
    report.duration_s = started.elapsed().as_secs_f64();
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_recorder_is_a_client_of_the_services_router() {
        let mapper = SessionConfig::router("tcp/0.0.0.0:7447");
        let session = recorder_session(mapper.clone(), None);
        assert_eq!(session.mode.as_deref(), Some("client"));
        assert_eq!(session.listen, Some(vec![]));
        assert_eq!(session.connect, Some(vec!["tcp/127.0.0.1:7447".into()]));
        let edge = SessionConfig::client("tls/mapper.local:7447");
        let session = recorder_session(edge, None);
        assert_eq!(session.connect, Some(vec!["tls/mapper.local:7447".into()]));
        let session = recorder_session(mapper, Some("tcp/10.0.0.2:7447".into()));
        assert_eq!(session.connect, Some(vec!["tcp/10.0.0.2:7447".into()]));
        let session = recorder_session(SessionConfig::default(), None);
        assert_eq!(session.connect, Some(vec![DEFAULT_CLIENT_CONNECT.into()]));
    }

    #[test]
    fn the_tally_counts_per_key_and_skips_foreign_keys() {
        let mut recorder = Recorder::new(std::io::Cursor::new(Vec::new()), false).unwrap();
        recorder
            .record("levelmap/park/robots/r1/odom", b"", 1)
            .unwrap();
        recorder
            .record("levelmap/park/robots/r1/odom", b"ab", 2)
            .unwrap();
        recorder.record("levelmap/park/map/poses", b"c", 3).unwrap();
        recorder.record("levelmap/park/map/grid", b"d", 4).unwrap();
        let (out, report) = recorder.finish().unwrap();
        assert_eq!((report.messages, report.skipped), (3, 1));
        assert_eq!(report.topics["levelmap/park/robots/r1/odom"], 2);
        assert_eq!(report.payload_bytes, 3);
        let read = runtime::recording::RecordingReader::new(
            std::io::Cursor::new(out.into_inner()),
            std::path::Path::new("t.mcap"),
        );
        assert_eq!(read.count(), 3);
    }
}

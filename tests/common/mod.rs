//! Shared by the end-to-end tests: free ports, an HTTP client (the tests look at the
//! system only through its HTTP API), service processes with their config files, a TCP relay
//! that can cut a robot's link.

#![allow(dead_code)]

mod edge_process;
mod mapper_process;
pub mod netns;
pub mod openapi;
pub mod sse;

use edge::{NodeBuilder, SimSource, SimSourceConfig, Source, SourceEvent};
use serde_json::Value;
use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};
// Each test binary uses its own part of these, as of the rest (`dead_code` above).
#[allow(unused_imports)]
pub use edge_process::*;
#[allow(unused_imports)]
pub use mapper_process::*;
pub use testdata::KillOnDrop;

/// Sends SIGTERM to `child` (a graceful stop).
pub fn sigterm(child: &Child) {
    let sent = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .expect("kill runs");
    assert!(sent.success(), "SIGTERM not sent");
}

/// Runs `command` (a `levelmap … --json`), which must succeed; its report, printed.
pub fn json_report(command: &mut Command) -> Value {
    let out = command.output().expect("levelmap runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report: Value = serde_json::from_slice(&out.stdout).expect("JSON");
    eprintln!("{report:#}");
    report
}

/// Every robot's nodes the map had (`before`, robot by robot) are still its first after a
/// restart.
pub fn assert_restored(http: &str, before: &[Vec<u64>]) {
    for (r, seen) in before.iter().enumerate() {
        let restored = node_seqs(http, "park", &format!("robot{r}"));
        assert!(
            restored.len() >= seen.len() && restored[..seen.len()] == seen[..],
            "robot{r}: before the kill {seen:?}, after the restart {restored:?}"
        );
    }
}

/// A loopback port nobody listens on, outside the range outgoing connections take theirs from.
pub fn free_port() -> u16 {
    sitelog::local::free_local_port().expect("a free port")
}

/// A fresh folder under the target's temp dir.
pub fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("levelmap-e2e-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir
}

/// The tests' HTTP client: every status is an answer (a 404 is checked, not an error).
pub fn agent() -> ureq::Agent {
    ureq::Agent::config_builder()
        .http_status_as_error(false)
        .timeout_global(Some(Duration::from_secs(10)))
        .build()
        .into()
}

/// GET `path` from `addr`: (status, body); `None` when nothing answers.
pub fn http_get(addr: &str, path: &str) -> Option<(u16, String)> {
    http_get_with(addr, path, None).map(|a| (a.status, a.body))
}

/// An HTTP answer: status, headers and the body as text (a PNG's bytes too, lossily: the
/// tests look at its signature only).
pub struct Answer {
    pub status: u16,
    pub headers: ureq::http::HeaderMap,
    pub body: String,
}

impl Answer {
    /// A header's value as text.
    pub fn header(&self, name: &str) -> Option<&str> {
        self.headers.get(name).and_then(|v| v.to_str().ok())
    }
}

/// `method path` with these headers; `None` when nothing answers.
pub fn http_call(addr: &str, method: &str, path: &str, headers: &[(&str, &str)]) -> Option<Answer> {
    let mut request = ureq::http::Request::builder()
        .method(method)
        .uri(format!("http://{addr}{path}"));
    for (k, v) in headers {
        request = request.header(*k, *v);
    }
    let mut response = agent().run(request.body(()).ok()?).ok()?;
    let body = response
        .body_mut()
        .with_config()
        .limit(u64::MAX)
        .read_to_vec()
        .ok()?;
    Some(Answer {
        status: response.status().as_u16(),
        headers: response.headers().clone(),
        body: String::from_utf8_lossy(&body).into_owned(),
    })
}

/// `method path` with a bearer token and a body: (status, body bytes, Location).
pub fn call(
    http: &str,
    method: &str,
    path: &str,
    token: &str,
    body: &[u8],
) -> (u16, Vec<u8>, String) {
    let request = ureq::http::Request::builder()
        .method(method)
        .uri(format!("http://{http}{path}"))
        .header("Authorization", format!("Bearer {token}"))
        .body(body.to_vec())
        .expect("a request");
    let mut response = agent().run(request).expect("an answer");
    let location = response
        .headers()
        .get("location")
        .map(|v| v.to_str().unwrap().to_owned())
        .unwrap_or_default();
    let body = response
        .body_mut()
        .with_config()
        .limit(u64::MAX)
        .read_to_vec()
        .expect("a body");
    (response.status().as_u16(), body, location)
}

/// GET `path` with a bearer token (none: without one).
pub fn http_get_with(addr: &str, path: &str, token: Option<&str>) -> Option<Answer> {
    let auth = token.map(|t| format!("Bearer {t}"));
    let headers: Vec<(&str, &str)> = auth.iter().map(|a| ("Authorization", a.as_str())).collect();
    http_call(addr, "GET", path, &headers)
}

/// GET a JSON document, 200 expected.
pub fn get_json(addr: &str, path: &str) -> Option<Value> {
    get_json_with(addr, path, None)
}

/// GET a JSON document with a bearer token, 200 expected.
pub fn get_json_with(addr: &str, path: &str, token: Option<&str>) -> Option<Value> {
    match http_get_with(addr, path, token)? {
        Answer {
            status: 200, body, ..
        } => serde_json::from_str(&body).ok(),
        _ => None,
    }
}

/// Polls `f` until it gives `Some` or `timeout` passes.
pub fn wait_for<T>(timeout: Duration, mut f: impl FnMut() -> Option<T>) -> Option<T> {
    let deadline = Instant::now() + timeout;
    loop {
        if let Some(v) = f() {
            return Some(v);
        }
        if Instant::now() > deadline {
            return None;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// The value of a Prometheus sample line `name{labels} value` (labels as written).
pub fn metric(text: &str, series: &str) -> u64 {
    text.lines()
        .find_map(|l| l.strip_prefix(series)?.trim().parse().ok())
        .unwrap_or(0)
}

/// Node sequence numbers of `robot` in the fleet's graph, in map order.
pub fn node_seqs(http: &str, fleet: &str, robot: &str) -> Vec<u64> {
    node_seqs_with(http, fleet, robot, None)
}

/// [`node_seqs`] with a bearer token.
pub fn node_seqs_with(http: &str, fleet: &str, robot: &str, token: Option<&str>) -> Vec<u64> {
    get_json_with(http, &format!("/api/v1/fleets/{fleet}/graph"), token)
        .map(|g| {
            g["nodes"]
                .as_array()
                .expect("nodes")
                .iter()
                .filter(|n| n["robot"] == robot)
                .map(|n| n["node_seq"].as_u64().expect("node_seq"))
                .collect()
        })
        .unwrap_or_default()
}

/// A cluster mapper host's config: site `park` among `hosts`, the write token `token`, its
/// Zenoh router listening on `zenoh` and connecting to `connect`, the NATS servers at
/// `servers`, the lease 3 s; a snapshot every 5 nodes, so that the drills' takeovers restore
/// from shared snapshots.
pub fn cluster_host_config(
    dir: &Path,
    (host, hosts): (&str, &[&str]),
    token: &str,
    (zenoh, connect): (&str, &[String]),
    servers: &[String],
) -> String {
    format!(
        "store_path = {store:?}\nfleets = [\"park\"]\ntoken = {token:?}\n\
         [store]\nsnapshot_every_nodes = 5\n\n\
         [mapping.coverage]\nenabled = false\n\n\
         [zenoh]\nmode = \"router\"\nlisten = [{zenoh:?}]\nconnect = {connect:?}\n\n\
         [cluster]\nhost = {host:?}\nhosts = {hosts:?}\nlease_ttl_ms = 3000\n\n\
         [cluster.nats]\nservers = {servers:?}\n",
        store = dir.join("mapper.redb"),
    )
}

/// `levelmap backup --json OUT` of the mapper at `http`, with `token` if given.
pub fn backup(http: &str, out: &Path, token: Option<&str>) -> std::process::Output {
    let mut command = levelmap();
    command
        .args(["backup", "--json", "--mapper", http])
        .arg(out);
    if let Some(token) = token {
        command.args(["--token", token]);
    }
    command.output().expect("levelmap backup runs")
}

/// A backup that succeeded: its JSON report and the nodes of `park` in it.
pub fn backed_up(taken: &std::process::Output) -> (Value, u64) {
    assert!(
        taken.status.success(),
        "{}",
        String::from_utf8_lossy(&taken.stderr)
    );
    let report: Value = serde_json::from_slice(&taken.stdout).expect("JSON");
    assert_eq!(report["fleets"][0][0], "park", "{report}");
    let nodes = report["fleets"][0][1].as_u64().expect("park's nodes");
    (report, nodes)
}

pub fn levelmap() -> Command {
    Command::new(env!("CARGO_BIN_EXE_levelmap"))
}

/// A TCP relay in front of the mapper's Zenoh endpoint: `cut` drops every connection and
/// refuses new ones until `restore`, like a radio link going down.
pub struct Relay {
    pub endpoint: String,
    up: Arc<AtomicBool>,
}

impl Relay {
    pub fn start(target: &str) -> Relay {
        Relay::start_to(&[target])
    }

    /// A relay whose n-th connection goes to `targets[n]`, and every one after the last to the
    /// last.
    pub fn start_to(targets: &[&str]) -> Relay {
        let targets: Vec<String> = targets
            .iter()
            .map(|t| t.trim_start_matches("tcp/").to_owned())
            .collect();
        let listener = TcpListener::bind("127.0.0.1:0").expect("relay port");
        let endpoint = format!("tcp/{}", listener.local_addr().expect("addr"));
        let up = Arc::new(AtomicBool::new(true));
        let flag = up.clone();
        std::thread::spawn(move || {
            let mut relayed = 0;
            for client in listener.incoming() {
                let Ok(client) = client else { continue };
                if !flag.load(Ordering::SeqCst) {
                    continue; // dropped: refused
                }
                let target = &targets[relayed.min(targets.len() - 1)];
                relayed += 1;
                let Ok(server) = TcpStream::connect(target) else {
                    continue;
                };
                for (from, to) in [
                    (client.try_clone(), server.try_clone()),
                    (server.try_clone(), client.try_clone()),
                ] {
                    let (Ok(mut from), Ok(mut to)) = (from, to) else {
                        continue;
                    };
                    let flag = flag.clone();
                    std::thread::spawn(move || {
                        let _ = from.set_read_timeout(Some(Duration::from_millis(100)));
                        let mut buf = [0u8; 16384];
                        loop {
                            if !flag.load(Ordering::SeqCst) {
                                break;
                            }
                            match from.read(&mut buf) {
                                Ok(0) => break,
                                Ok(n) => {
                                    if to.write_all(&buf[..n]).is_err() {
                                        break;
                                    }
                                }
                                Err(e)
                                    if matches!(
                                        e.kind(),
                                        std::io::ErrorKind::WouldBlock
                                            | std::io::ErrorKind::TimedOut
                                    ) => {}
                                Err(_) => break,
                            }
                        }
                        let _ = from.shutdown(std::net::Shutdown::Both);
                        let _ = to.shutdown(std::net::Shutdown::Both);
                    });
                }
            }
        });
        Relay { endpoint, up }
    }

    pub fn cut(&self) {
        self.up.store(false, Ordering::SeqCst);
    }

    pub fn restore(&self) {
        self.up.store(true, Ordering::SeqCst);
    }
}

/// The first `n` nodes of a simulated robot, with their clouds (the edge's default), as
/// messages a test can edit (or forge).
pub fn real_nodes(n: usize) -> Vec<wire::v1::Node> {
    let mut source = SimSource::new(&SimSourceConfig::default(), 1_700_000_000_000_000_000, 10.0)
        .expect("loop 0");
    let mut builder = NodeBuilder::new("park", "robot0", Default::default(), Default::default(), 0)
        .with_cloud(&Default::default());
    let mut nodes = Vec::new();
    while nodes.len() < n {
        match source.next_event().expect("enough scans") {
            SourceEvent::Scan(scan) => nodes.extend(builder.offer(&scan).expect("levels")),
            SourceEvent::Odometry(_) => {}
        }
    }
    nodes
        .iter()
        .map(|node| wire::Message::decode(&node.encode()[..]).expect("a node decodes"))
        .collect()
}

/// A mapper in this process on free ports, with a Zenoh client session to it.
pub async fn in_process_mapper(
    dir: &Path,
    token: &str,
) -> (mapper::Running, zenoh::Session, String) {
    let config = mapper::MapperConfig {
        token: token.into(),
        ..Default::default()
    };
    in_process_mapper_with(dir, config).await
}

/// [`in_process_mapper`] with the rest of `config` (its ports and store are chosen here).
pub async fn in_process_mapper_with(
    dir: &Path,
    config: mapper::MapperConfig,
) -> (mapper::Running, zenoh::Session, String) {
    let zenoh = format!("tcp/127.0.0.1:{}", free_port());
    let mapper = mapper::start(mapper::MapperConfig {
        zenoh: runtime::session::SessionConfig::router(&zenoh),
        http_listen: "127.0.0.1:0".into(),
        store_path: dir.join("mapper.redb"),
        ..config
    })
    .await
    .expect("mapper starts");
    let session = runtime::session::SessionConfig::client(&zenoh)
        .open(runtime::session::Role::Client)
        .await
        .expect("client session");
    let http = mapper.http_addr.to_string();
    (mapper, session, http)
}

/// Puts `nodes` of robot0 in fleet park, again and again as the edge does, until all are in
/// the map (read with `token`).
pub async fn put_until_mapped(
    session: &zenoh::Session,
    http: &str,
    token: Option<&str>,
    nodes: &[wire::v1::Node],
) {
    use wire::Message;
    let key = wire::node_key("park", "robot0").unwrap();
    loop {
        for n in nodes {
            session.put(key.clone(), n.encode_to_vec()).await.unwrap();
        }
        tokio::time::sleep(Duration::from_millis(300)).await;
        let (h, t) = (http.to_owned(), token.map(str::to_owned));
        let seqs =
            tokio::task::spawn_blocking(move || node_seqs_with(&h, "park", "robot0", t.as_deref()))
                .await
                .unwrap();
        if seqs.len() == nodes.len() {
            return;
        }
    }
}

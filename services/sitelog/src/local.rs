//! Three real nats-servers on this machine, one JetStream cluster, each fsyncing every
//! write, optionally secured as `deploy/cluster/make-nats-certs.sh` makes them: on loopback,
//! or each at an address in a network namespace of its own ([`Placement`], the drills' hosts),
//! their clients on every interface (a mapper host in a network namespace reaches them). Processes only, no client: the cluster tests, the
//! drills (`tests/e2e_cluster.rs`) and `levelmap bench-cluster` start them through this.

use std::io;
use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};

/// The servers' names, in the order of their ports.
const NAMES: [&str; 3] = ["n1", "n2", "n3"];

/// Each local server's JetStream file storage, named rather than left to nats-server, whose
/// default is taken from the disk's free space when it starts (973 MB in a CI run on a
/// nearly full disk): the clouds' stream reserves `[clouds] max_bytes` (2 GiB) on every server,
/// and a test that writes megabytes must not depend on what else the disk holds.
const LOCAL_FILE_STORE: &str = "8G";

/// Where a server runs: the address its routes and monitoring listen on, and the network
/// namespace it runs in (through `ip netns exec`, which needs root), if not this process's.
#[derive(Clone, Debug)]
pub struct Placement {
    /// An address of this machine, or of the namespace.
    pub address: String,
    /// The namespace's name (`ip netns`).
    pub netns: Option<String>,
}

impl Placement {
    fn loopback() -> Placement {
        Placement {
            address: "127.0.0.1".into(),
            netns: None,
        }
    }
}

/// Three nats-servers running; killed when dropped.
pub struct LocalCluster {
    addresses: Vec<String>,
    client_ports: Vec<u16>,
    monitor_ports: Vec<u16>,
    servers: Vec<Option<Child>>,
    names: Vec<String>,
    /// How each server was started, to start it again.
    launches: Vec<Launch>,
}

/// How one server is started: its binary, config and log, and its namespace.
struct Launch {
    binary: PathBuf,
    config: PathBuf,
    log: PathBuf,
    netns: Option<String>,
}

impl Launch {
    /// Starts the server, its log appended to.
    fn spawn(&self) -> io::Result<Child> {
        let log = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&self.log)?;
        let mut command = match &self.netns {
            None => Command::new(&self.binary),
            Some(ns) => {
                let mut inside = Command::new("ip");
                inside.args(["netns", "exec", ns]).arg(&self.binary);
                inside
            }
        };
        command
            .arg("-c")
            .arg(&self.config)
            .stdout(Stdio::null())
            .stderr(log)
            .spawn()
    }
}

impl LocalCluster {
    /// Starts `binary` three times, their configs, stores and logs in `dir` (made if
    /// missing); with TLS and per-client certificates from `secured` when given (the
    /// folder `make-nats-certs.sh` fills). Returns once the processes are spawned: clients
    /// retry until the cluster answers.
    pub fn start(binary: &Path, dir: &Path, secured: Option<&Path>) -> io::Result<LocalCluster> {
        let loopback = [(); 3].map(|_| Placement::loopback());
        Self::start_placed(binary, dir, secured, &loopback)
    }

    /// [`LocalCluster::start`] with each server where `places` puts it.
    pub fn start_placed(
        binary: &Path,
        dir: &Path,
        secured: Option<&Path>,
        places: &[Placement; 3],
    ) -> io::Result<LocalCluster> {
        if !binary.is_file() {
            return Err(io::Error::new(
                io::ErrorKind::NotFound,
                format!("{}: no nats-server binary there", binary.display()),
            ));
        }
        std::fs::create_dir_all(dir)?;
        let free_ports = || {
            (0..3)
                .map(|_| free_local_port())
                .collect::<io::Result<Vec<u16>>>()
        };
        let (client_ports, route_ports, monitor_ports) =
            (free_ports()?, free_ports()?, free_ports()?);
        let routes: Vec<String> = route_ports
            .iter()
            .zip(places)
            .map(|(p, place)| format!("nats-route://{}:{p}", place.address))
            .collect();
        if let Some(certs) = secured {
            // nats-server reads an include relative to the config's folder.
            std::fs::copy(certs.join("auth.conf"), dir.join("auth.conf"))?;
        }
        let mut cluster = LocalCluster {
            addresses: places.iter().map(|p| p.address.clone()).collect(),
            client_ports,
            monitor_ports,
            servers: Vec::new(),
            names: NAMES.iter().map(|n| n.to_string()).collect(),
            launches: Vec::new(),
        };
        for (i, name) in NAMES.iter().enumerate() {
            let config = dir.join(format!("{name}.conf"));
            std::fs::write(
                &config,
                format!(
                    "server_name: {name}\nlisten: 0.0.0.0:{client}\nhttp: {address}:{monitor}\n\
                     jetstream {{ store_dir: \"{store}\", max_file_store: {LOCAL_FILE_STORE}, \
                     sync_interval: always }}\n\
                     cluster {{ name: levelmap, listen: {address}:{route}, routes: [{routes}]{route_tls} }}\n\
                     {client_tls}",
                    address = places[i].address,
                    client = cluster.client_ports[i],
                    monitor = cluster.monitor_ports[i],
                    store = dir.join(name).display(),
                    route = route_ports[i],
                    routes = routes.join(", "),
                    route_tls = secured.map_or(String::new(), |d| format!(
                        ", {}",
                        tls(d, name, "verify: true")
                    )),
                    client_tls = secured.map_or(String::new(), |d| format!(
                        "{}\ninclude \"auth.conf\"\n",
                        tls(d, name, "verify_and_map: true")
                    )),
                ),
            )?;
            let launch = Launch {
                binary: binary.to_owned(),
                config,
                log: dir.join(format!("{name}.log")),
                netns: places[i].netns.clone(),
            };
            let child = launch.spawn()?;
            cluster.launches.push(launch);
            cluster.servers.push(Some(child));
        }
        Ok(cluster)
    }

    /// The client port of every server.
    pub fn ports(&self) -> &[u16] {
        &self.client_ports
    }

    /// `nats://address:port` of every server.
    pub fn client_urls(&self) -> Vec<String> {
        self.at(&self.client_ports)
            .into_iter()
            .map(|a| format!("nats://{a}"))
            .collect()
    }

    /// The address of every server.
    pub fn addresses(&self) -> &[String] {
        &self.addresses
    }

    /// `address:port` of every server's monitoring (HTTP: `/jsz`, `/varz`).
    pub fn monitors(&self) -> Vec<String> {
        self.at(&self.monitor_ports)
    }

    /// `address:port` of every server, with its port of `ports`.
    fn at(&self, ports: &[u16]) -> Vec<String> {
        self.addresses
            .iter()
            .zip(ports)
            .map(|(a, p)| format!("{a}:{p}"))
            .collect()
    }

    /// The names of the servers, in the order of their ports.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// SIGKILLs the server named `name` and reaps it.
    pub fn kill(&mut self, name: &str) -> io::Result<()> {
        let i = self.index(name)?;
        let child = self.servers[i]
            .as_mut()
            .ok_or_else(|| io::Error::other(format!("no server {name} runs")))?;
        child.kill()?;
        child.wait()?;
        self.servers[i] = None;
        Ok(())
    }

    /// Starts the server named `name` again (killed first if it runs), on its config and
    /// store: it catches up from the others.
    pub fn restart(&mut self, name: &str) -> io::Result<()> {
        if self.servers[self.index(name)?].is_some() {
            self.kill(name)?;
        }
        let i = self.index(name)?;
        self.servers[i] = Some(self.launches[i].spawn()?);
        Ok(())
    }

    fn index(&self, name: &str) -> io::Result<usize> {
        self.names
            .iter()
            .position(|n| n == name)
            .ok_or_else(|| io::Error::other(format!("no server named {name}")))
    }
}

impl LocalCluster {
    /// The last `lines` lines of each server's log, headed by its path.
    pub fn log_tails(&self, lines: usize) -> String {
        let mut out = String::new();
        for launch in &self.launches {
            let text = std::fs::read_to_string(&launch.log).unwrap_or_default();
            let all: Vec<&str> = text.lines().collect();
            let tail = &all[all.len().saturating_sub(lines)..];
            out += &format!("--- {} (last {} lines)\n", launch.log.display(), tail.len());
            for line in tail {
                out += line;
                out.push('\n');
            }
        }
        out
    }
}

impl Drop for LocalCluster {
    fn drop(&mut self) {
        for child in self.servers.iter_mut().flatten() {
            let _ = child.kill();
            let _ = child.wait();
        }
        // A test failed with the servers running: what they said last, where it fails.
        if std::thread::panicking() {
            eprintln!("{}", self.log_tails(20));
        }
    }
}

/// A loopback port nothing listens on, for a process started next to listen on. Taken below
/// the kernel's ephemeral range: a port from `bind(0)` lies in that range, and any outgoing
/// connection made before the process binds it may be given the same port (a drill failed
/// so, "Address already in use"). Distinct on every call within a process.
pub fn free_local_port() -> io::Result<u16> {
    static NEXT: AtomicU32 = AtomicU32::new(0);
    let ephemeral_low = std::fs::read_to_string("/proc/sys/net/ipv4/ip_local_port_range")
        .ok()
        .and_then(|range| range.split_whitespace().next()?.parse::<u32>().ok())
        .unwrap_or(32768)
        .min(u32::from(u16::MAX));
    let low = (ephemeral_low / 2).max(1024);
    if ephemeral_low <= low {
        // No room below the range: the kernel's choice, racy as it is.
        return Ok(TcpListener::bind("127.0.0.1:0")?.local_addr()?.port());
    }
    let span = ephemeral_low - low;
    // Processes start apart (by pid) so that two test binaries rarely probe the same ports.
    let start = std::process::id().wrapping_mul(7919);
    for _ in 0..span {
        let port = low + start.wrapping_add(NEXT.fetch_add(1, Ordering::Relaxed)) % span;
        let port = u16::try_from(port).expect("below the ephemeral range");
        if TcpListener::bind(("127.0.0.1", port)).is_ok() {
            return Ok(port);
        }
    }
    Err(io::Error::new(
        io::ErrorKind::AddrInUse,
        format!("every port in {low}..{ephemeral_low} is in use"),
    ))
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

/// The nats-server binary named by `NATS_SERVER_BIN`, if set.
pub fn nats_server_from_env() -> Option<PathBuf> {
    std::env::var_os("NATS_SERVER_BIN").map(PathBuf::from)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn free_local_ports_are_distinct_bindable_and_below_the_ephemeral_range() {
        let ephemeral_low: u16 = std::fs::read_to_string("/proc/sys/net/ipv4/ip_local_port_range")
            .expect("Linux names its ephemeral range")
            .split_whitespace()
            .next()
            .and_then(|low| low.parse().ok())
            .expect("a number");
        let ports: Vec<u16> = (0..50)
            .map(|_| free_local_port().expect("a port"))
            .collect();
        let mut distinct = ports.clone();
        distinct.sort_unstable();
        distinct.dedup();
        assert_eq!(distinct.len(), ports.len(), "a port given twice: {ports:?}");
        for port in ports {
            assert!(port < ephemeral_low, "{port} is in the ephemeral range");
            TcpListener::bind(("127.0.0.1", port)).expect("the port is free");
        }
    }
}

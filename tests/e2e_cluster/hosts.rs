//! The drills' machines (`tests/e2e_cluster.rs`): five mapper hosts on a LAN of network
//! namespaces with the NATS servers beside three of them, the robots, a gateway; and how a
//! drill looks at them (the host serving the site, its map's growth, every node once).

use crate::common::netns::{Lan, Member, Namespace};
use crate::common::*;
use crate::nats;
use sitelog::local::Placement;
use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::time::{Duration, Instant};

pub(crate) const ROBOTS: usize = 2;
/// The hosts' write token.
pub(crate) const TOKEN: &str = "s3cret";
/// The mapper hosts, each in a namespace of its own.
pub(crate) const HOSTS: [&str; 5] = ["h1", "h2", "h3", "h4", "h5"];

/// A mapper host's config: site `park`, hosts h1–h5 ([`cluster_host_config`]).
pub(crate) fn host_config(
    dir: &Path,
    host: &str,
    router: (&str, &[String]),
    servers: &[String],
) -> String {
    cluster_host_config(dir, (host, &HOSTS), TOKEN, router, servers)
}

pub(crate) fn summary_nodes(http: &str) -> Option<u64> {
    get_json(http, "/api/v1/fleets/park/summary")?["nodes"].as_u64()
}

/// The hosts h1–h5 on their LAN with the NATS servers, the robots' folder. The owner (first
/// in the site's order) and the standby (second) are indices into `hosts`.
pub(crate) struct Hosts {
    pub(crate) servers: nats::Cluster,
    /// `None` while killed or restarted.
    pub(crate) hosts: Vec<Option<MapperProcess>>,
    /// Each host's Zenoh endpoint and HTTP address, also while it is down.
    pub(crate) routers: Vec<String>,
    pub(crate) https: Vec<String>,
    pub(crate) owner: usize,
    pub(crate) standby: usize,
    /// The hosts the NATS servers n1, n2 and n3 run beside.
    pub(crate) nats_hosts: [usize; 3],
    pub(crate) dir: PathBuf,
    /// The namespaces go once every process in them has been killed.
    pub(crate) lan: Lan,
    /// Held to the end: one drill at a time (the test harness runs tests in threads), so
    /// that two drills' eighteen processes do not share this machine's two cores.
    pub(crate) _alone: std::sync::MutexGuard<'static, ()>,
}

/// Taken by each drill's [`Hosts`].
pub(crate) static ONE_DRILL_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

impl Hosts {
    /// The hosts, the owner alone first: it takes the site over before the others start.
    pub(crate) fn start(name: &str) -> Hosts {
        Self::start_with(name, false)
    }

    /// With a NATS server beside the owner when `nats_beside_owner` (and the two after the
    /// standby), else beside the three hosts after the standby.
    pub(crate) fn start_with(name: &str, nats_beside_owner: bool) -> Hosts {
        // A drill that failed leaves the lock poisoned; the next one runs all the same.
        let alone = ONE_DRILL_AT_A_TIME
            .lock()
            .unwrap_or_else(|e| e.into_inner());
        let dir = temp_dir(name);
        let lan = Lan::create(&["h1", "h2", "h3", "h4", "h5", "gw", "robots"]);
        let order: Vec<usize> = sitelog::host_order("park", &HOSTS)
            .into_iter()
            .map(|h| HOSTS.iter().position(|&n| n == h).expect("a host"))
            .collect();
        let (owner, standby) = (order[0], order[1]);
        let nats_hosts = if nats_beside_owner {
            [order[0], order[2], order[3]]
        } else {
            [order[2], order[3], order[4]]
        };
        let places = nats_hosts.map(|h| {
            let member = lan.member(HOSTS[h]);
            Placement {
                address: member.ip.clone(),
                netns: Some(member.ns.clone()),
            }
        });
        let servers = nats::Cluster::start_placed(name, &places);
        let ports: Vec<(u16, u16)> = HOSTS.iter().map(|_| (free_port(), free_port())).collect();
        let routers: Vec<String> = HOSTS
            .iter()
            .zip(&ports)
            .map(|(h, (_, zenoh))| format!("tcp/{}:{zenoh}", lan.member(h).ip))
            .collect();
        let https = HOSTS
            .iter()
            .zip(&ports)
            .map(|(h, (http, _))| format!("{}:{http}", lan.member(h).ip))
            .collect();
        let mut hosts = Hosts {
            servers,
            hosts: HOSTS.iter().map(|_| None).collect(),
            routers,
            https,
            owner,
            standby,
            nats_hosts,
            dir,
            lan,
            _alone: alone,
        };
        // Each host's router connects to those of the hosts started before it.
        let mut started: Vec<String> = Vec::new();
        let owner_first = std::iter::once(owner).chain((0..HOSTS.len()).filter(|&h| h != owner));
        for h in owner_first {
            let (http_port, zenoh_port) = ports[h];
            let host_dir = hosts.dir.join(HOSTS[h]);
            std::fs::create_dir_all(&host_dir).expect("the host's folder");
            let config = host_dir.join("mapper.toml");
            let listen = format!("tcp/0.0.0.0:{zenoh_port}");
            let toml = host_config(
                &host_dir,
                HOSTS[h],
                (&listen, &started),
                &hosts.servers.client_urls(),
            );
            std::fs::write(
                &config,
                format!("http_listen = \"0.0.0.0:{http_port}\"\n{toml}"),
            )
            .expect("the host's config");
            let member = hosts.lan.member(HOSTS[h]);
            let (http, zenoh) = (hosts.https[h].clone(), hosts.routers[h].clone());
            let process = MapperProcess::spawn_in(Some(member), http, zenoh.clone(), config);
            if h == owner {
                wait_for(Duration::from_secs(60), || summary_nodes(&process.http))
                    .expect("the owner takes the site over");
            } else {
                assert!(
                    summary_nodes(&process.http).is_none(),
                    "{} must not serve a site {} owns",
                    HOSTS[h],
                    HOSTS[owner]
                );
            }
            hosts.hosts[h] = Some(process);
            started.push(zenoh);
        }
        let [n1, n2, n3] = nats_hosts.map(|h| HOSTS[h]);
        eprintln!(
            "hosts: {} owns the site, {} stands by; NATS n1, n2, n3 beside {n1}, {n2}, {n3}",
            HOSTS[owner], HOSTS[standby]
        );
        hosts
    }

    pub(crate) fn host(&self, h: usize) -> &MapperProcess {
        self.hosts[h]
            .as_ref()
            .unwrap_or_else(|| panic!("{} runs", HOSTS[h]))
    }

    pub(crate) fn owner(&self) -> &MapperProcess {
        self.host(self.owner)
    }

    pub(crate) fn standby(&self) -> &MapperProcess {
        self.host(self.standby)
    }

    /// SIGKILLs the owner.
    pub(crate) fn kill_owner(&mut self) {
        self.hosts[self.owner]
            .take()
            .expect("the owner runs")
            .kill();
    }

    pub(crate) fn member(&self, name: &str) -> &Member {
        self.lan.member(name)
    }

    /// The robots, on the standby's router (the owner's acks reach them through the mesh),
    /// once each has nodes in the owner's map; those nodes.
    pub(crate) fn robots_on_owner(&self) -> (Vec<KillOnDrop>, Vec<Vec<u64>>) {
        let standby = self.routers[self.standby].clone();
        self.robots_on_owner_via(&[&standby], 60.0)
    }

    /// The robots connecting to `routers`, in turn, driving `duration_s` (at 4× speed).
    pub(crate) fn robots_on_owner_via(
        &self,
        routers: &[&str],
        duration_s: f64,
    ) -> (Vec<KillOnDrop>, Vec<Vec<u64>>) {
        self.robots_on_owner_with(routers, duration_s, "")
    }

    /// [`Hosts::robots_on_owner_via`], with `extra` in the robots' configs; the robots run in
    /// their own namespace.
    pub(crate) fn robots_on_owner_with(
        &self,
        routers: &[&str],
        duration_s: f64,
        extra: &str,
    ) -> (Vec<KillOnDrop>, Vec<Vec<u64>>) {
        let source = format!("[source.sim]\nduration_s = {duration_s:.1}\n");
        let robots = self.member("robots");
        let edges: Vec<_> = (0..ROBOTS)
            .map(|r| {
                let source = format!("{source}loop_index = {r}\n{extra}");
                let edge = edge_command_to(&self.dir, r, routers, 4.0, &source);
                robots
                    .wrap(&edge)
                    .stdout(Stdio::piped())
                    .stderr(Stdio::null())
                    .spawn()
                    .map(KillOnDrop::from)
                    .expect("levelmap edge starts")
            })
            .collect();
        let owner = &self.owner().http;
        let before = wait_for(Duration::from_secs(90), || {
            let seqs: Vec<Vec<u64>> = (0..ROBOTS)
                .map(|r| node_seqs(owner, "park", &format!("robot{r}")))
                .collect();
            seqs.iter().all(|s| s.len() >= 3).then_some(seqs)
        })
        .expect("both robots' nodes reach the owner's map");
        (edges, before)
    }

    /// The host serving the site (its HTTP address) and how many nodes its map holds.
    pub(crate) fn serving(&self) -> Option<(String, u64)> {
        self.hosts
            .iter()
            .flatten()
            .find_map(|h| Some((h.http.clone(), summary_nodes(&h.http)?)))
    }

    /// Waits for the site's map to hold more than `nodes`, on whichever host serves it; how
    /// long after `since`.
    pub(crate) fn grows_past(&self, nodes: u64, since: Instant) -> Duration {
        wait_for(Duration::from_secs(60), || {
            let (_, now) = self.serving()?;
            (now > nodes).then(|| since.elapsed())
        })
        .expect("the site maps again within 60 s")
    }

    /// Watches the site's map for `window` from `since`: the longest time it did not grow
    /// (the robots publishing all along), on whichever host served it.
    pub(crate) fn longest_pause(&self, since: Instant, window: Duration) -> Duration {
        let (mut last_growth, mut longest) = (since, Duration::ZERO);
        let mut nodes = self.serving().map_or(0, |(_, n)| n);
        while since.elapsed() < window {
            if let Some((_, now)) = self.serving()
                && now > nodes
            {
                nodes = now;
                longest = longest.max(last_growth.elapsed());
                last_growth = Instant::now();
            }
            std::thread::sleep(Duration::from_millis(100));
        }
        longest.max(last_growth.elapsed())
    }

    /// Waits for the standby to serve the site; how long after `since`.
    pub(crate) fn standby_takes_over(&self, since: Instant) -> Duration {
        wait_for(Duration::from_secs(60), || {
            let n = summary_nodes(&self.standby().http)?;
            (n > 0).then_some(since.elapsed())
        })
        .expect("the standby takes the site over")
    }

    /// Every node each robot made is in the standby's map once, in order.
    pub(crate) fn every_node_once_on_standby(&self, edges: Vec<KillOnDrop>) {
        self.every_node_once(edges, || self.standby().http.clone());
    }

    /// The owner, back after a fault, gets the site again from the standby once it has been
    /// alive for the hand-back time (it is first in the site's order); every node made is
    /// there once.
    pub(crate) fn every_node_once_back_home(&self, edges: Vec<KillOnDrop>) {
        let owner = self.owner().http.clone();
        self.every_node_once(edges, || {
            wait_for(Duration::from_secs(60), || summary_nodes(&owner))
                .expect("the standby hands the site back to the owner, first in its order");
            owner.clone()
        });
        let metrics = http_get(&self.standby().http, "/metrics")
            .expect("metrics")
            .1;
        assert_eq!(metric(&metrics, "levelmap_sites_handed_back_total"), 1);
    }

    /// Every node each robot made is in the map of the host `serving` names once the robots
    /// are done, once, in order.
    pub(crate) fn every_node_once(&self, edges: Vec<KillOnDrop>, serving: impl Fn() -> String) {
        let reports: Vec<_> = edges
            .into_iter()
            .map(|edge| edge_report(edge, Duration::from_secs(180)))
            .collect();
        let http = serving();
        for (r, report) in reports.into_iter().enumerate() {
            let made = report["nodes"].as_u64().expect("nodes");
            assert_eq!(report["outbox_pending"], 0, "robot{r}: {report}");
            let seqs = node_seqs(&http, "park", &format!("robot{r}"));
            assert_eq!(
                seqs,
                (0..made).collect::<Vec<_>>(),
                "robot{r}: every node made, once, in order"
            );
        }
    }

    /// The mapper log lines about the cluster and the site of every running host, printed.
    pub(crate) fn print_site_logs(&self, drill: &str) {
        for (h, host) in self.hosts.iter().enumerate() {
            let Some(host) = host else { continue };
            let log =
                std::fs::read_to_string(host.config.with_extension("log")).unwrap_or_default();
            for line in log.lines().filter(|l| {
                l.contains("cluster:")
                    || l.contains("site ")
                    || l.contains("WARN")
                    || l.contains("nats")
            }) {
                eprintln!("{drill}: {}: {}", HOSTS[h], without_colours(line));
            }
        }
    }
}

impl Drop for Hosts {
    fn drop(&mut self) {
        std::fs::remove_dir_all(&self.dir).ok();
    }
}

/// The server leading `stream`, as the servers' monitoring (`/jsz`) says.
pub(crate) fn stream_leader(servers: &nats::Cluster, stream: &str) -> Option<String> {
    servers.monitors().iter().find_map(|monitor| {
        let jsz = get_json(monitor, "/jsz?accounts=true&streams=true")?;
        jsz["account_details"]
            .as_array()?
            .iter()
            .flat_map(|a| a["stream_detail"].as_array().into_iter().flatten())
            .find(|s| s["name"] == stream)
            .and_then(|s| s["cluster"]["leader"].as_str().map(str::to_owned))
    })
}

/// A `levelmap gateway` in front of the running hosts.
pub(crate) struct GatewayProcess {
    pub(crate) http: String,
    /// Held only to kill the gateway when this is dropped.
    _process: KillOnDrop,
}

impl GatewayProcess {
    /// In the namespace `gw`, listing every mapper host's HTTP address.
    pub(crate) fn start(cluster: &Hosts, name: &str) -> GatewayProcess {
        let port = free_port();
        let http = format!("{}:{port}", cluster.member("gw").ip);
        let servers = cluster.servers.client_urls();
        let hosts: String = HOSTS
            .iter()
            .zip(&cluster.https)
            .map(|(host, address)| format!("{host} = {address:?}\n"))
            .collect();
        let config = cluster.dir.join(format!("{name}.toml"));
        std::fs::write(
            &config,
            format!(
                "http_listen = \"0.0.0.0:{port}\"\n[hosts]\n{hosts}[nats]\nservers = {servers:?}\n"
            ),
        )
        .expect("gateway config");
        let log = std::fs::File::create(config.with_extension("log")).expect("gateway log");
        let mut gateway = levelmap();
        gateway.args(["gateway", "--config"]).arg(&config);
        let child = cluster
            .member("gw")
            .wrap(&gateway)
            .stdout(Stdio::null())
            .stderr(log)
            .spawn()
            .map(KillOnDrop::from)
            .expect("levelmap gateway starts");
        wait_for(Duration::from_secs(30), || http_get(&http, "/healthz")).expect("gateway up");
        GatewayProcess {
            http,
            _process: child,
        }
    }
}

/// `line` without its ANSI colour codes (`ESC [ … m`).
pub(crate) fn without_colours(line: &str) -> String {
    let mut out = String::with_capacity(line.len());
    let mut chars = line.chars();
    while let Some(c) = chars.next() {
        if c == '\u{1b}' {
            chars.by_ref().find(|&c| c == 'm');
        } else {
            out.push(c);
        }
    }
    out
}

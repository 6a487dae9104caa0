//! The processes a `bench-cluster` run measures, each a child process of this very binary
//! (`levelmap mapper`, `levelmap gateway`) as an operator runs them: three nats-servers, the
//! mapper hosts with their Zenoh routers meshed and a gateway in front; or, for the cost of
//! the cluster, one single-machine mapper holding every site. Configs, stores and logs are
//! in the run's folder.

use crate::bench_fleet::agent;
use anyhow::{Context, Result, bail};
use gateway::GatewayConfig;
use mapper::MapperConfig;
use mapper::config::ClusterConfig;
use runtime::session::SessionConfig;
use sitelog::NatsAccess;
use sitelog::local::LocalCluster;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// A mapper host (or the single mapper) running.
pub(super) struct Host {
    pub name: String,
    /// Its HTTP API, `127.0.0.1:port`.
    pub http: String,
    /// Its Zenoh router's endpoint.
    pub zenoh: String,
    /// `None` once killed.
    child: Option<Child>,
}

/// Every process of the run; killed when dropped.
pub(super) struct Deployment {
    /// Declared first: dropped (killed) before the servers they use.
    hosts: Vec<Host>,
    gateway: Option<(String, Child)>,
    _nats: Option<LocalCluster>,
    /// The run's folder: each process's config and log in a folder named after it.
    dir: PathBuf,
}

impl Deployment {
    /// Three nats-servers (`nats_server`), `hosts` mapper hosts h1… sharing `sites`, and a
    /// gateway; in `dir` ([`crate::lab_dir::prepare`]).
    pub fn cluster(dir: &Path, hosts: usize, sites: &[String], nats_server: &Path) -> Result<Self> {
        crate::lab_dir::prepare(dir)?;
        let nats = LocalCluster::start(nats_server, &dir.join("nats"), None)
            .context("starting three nats-servers")?;
        let access = NatsAccess {
            servers: nats.client_urls(),
            ..NatsAccess::default()
        };
        let names: Vec<String> = (1..=hosts).map(|h| format!("h{h}")).collect();
        let mut started: Vec<Host> = Vec::new();
        for name in &names {
            let (http, zenoh) = (local_address()?, format!("tcp/{}", local_address()?));
            let mut config = site_mapper(&dir.join(name), sites, &http, &zenoh)?;
            // Each router connects to those started before it: a full mesh, one link a pair.
            config.zenoh.connect = Some(started.iter().map(|h| h.zenoh.clone()).collect());
            // As deploy/cluster/mapper-host.toml: a takeover replays at most this tail.
            config.store.snapshot_every_nodes = cluster::SNAPSHOT_EVERY_NODES;
            config.cluster = Some(ClusterConfig {
                host: name.clone(),
                hosts: names.clone(),
                nats: access.clone(),
                ..ClusterConfig::default()
            });
            let child = spawn(&dir.join(name), "mapper", &toml::to_string(&config)?)?;
            started.push(Host {
                name: name.clone(),
                http,
                zenoh,
                child: Some(child),
            });
        }
        let gateway_http = local_address()?;
        let gateway = GatewayConfig {
            http_listen: gateway_http.clone(),
            hosts: started
                .iter()
                .map(|h| (h.name.clone(), h.http.clone()))
                .collect(),
            nats: access,
            ..GatewayConfig::default()
        };
        let gateway = spawn(&dir.join("gateway"), "gateway", &toml::to_string(&gateway)?)?;
        Ok(Deployment {
            hosts: started,
            gateway: Some((gateway_http, gateway)),
            _nats: Some(nats),
            dir: dir.to_owned(),
        })
    }

    /// One mapper without `[cluster]` holding every site, in `dir` ([`crate::lab_dir::prepare`]).
    pub fn single_machine(dir: &Path, sites: &[String]) -> Result<Self> {
        crate::lab_dir::prepare(dir)?;
        let (http, zenoh) = (local_address()?, format!("tcp/{}", local_address()?));
        let config = site_mapper(&dir.join("mapper"), sites, &http, &zenoh)?;
        let child = spawn(&dir.join("mapper"), "mapper", &toml::to_string(&config)?)?;
        Ok(Deployment {
            hosts: vec![Host {
                name: "mapper".into(),
                http,
                zenoh,
                child: Some(child),
            }],
            gateway: None,
            _nats: None,
            dir: dir.to_owned(),
        })
    }

    /// Where users read the map: the gateway, or the single mapper.
    pub fn http(&self) -> &str {
        match &self.gateway {
            Some((http, _)) => http,
            None => &self.hosts[0].http,
        }
    }

    /// Every router's endpoint, in the hosts' order.
    pub fn zenoh_endpoints(&self) -> Vec<String> {
        self.hosts.iter().map(|h| h.zenoh.clone()).collect()
    }

    /// Waits until every site answers through [`Self::http`] (its owner has claimed it; the
    /// single mapper: until it answers), or fails naming those that do not, and any process
    /// that exited.
    pub fn wait_served(&mut self, sites: &[String], timeout: Duration) -> Result<()> {
        let deadline = Instant::now() + timeout;
        loop {
            let missing: Vec<&String> = if self.gateway.is_none() {
                // A single mapper makes a fleet at its first node.
                let up = status(self.http(), "/healthz") == 200;
                sites.iter().filter(|_| !up).collect()
            } else {
                sites
                    .iter()
                    .filter(|s| status(self.http(), &format!("/api/v1/fleets/{s}/summary")) != 200)
                    .collect()
            };
            if missing.is_empty() {
                return Ok(());
            }
            if let Some(exited) = self.exited() {
                bail!(
                    "{exited} exited before the sites were served{}",
                    self.log_tails()
                );
            }
            if Instant::now() > deadline {
                bail!(
                    "no owner serves {missing:?} after {timeout:?}{}",
                    self.log_tails()
                );
            }
            std::thread::sleep(Duration::from_millis(200));
        }
    }

    /// Waits until each site is served by its home, the first host in its order (a site
    /// claimed by another host while the hosts were starting is handed back), so that the
    /// bench measures the placement the hash gives.
    pub fn wait_home(&self, sites: &[String], timeout: Duration) -> Result<()> {
        let names: Vec<&str> = self.hosts.iter().map(|h| h.name.as_str()).collect();
        let home: BTreeMap<&str, &str> = sites
            .iter()
            .map(|s| (s.as_str(), sitelog::host_order(s, &names)[0]))
            .collect();
        let deadline = Instant::now() + timeout;
        loop {
            let owners = self.owners();
            let away: Vec<&str> = home
                .iter()
                .filter(|(site, host)| {
                    !owners
                        .get(**host)
                        .is_some_and(|o| o.iter().any(|s| s == *site))
                })
                .map(|(site, _)| *site)
                .collect();
            if away.is_empty() {
                return Ok(());
            }
            if Instant::now() > deadline {
                bail!("sites {away:?} are not on their first host after {timeout:?}: {owners:?}");
            }
            std::thread::sleep(Duration::from_millis(500));
        }
    }

    /// The last lines of every process's log, to say why a run failed where its folder is
    /// gone (a CI machine's).
    fn log_tails(&self) -> String {
        const LINES: usize = 4;
        let names = self.hosts.iter().map(|h| h.name.as_str());
        let names = names.chain(self.gateway.as_ref().map(|_| "gateway"));
        let mut tails = String::new();
        for name in names {
            let log = std::fs::read_to_string(self.dir.join(name).join("log")).unwrap_or_default();
            let lines: Vec<&str> = log.lines().collect();
            tails.push_str(&format!("\n{name}'s log ends:"));
            for line in &lines[lines.len().saturating_sub(LINES)..] {
                tails.push_str(&format!("\n  {line}"));
            }
        }
        tails
    }

    /// The first process found exited, named.
    fn exited(&mut self) -> Option<String> {
        let hosts = self
            .hosts
            .iter_mut()
            .filter_map(|h| Some((&h.name, h.child.as_mut()?)));
        let gateway = self.gateway.as_mut().map(|(_, c)| c);
        let gateway_name = "gateway".to_string();
        hosts
            .chain(gateway.map(|c| (&gateway_name, c)))
            .find_map(|(name, child)| {
                let status = child.try_wait().ok()??;
                Some(format!("{name} ({status})"))
            })
    }

    /// The sites each running host serves now (its `/api/v1/fleets`).
    pub fn owners(&self) -> BTreeMap<String, Vec<String>> {
        self.hosts
            .iter()
            .filter(|h| h.child.is_some())
            .map(|h| {
                let sites = agent()
                    .get(format!("http://{}/api/v1/fleets", h.http))
                    .call()
                    .ok()
                    .and_then(|mut r| r.body_mut().read_to_vec().ok())
                    .and_then(|body| serde_json::from_slice::<serde_json::Value>(&body).ok())
                    .and_then(|v| serde_json::from_value(v["fleets"].clone()).ok())
                    .unwrap_or_default();
                (h.name.clone(), sites)
            })
            .collect()
    }

    /// SIGKILLs host `name`: its mapper and, in the same process, its Zenoh router.
    pub fn kill(&mut self, name: &str) -> Result<()> {
        let host = self
            .hosts
            .iter_mut()
            .find(|h| h.name == name)
            .context("no such host")?;
        let mut child = host.child.take().context("killed already")?;
        child.kill()?;
        child.wait()?;
        Ok(())
    }
}

impl Drop for Deployment {
    fn drop(&mut self) {
        let hosts = self.hosts.iter_mut().filter_map(|h| h.child.as_mut());
        for child in hosts.chain(self.gateway.as_mut().map(|(_, c)| c)) {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

/// The mapper config of every run: the park's datum and mapping, the sites, its store in
/// `dir`.
fn site_mapper(dir: &Path, sites: &[String], http: &str, zenoh: &str) -> Result<MapperConfig> {
    let mut config = crate::park_mapper_config(dir, http, zenoh)?;
    config.fleets = sites.to_vec();
    config.zenoh = SessionConfig::router(zenoh);
    Ok(config)
}

/// `levelmap <command> --config <dir>/config.toml`, its log in `<dir>/log`.
fn spawn(dir: &Path, command: &str, config: &str) -> Result<Child> {
    std::fs::create_dir_all(dir)?;
    let path = dir.join("config.toml");
    std::fs::write(&path, config)?;
    let log = std::fs::File::create(dir.join("log"))?;
    Command::new(std::env::current_exe().context("this binary's path")?)
        .arg(command)
        .arg("--config")
        .arg(&path)
        .env("NO_COLOR", "1")
        .stdin(Stdio::null())
        .stdout(log.try_clone()?)
        .stderr(log)
        .spawn()
        .with_context(|| format!("starting levelmap {command}"))
}

/// A free `127.0.0.1:port`.
fn local_address() -> Result<String> {
    Ok(format!("127.0.0.1:{}", sitelog::local::free_local_port()?))
}

/// The HTTP status of GET `path` (0: no answer).
pub(super) fn status(http: &str, path: &str) -> u16 {
    agent()
        .get(format!("http://{http}{path}"))
        .call()
        .map_or(0, |mut r| {
            let _ = r.body_mut().read_to_vec();
            r.status().as_u16()
        })
}

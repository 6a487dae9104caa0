//! The mapper as the drills start it: a `levelmap mapper` process on its own ports and
//! store, stopped, killed and started again on the same store; and its store checked.

use super::{KillOnDrop, free_port, http_get, levelmap, netns, sigterm, wait_for};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Child, Stdio};
use std::time::Duration;

/// A mapper process on its own ports and store.
pub struct MapperProcess {
    pub http: String,
    pub zenoh: String,
    pub config: PathBuf,
    /// The network namespace it runs in, if not the test's.
    ns: Option<String>,
    child: KillOnDrop,
}

/// A mapper stopped or killed: what starts it again as it was.
pub struct Stopped {
    pub http: String,
    pub zenoh: String,
    pub config: PathBuf,
    ns: Option<String>,
}

impl MapperProcess {
    pub fn start(dir: &Path) -> MapperProcess {
        Self::start_on(dir, format!("tcp/127.0.0.1:{}", free_port()))
    }

    /// A mapper listening for robots on `zenoh` (an endpoint the robots may already dial).
    pub fn start_on(dir: &Path, zenoh: String) -> MapperProcess {
        Self::start_with(dir, zenoh, "")
    }

    /// A mapper with more top-level config lines (`fleets = [...]`, a `store_path`, which
    /// comes after the default one and wins).
    pub fn start_with(dir: &Path, zenoh: String, extra: &str) -> MapperProcess {
        let table = format!("mode = \"router\"\nlisten = [{zenoh:?}]\n");
        Self::start_configured(dir, zenoh, extra, &table)
    }

    /// A mapper whose `[zenoh]` table (with any subtables) is `zenoh_toml`, listening for
    /// robots on `zenoh`.
    pub fn start_with_zenoh(dir: &Path, zenoh: String, zenoh_toml: &str) -> MapperProcess {
        Self::start_configured(dir, zenoh, "", zenoh_toml)
    }

    /// A mapper with `config_toml` as its whole config but `http_listen` (on a free port),
    /// without the drills' defaults.
    pub fn start_config(dir: &Path, zenoh: String, config_toml: &str) -> MapperProcess {
        let http = format!("127.0.0.1:{}", free_port());
        let config = dir.join("mapper.toml");
        std::fs::write(&config, format!("http_listen = {http:?}\n{config_toml}"))
            .expect("mapper config");
        Self::spawn(http, zenoh, config)
    }

    fn start_configured(dir: &Path, zenoh: String, extra: &str, zenoh_toml: &str) -> MapperProcess {
        let http = format!("127.0.0.1:{}", free_port());
        let config = dir.join("mapper.toml");
        let store = format!("store_path = {:?}\n", dir.join("mapper.redb"));
        let store = if extra.contains("store_path") {
            ""
        } else {
            &store
        };
        // The drills count mapped nodes: every node is mapped, none passed over covered
        // ground (bounded growth is tested by e2e_laps).
        std::fs::write(
            &config,
            format!(
                "http_listen = {http:?}\n{store}{extra}\n[mapping.coverage]\nenabled = false\n\n[zenoh]\n{zenoh_toml}",
            ),
        )
        .expect("mapper config");
        Self::spawn(http, zenoh, config)
    }

    fn spawn(http: String, zenoh: String, config: PathBuf) -> MapperProcess {
        Self::spawn_in(None, http, zenoh, config)
    }

    /// A mapper with its config file `config` written already, inside `net` if given; `http`
    /// is where the test reaches its HTTP API.
    pub fn spawn_in(
        net: Option<&dyn netns::Namespace>,
        http: String,
        zenoh: String,
        config: PathBuf,
    ) -> MapperProcess {
        Self::spawn_with_args(net, http, zenoh, config, &[])
    }

    /// [`Self::spawn_in`] with more arguments for `levelmap mapper`.
    fn spawn_with_args(
        net: Option<&dyn netns::Namespace>,
        http: String,
        zenoh: String,
        config: PathBuf,
        args: &[&std::ffi::OsStr],
    ) -> MapperProcess {
        // Its log beside its config (appended to across restarts), read when it fails to start.
        let log_path = config.with_extension("log");
        let log = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&log_path)
            .expect("mapper log");
        let mut command = levelmap();
        command.args(["mapper", "--config"]).arg(&config).args(args);
        if let Some(net) = net {
            command = net.wrap(&command);
        }
        let ns = net.map(|net| net.ns().to_owned());
        let mut child = command
            .stdout(Stdio::null())
            .stderr(log)
            .spawn()
            .map(KillOnDrop::from)
            .expect("levelmap mapper starts");
        let up = wait_for(Duration::from_secs(30), || http_get(&http, "/healthz"));
        if up.is_none() {
            let exited = child.try_wait().ok().flatten();
            let log = std::fs::read_to_string(&log_path).unwrap_or_default();
            let tail: Vec<&str> = log.lines().rev().take(20).collect();
            panic!(
                "the mapper's /healthz ({http}) did not answer in 30 s; exited: {exited:?}; \
                 its log's last lines, newest first:\n{}",
                tail.join("\n")
            );
        }
        MapperProcess {
            http,
            zenoh,
            config,
            ns,
            child,
        }
    }

    /// The process id.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// The process, for signals and its exit.
    pub fn child(&mut self) -> &mut Child {
        &mut self.child
    }

    /// SIGTERM, waited for: a graceful stop (exit code 0; the snapshots written).
    pub fn stop(mut self) -> Stopped {
        sigterm(&self.child);
        let status = self.child.wait().expect("stops");
        assert_eq!(status.code(), Some(0), "a graceful stop");
        self.stopped()
    }

    /// SIGKILL: no chance to flush or close anything.
    pub fn kill(mut self) -> Stopped {
        self.child.kill().expect("SIGKILL");
        self.child.wait().expect("reaped");
        self.stopped()
    }

    fn stopped(&self) -> Stopped {
        Stopped {
            http: self.http.clone(),
            zenoh: self.zenoh.clone(),
            config: self.config.clone(),
            ns: self.ns.clone(),
        }
    }

    /// The same mapper (ports, config, namespace) started from a backup
    /// (`levelmap mapper --restore`): its store must be gone.
    pub fn restore(stopped: Stopped, backup: &Path) -> MapperProcess {
        let net = stopped.ns.as_ref().map(|ns| ns as &dyn netns::Namespace);
        let args = [std::ffi::OsStr::new("--restore"), backup.as_os_str()];
        Self::spawn_with_args(net, stopped.http, stopped.zenoh, stopped.config, &args)
    }

    /// The same mapper (ports, store, namespace) started again.
    pub fn restart(stopped: Stopped) -> MapperProcess {
        let net = stopped.ns.as_ref().map(|ns| ns as &dyn netns::Namespace);
        Self::spawn_in(net, stopped.http, stopped.zenoh, stopped.config)
    }
}

/// `levelmap mapper --verify-store --json` on a mapper's config: the exit code, the report.
pub fn verify_store(config: &Path) -> (Option<i32>, Value) {
    let out = levelmap()
        .args(["mapper", "--verify-store", "--json", "--config"])
        .arg(config)
        .output()
        .expect("levelmap runs");
    let report = serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!(
            "--verify-store --json: {e}: {}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        )
    });
    (out.status.code(), report)
}

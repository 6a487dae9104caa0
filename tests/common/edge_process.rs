//! The edge service as the drills start it: a simulated robot's process with its config
//! file written, and its JSON report when it ends.

use super::{KillOnDrop, levelmap};
use serde_json::Value;
use std::io::Read;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// A simulated robot's edge service process (`--json` report on stdout).
pub fn spawn_edge(
    dir: &Path,
    robot: usize,
    connect: &str,
    duration_s: f64,
    speed: f64,
) -> KillOnDrop {
    let source = format!("[source.sim]\nloop_index = {robot}\nduration_s = {duration_s}\n");
    spawn_edge_with(dir, robot, connect, speed, &source)
}

/// An edge service process with the given `[source.…]` table.
pub fn spawn_edge_with(
    dir: &Path,
    robot: usize,
    connect: &str,
    speed: f64,
    source: &str,
) -> KillOnDrop {
    edge_command(dir, robot, connect, speed, source)
        .spawn()
        .map(KillOnDrop::from)
        .expect("levelmap edge starts")
}

/// A simulated robot's edge service with `LEVELMAP_…` keys in its environment.
pub fn spawn_edge_env(
    dir: &Path,
    robot: usize,
    connect: &str,
    (duration_s, speed): (f64, f64),
    env: &[(&str, &str)],
) -> KillOnDrop {
    let source = format!(
        "[source.sim]\nloop_index = {}\nduration_s = {duration_s}\n",
        robot % 3
    );
    edge_command(dir, robot, connect, speed, &source)
        .envs(env.iter().copied())
        .spawn()
        .map(KillOnDrop::from)
        .expect("levelmap edge starts")
}

/// The command of an edge service with its config file written (the partition drill runs its
/// program and arguments inside a network namespace).
pub fn edge_command(dir: &Path, robot: usize, connect: &str, speed: f64, source: &str) -> Command {
    edge_command_to(dir, robot, &[connect], speed, source)
}

/// [`edge_command`] with several routers to connect to (Zenoh tries them in turn).
pub fn edge_command_to(
    dir: &Path,
    robot: usize,
    connect: &[&str],
    speed: f64,
    source: &str,
) -> Command {
    let config = dir.join(format!("robot{robot}.toml"));
    std::fs::write(
        &config,
        format!(
            "robot = \"robot{robot}\"\noutbox_path = {:?}\nspeed = {speed}\nresend_after_ms = 500\n\
             [zenoh]\nconnect = {connect:?}\n{source}",
            dir.join(format!("robot{robot}-outbox.redb"))
        ),
    )
    .expect("edge config");
    let mut command = levelmap();
    command
        .args(["edge", "--json", "--config"])
        .arg(&config)
        .stdout(Stdio::piped())
        .stderr(Stdio::null());
    command
}

/// Waits for an edge process (at most `timeout`) and returns its JSON report.
pub fn edge_report(mut child: KillOnDrop, timeout: Duration) -> Value {
    let deadline = Instant::now() + timeout;
    loop {
        if let Some(status) = child.try_wait().expect("edge status") {
            assert!(status.success(), "edge exited with {status}");
            let mut out = String::new();
            child
                .stdout
                .take()
                .expect("stdout")
                .read_to_string(&mut out)
                .expect("report");
            return serde_json::from_str(&out).expect("JSON report");
        }
        if Instant::now() > deadline {
            panic!("edge still running after {timeout:?}");
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

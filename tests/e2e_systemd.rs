//! The systemd units of `deploy/systemd/`: `systemd-analyze verify` passes on each (the edge's
//! and the NATS servers' templates as instances), with ExecStart at the built binary (the
//! tests' nats-server for NATS), and their hardening scores at most 2.0 on `systemd-analyze
//! security`. systemd only warns about an unknown key, so any output fails the check: a unit
//! with a typo'd key is shown to fail it. And the services take
//! their whole config from `LEVELMAP_…` variables, as the units set the robot id, through
//! the binary; a variable that names no key stops the start.

mod common;

use common::*;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

const INSTALLED_AT: &str = "/usr/local/bin/levelmap";

/// A unit of `deploy/systemd/` with ExecStart at the binary under test.
fn unit_text(name: &str) -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../deploy/systemd")
        .join(name);
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path:?}: {e}"));
    assert!(
        text.contains(&format!("ExecStart={INSTALLED_AT} ")),
        "{name}"
    );
    text.replace(INSTALLED_AT, env!("CARGO_BIN_EXE_levelmap"))
}

/// The NATS servers' unit, with ExecStart at the tests' nats-server (2.15, as shipped).
fn nats_unit_text() -> String {
    const NATS_AT: &str = "/usr/local/bin/nats-server";
    let path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../deploy/systemd/levelmap-nats@.service");
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path:?}: {e}"));
    assert!(
        text.contains(&format!("ExecStart={NATS_AT} ")),
        "levelmap-nats@.service"
    );
    text.replace(
        NATS_AT,
        &testdata::nats::nats_server().display().to_string(),
    )
}

fn write_unit(dir: &Path, name: &str, text: &str) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text).expect("unit written");
    path
}

/// `systemd-analyze ARGS UNIT`: `Err` with its output when it fails or says anything.
fn analyze(args: &[&str], unit: &Path) -> Result<(), String> {
    testdata::debian::require(&[("systemd-analyze", "systemd")]);
    let out = Command::new("systemd-analyze")
        .args(args)
        .arg(unit)
        .output()
        .expect("systemd-analyze runs (Debian: apt-get install systemd)");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    match (
        out.status.success(),
        args[0] == "verify" && !text.trim().is_empty(),
    ) {
        (true, false) => Ok(()),
        _ => Err(format!(
            "{} {unit:?}: {}\n{text}",
            args.join(" "),
            out.status
        )),
    }
}

fn verify(unit: &Path) -> Result<(), String> {
    analyze(&["verify", "--man=no"], unit)
}

#[test]
fn every_unit_verifies_and_is_hardened() {
    let dir = temp_dir("systemd");
    let mapper = write_unit(
        &dir,
        "levelmap-mapper.service",
        &unit_text("levelmap-mapper.service"),
    );
    write_unit(
        &dir,
        "levelmap-edge@.service",
        &unit_text("levelmap-edge@.service"),
    );
    let gateway = write_unit(
        &dir,
        "levelmap-gateway.service",
        &unit_text("levelmap-gateway.service"),
    );
    write_unit(&dir, "levelmap-nats@.service", &nats_unit_text());
    // Every unit shipped is one of these.
    let shipped: Vec<String> =
        std::fs::read_dir(Path::new(env!("CARGO_MANIFEST_DIR")).join("../../deploy/systemd"))
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|name| name.ends_with(".service"))
            .collect();
    for name in &shipped {
        assert!(
            dir.join(name).is_file(),
            "{name} is shipped but not checked"
        );
    }
    // The templates are loaded for an instance: a robot's, a NATS server's.
    let edge = dir.join("levelmap-edge@robot3.service");
    let nats = dir.join("levelmap-nats@nats1.service");
    for unit in [&mapper, &edge, &gateway, &nats] {
        verify(unit).unwrap_or_else(|e| panic!("{e}"));
        // Exposure 0..10 as the tool prints it; the threshold is in tenths.
        analyze(&["security", "--offline=yes", "--threshold=20"], unit)
            .unwrap_or_else(|e| panic!("{e}"));
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_unit_with_a_typo_fails_verification() {
    let dir = temp_dir("systemd-typo");
    let good = unit_text("levelmap-mapper.service");
    let typo = good.replace("ProtectSystem=strict", "ProtectSystm=strict");
    assert_ne!(typo, good);
    let e = verify(&write_unit(&dir, "typo.service", &typo)).unwrap_err();
    assert!(e.contains("ProtectSystm"), "{e}");
    let missing = good.replace(env!("CARGO_BIN_EXE_levelmap"), "/nonexistent/levelmap");
    let e = verify(&write_unit(&dir, "missing.service", &missing)).unwrap_err();
    assert!(e.contains("/nonexistent/levelmap"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn the_services_take_their_config_from_the_environment() {
    let dir = temp_dir("env-config");
    let http = format!("127.0.0.1:{}", free_port());
    let zenoh = format!("tcp/127.0.0.1:{}", free_port());
    let store = dir.join("mapper.redb");
    let mapper_env = [
        ("LEVELMAP_HTTP_LISTEN", http.as_str()),
        ("LEVELMAP_STORE_PATH", store.to_str().unwrap()),
        ("LEVELMAP_FLEETS", r#"["yard"]"#),
        ("LEVELMAP_ZENOH__LISTEN", &format!("[{zenoh:?}]")),
    ];
    // No config file: every key from the environment, or its default.
    let mapper = levelmap()
        .arg("mapper")
        .envs(mapper_env)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .map(KillOnDrop::from)
        .expect("levelmap mapper starts");
    let up = wait_for(Duration::from_secs(30), || http_get(&http, "/healthz"));
    assert!(up.is_some(), "the mapper did not answer on {http}");
    let outbox = dir.join("outbox.redb");
    let edge = levelmap()
        .args(["edge", "--json"])
        .envs([
            ("LEVELMAP_FLEET", "yard"),
            // A robot id that reads as a number stays the id (the key holds a string).
            ("LEVELMAP_ROBOT", "7"),
            ("LEVELMAP_ZENOH__CONNECT", &format!("[{zenoh:?}]")),
            ("LEVELMAP_OUTBOX_PATH", outbox.to_str().unwrap()),
            ("LEVELMAP_SPEED", "4"),
            ("LEVELMAP_RESEND_AFTER_MS", "500"),
            ("LEVELMAP_SOURCE__SIM__DURATION_S", "12"),
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .map(KillOnDrop::from)
        .expect("levelmap edge starts");
    let report = edge_report(edge, Duration::from_secs(120));
    assert_eq!(report["robot"], "7", "{report}");
    let made = report["nodes"].as_u64().unwrap();
    assert!(made >= 2, "{report}");
    assert_eq!(node_seqs(&http, "yard", "7"), (0..made).collect::<Vec<_>>());
    drop(mapper);

    // A variable that names no key stops the start, naming it.
    let out = levelmap()
        .arg("mapper")
        .envs(mapper_env)
        .env("LEVELMAP_HTTP_LISTN", "0.0.0.0:1")
        .output()
        .expect("levelmap mapper runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(stderr.contains("LEVELMAP_HTTP_LISTN"), "{stderr}");
    std::fs::remove_dir_all(&dir).ok();
}

//! The robot link over TLS with client certificates, and the access-control list that
//! `deploy/zenoh/make-certs.sh` writes into the mapper's Zenoh configuration: real
//! `levelmap mapper` and `levelmap edge` processes, and Zenoh sessions holding the robots'
//! certificates. Every refusal is paired with the same attempt going through where it should
//! (the right certificate, or the same mapper without the list), so that a refusal for the
//! wrong reason fails the test.

mod common;

use common::*;
use runtime::session::{Role, SessionConfig, TlsConfig, now_ns};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};
use wire::{Message, v1};
use zenoh::Wait;

const FLEET: &str = "park";

/// make-certs.sh's CA, mapper and robot0/robot1 files in `dir/name`; fails the test, with
/// the script's words, when it cannot run (openssl missing).
fn make_certs(dir: &Path, name: &str) -> PathBuf {
    make_certs_for(dir, name, &["robot0", "robot1"])
}

/// make-certs.sh's files for `robots` (of fleet park, or `fleet/robot`) in `dir/name`.
fn make_certs_for(dir: &Path, name: &str, robots: &[&str]) -> PathBuf {
    let out = dir.join(name);
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../deploy/zenoh/make-certs.sh");
    testdata::debian::require(&[("openssl", "openssl")]);
    let run = Command::new("bash")
        .arg(&script)
        .arg(&out)
        .arg(FLEET)
        .args(robots)
        .output()
        .expect("bash runs make-certs.sh");
    assert!(
        run.status.success(),
        "make-certs.sh failed (it needs openssl): {}",
        String::from_utf8_lossy(&run.stderr)
    );
    out
}

/// A mapper on make-certs.sh's router.json5 (TLS, client certificates, the access-control
/// list); the TOML's `listen` replaces the file's `tls/0.0.0.0:7447` with a free port.
fn guarded_mapper(dir: &Path, certs: &Path) -> MapperProcess {
    let zenoh = format!("tls/127.0.0.1:{}", free_port());
    let table = format!(
        "listen = [{zenoh:?}]\nconfig_file = {:?}\n",
        certs.join("router.json5")
    );
    MapperProcess::start_with_zenoh(&fresh(dir), zenoh, &table)
}

/// The same TLS and client certificates from `[zenoh.tls]` alone: no access-control list.
fn unguarded_mapper(dir: &Path, certs: &Path) -> MapperProcess {
    let zenoh = format!("tls/127.0.0.1:{}", free_port());
    let table = format!(
        "listen = [{zenoh:?}]\n[zenoh.tls]\nroot_ca = {:?}\ncert = {:?}\nkey = {:?}\n",
        certs.join("ca.pem"),
        certs.join("mapper.pem"),
        certs.join("mapper.key")
    );
    MapperProcess::start_with_zenoh(&fresh(dir), zenoh, &table)
}

fn fresh(dir: &Path) -> PathBuf {
    std::fs::create_dir_all(dir).expect("mapper dir");
    dir.to_owned()
}

/// `[zenoh.tls]` for a robot: the fleet's CA in `ca`, the certificate `robot` of `identity`.
fn robot_tls(ca: &Path, identity: Option<(&Path, &str)>) -> TlsConfig {
    TlsConfig {
        root_ca: Some(ca.join("ca.pem")),
        cert: identity.map(|(dir, robot)| dir.join(format!("{robot}.pem"))),
        key: identity.map(|(dir, robot)| dir.join(format!("{robot}.key"))),
    }
}

/// A client session to `endpoint`, as a robot's edge service opens it.
fn session(endpoint: &str, tls: TlsConfig) -> anyhow::Result<zenoh::Session> {
    let config = SessionConfig {
        tls,
        ..SessionConfig::client(endpoint)
    }
    .to_zenoh(Role::Client)?;
    zenoh::open(config)
        .wait()
        .map_err(anyhow::Error::from_boxed)
}

#[test]
fn only_a_certificate_of_the_fleet_ca_opens_the_link() {
    let dir = temp_dir("security-link");
    let certs = make_certs(&dir, "certs");
    // Another CA, with a robot0 of its own.
    let rogue = make_certs(&dir, "rogue");
    let mapper = guarded_mapper(&dir.join("mapper"), &certs);

    let robot0 = session(&mapper.zenoh, robot_tls(&certs, Some((&certs, "robot0"))));
    assert!(robot0.is_ok(), "robot0's certificate opens the link");
    let none = session(&mapper.zenoh, robot_tls(&certs, None));
    assert!(none.is_err(), "a client without a certificate connected");
    let forged = session(&mapper.zenoh, robot_tls(&certs, Some((&rogue, "robot0"))));
    assert!(forged.is_err(), "another CA's robot0 connected");
    let plain = SessionConfig::client(&mapper.zenoh.replace("tls/", "tcp/"))
        .to_zenoh(Role::Client)
        .map(|config| zenoh::open(config).wait());
    assert!(
        matches!(plain, Ok(Err(_))),
        "plain TCP to the TLS port connected"
    );
    drop(robot0);
    std::fs::remove_dir_all(&dir).ok();
}

/// What robot1 achieved with robot0's keys against one mapper.
#[derive(Debug)]
struct Forgery {
    /// robot0's node, put by robot1 on robot0's key, was mapped.
    node_mapped: bool,
    /// robot1's ack on robot0's ack key reached robot0.
    ack_delivered: bool,
    /// The mapper's acks to robot0 that robot1 received.
    acks_overheard: usize,
    /// robot0 itself, on its own keys: its node mapped and the mapper's ack received.
    robot0_acked: bool,
}

/// robot1 puts robot0's first node on robot0's node key and a forged ack (node 999) on
/// robot0's ack key, and listens to robot0's acks; then robot0 puts the same node itself.
fn forge(mapper: &MapperProcess, certs: &Path) -> Forgery {
    let open = |robot| session(&mapper.zenoh, robot_tls(certs, Some((certs, robot)))).unwrap();
    // robot1 listens on a session of its own: a session's own puts reach its subscribers
    // without the router.
    let (robot0, robot1, robot1_ear) = (open("robot0"), open("robot1"), open("robot1"));
    let (node_key, ack_key) = (
        wire::node_key(FLEET, "robot0").unwrap(),
        wire::ack_key(FLEET, "robot0").unwrap(),
    );
    let acks = robot0.declare_subscriber(&ack_key).wait().unwrap();
    let overheard = robot1_ear.declare_subscriber(&ack_key).wait().unwrap();
    let node = real_nodes(1).remove(0);
    let forged_ack = v1::Ack {
        header: Some(v1::Header::new(FLEET, "robot0", 0, now_ns(), now_ns())),
        acked_node_seq: Some(999),
        chain_id: node.chain_id,
        resend_from: None,
    }
    .encode_to_vec();
    let node = node.encode_to_vec();
    let mut acked = Vec::new();
    let drain = |acked: &mut Vec<u64>| {
        while let Ok(Some(sample)) = acks.try_recv() {
            let ack = wire::decode_ack(&sample.payload().to_bytes()).expect("an ack");
            acked.extend(ack.acked_node_seq);
        }
    };

    // Again and again: a put made before a subscription reached the router is lost.
    let (mut node_mapped, deadline) = (false, Instant::now() + Duration::from_secs(6));
    while Instant::now() < deadline && !(node_mapped && acked.contains(&999)) {
        robot1.put(&node_key, node.clone()).wait().unwrap();
        robot1.put(&ack_key, forged_ack.clone()).wait().unwrap();
        std::thread::sleep(Duration::from_millis(200));
        drain(&mut acked);
        node_mapped = !node_seqs(&mapper.http, FLEET, "robot0").is_empty();
    }
    let ack_delivered = acked.contains(&999);

    let deadline = Instant::now() + Duration::from_secs(30);
    while Instant::now() < deadline && !acked.contains(&0) {
        robot0.put(&node_key, node.clone()).wait().unwrap();
        std::thread::sleep(Duration::from_millis(300));
        drain(&mut acked);
    }
    let robot0_acked = acked.contains(&0) && node_seqs(&mapper.http, FLEET, "robot0") == vec![0];
    // robot1 would have had the same acks by now.
    std::thread::sleep(Duration::from_millis(500));
    let acks_overheard = std::iter::from_fn(|| overheard.try_recv().ok().flatten())
        .filter(|sample| {
            let ack = wire::decode_ack(&sample.payload().to_bytes()).expect("an ack");
            ack.acked_node_seq != Some(999)
        })
        .count();
    Forgery {
        node_mapped,
        ack_delivered,
        acks_overheard,
        robot0_acked,
    }
}

#[test]
fn a_robot_can_neither_publish_as_another_nor_forge_or_overhear_its_acks() {
    let dir = temp_dir("security-acl");
    let certs = make_certs(&dir, "certs");
    let guarded = guarded_mapper(&dir.join("guarded"), &certs);
    let unguarded = unguarded_mapper(&dir.join("unguarded"), &certs);

    let refused = forge(&guarded, &certs);
    assert!(!refused.node_mapped, "{refused:?}");
    assert!(!refused.ack_delivered, "{refused:?}");
    assert_eq!(refused.acks_overheard, 0, "{refused:?}");
    assert!(
        refused.robot0_acked,
        "robot0 itself gets through: {refused:?}"
    );
    let metrics = http_get(&guarded.http, "/metrics").expect("metrics").1;
    assert_eq!(
        metric(&metrics, "levelmap_nodes_accepted_total"),
        1,
        "{metrics}"
    );

    // The same forgeries, over the same TLS but without the list, all go through.
    let accepted = forge(&unguarded, &certs);
    assert!(accepted.node_mapped, "{accepted:?}");
    assert!(accepted.ack_delivered, "{accepted:?}");
    assert!(accepted.acks_overheard > 0, "{accepted:?}");
    assert!(accepted.robot0_acked, "{accepted:?}");
    drop((guarded, unguarded));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_robot_with_its_certificate_is_mapped_over_tls_through_the_list() {
    let dir = temp_dir("security-edge");
    let certs = make_certs(&dir, "certs");
    let mapper = guarded_mapper(&dir.join("mapper"), &certs);
    let source = format!(
        "[zenoh.tls]\nroot_ca = {:?}\ncert = {:?}\nkey = {:?}\n\
         [source.sim]\nloop_index = 0\nduration_s = 40.0\n",
        certs.join("ca.pem"),
        certs.join("robot0.pem"),
        certs.join("robot0.key")
    );
    let edge = spawn_edge_with(&dir, 0, &mapper.zenoh, 4.0, &source);
    let report = edge_report(edge, Duration::from_secs(180));
    let made = report["nodes"].as_u64().expect("nodes made");
    assert!(made >= 5, "{report}");
    assert_eq!(report["outbox_pending"], 0, "{report}");
    assert_eq!(
        node_seqs(&mapper.http, FLEET, "robot0"),
        (0..made).collect::<Vec<_>>(),
        "{report}"
    );
    // The mapper's corrected poses reached the robot (an egress rule of the list).
    assert!(report["map_pose_updates"].as_u64().unwrap() > 0, "{report}");

    // Another robot of the fleet may query the map (ingress query, egress reply).
    let robot1 = session(&mapper.zenoh, robot_tls(&certs, Some((&certs, "robot1")))).unwrap();
    let replies = robot1
        .get(wire::map_key(FLEET, "summary").unwrap())
        .timeout(Duration::from_secs(5))
        .wait()
        .unwrap();
    let reply = replies.recv().expect("a reply to the summary query");
    let body = reply.result().expect("a summary").payload().to_bytes();
    let summary = wire::decode_map_summary(&body).expect("a MapSummary");
    assert_eq!(summary.nodes, made);
    std::fs::remove_dir_all(&dir).ok();
}

/// Runs `levelmap SERVICE --config CONFIG`, which must exit at start: its stderr.
fn refused_at_start(service: &str, config: &Path) -> String {
    let mut child = levelmap()
        .args([service, "--config"])
        .arg(config)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("levelmap starts");
    let deadline = Instant::now() + Duration::from_secs(30);
    let status = loop {
        if let Some(status) = child.try_wait().expect("status") {
            break status;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            panic!(
                "levelmap {service} --config {} kept running",
                config.display()
            );
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let mut stderr = String::new();
    std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut stderr).unwrap();
    assert!(!status.success(), "{stderr}");
    let stderr = stderr.trim_end().to_owned();
    assert_eq!(stderr.lines().count(), 1, "one line: {stderr}");
    stderr
}

#[test]
fn a_bad_tls_setting_stops_a_service_at_start_in_one_line() {
    let dir = temp_dir("security-config");
    let certs = make_certs(&dir, "certs");
    let garbage = dir.join("garbage.pem");
    std::fs::write(
        &garbage,
        "-----BEGIN CERTIFICATE-----\nnot base64 at all!\n",
    )
    .unwrap();
    let missing = certs.join("robot7.pem");
    let store = dir.join("mapper.redb");
    let mapper_with = |zenoh: &str| {
        let path = dir.join("mapper.toml");
        let (http, port) = (free_port(), free_port());
        std::fs::write(
            &path,
            format!(
                "http_listen = \"127.0.0.1:{http}\"\nstore_path = {store:?}\n[zenoh]\n\
                 listen = [\"tls/127.0.0.1:{port}\"]\n{zenoh}"
            ),
        )
        .unwrap();
        path
    };
    let tls = |root_ca: &Path, cert: &Path, key: &Path| {
        format!("[zenoh.tls]\nroot_ca = {root_ca:?}\ncert = {cert:?}\nkey = {key:?}\n")
    };
    let (ca, cert, key) = (
        certs.join("ca.pem"),
        certs.join("mapper.pem"),
        certs.join("mapper.key"),
    );

    let e = refused_at_start("mapper", &mapper_with(&tls(&ca, &missing, &key)));
    assert!(
        e.contains("[zenoh.tls] cert: ") && e.contains("robot7.pem"),
        "{e}"
    );
    let e = refused_at_start("mapper", &mapper_with(&tls(&ca, &cert, &cert)));
    assert!(
        e.contains("[zenoh.tls] key: ") && e.contains("no private key"),
        "{e}"
    );
    let e = refused_at_start("mapper", &mapper_with(&tls(&garbage, &cert, &key)));
    assert!(
        e.contains("[zenoh.tls] root_ca: ") && e.contains("garbage.pem: bad PEM"),
        "{e}"
    );
    let e = refused_at_start("mapper", &mapper_with(""));
    assert!(e.contains("listen endpoint tls/127.0.0.1:"), "{e}");
    assert!(e.contains("needs a certificate and key"), "{e}");
    // A key in the Zenoh file is named with the file.
    let router = std::fs::read_to_string(certs.join("router.json5")).unwrap();
    let broken = dir.join("router.json5");
    let mapper_key = certs.join("mapper.key").display().to_string();
    std::fs::write(
        &broken,
        router.replace(&mapper_key, "/nonexistent/mapper.key"),
    )
    .unwrap();
    let e = refused_at_start(
        "mapper",
        &mapper_with(&format!("config_file = {broken:?}\n")),
    );
    assert!(
        e.contains("transport/link/tls/listen_private_key in ")
            && e.contains("/nonexistent/mapper.key"),
        "{e}"
    );
    // Refused before the store was opened.
    assert!(!store.exists());

    // A robot's link is dialled again and again while the mapper is away; a bad file must
    // stop it instead.
    let edge = dir.join("edge.toml");
    std::fs::write(
        &edge,
        format!(
            "outbox_path = {:?}\n[zenoh]\nconnect = [\"tls/127.0.0.1:{}\"]\n{}",
            dir.join("outbox.redb"),
            free_port(),
            tls(&ca, &certs.join("robot0.pem"), &missing)
        ),
    )
    .unwrap();
    let e = refused_at_start("edge", &edge);
    assert!(
        e.contains("[zenoh.tls] key: ") && e.contains("robot7.pem"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// A mapper host's router as make-certs.sh's router.json5 makes it, listening on a free
/// port of loopback and connected to `others` (the other hosts' routers).
fn host_router(certs: &Path, others: &[String]) -> (zenoh::Session, String) {
    let endpoint = format!("tls/127.0.0.1:{}", free_port());
    let config = SessionConfig {
        listen: Some(vec![endpoint.clone()]),
        connect: Some(others.to_vec()),
        config_file: Some(certs.join("router.json5")),
        ..SessionConfig::default()
    }
    .to_zenoh(Role::Router)
    .expect("router config");
    let session = zenoh::open(config).wait().expect("the router opens");
    (session, endpoint)
}

/// Puts on `from` until `to` hears it (at most 20 s): whether it did.
fn carried(from: &zenoh::Session, to: &zenoh::Session, key: &str) -> bool {
    let heard = to.declare_subscriber(key).wait().unwrap();
    let deadline = Instant::now() + Duration::from_secs(20);
    while Instant::now() < deadline {
        from.put(key, "sample").wait().unwrap();
        std::thread::sleep(Duration::from_millis(200));
        if heard.try_recv().ok().flatten().is_some() {
            return true;
        }
    }
    false
}

#[test]
fn mapper_hosts_routers_carry_each_fleets_robots_between_them_over_tls_and_the_list() {
    let dir = temp_dir("security-mesh");
    let certs = make_certs_for(&dir, "certs", &["robot0", "yard/robot2"]);
    let (first, first_endpoint) = host_router(&certs, &[]);
    let (second, _) = host_router(&certs, std::slice::from_ref(&first_endpoint));
    let dial = |robot| {
        session(&first_endpoint, robot_tls(&certs, Some((&certs, robot)))).expect("robot link")
    };
    let (robot0, robot2) = (dial("robot0"), dial("robot2"));
    for (robot, own) in [
        (&robot0, "levelmap/park/robots/robot0"),
        (&robot2, "levelmap/yard/robots/robot2"),
    ] {
        assert!(
            carried(robot, &second, &format!("{own}/node")),
            "{own}/node, put on the first host's router, reached the second host"
        );
        assert!(
            carried(&second, robot, &format!("{own}/ack")),
            "the second host's ack on {own}/ack reached its robot through the first router"
        );
    }
    // The list still holds across the mesh: robot2, of yard, cannot put as park's robot0.
    let forged = "levelmap/park/robots/robot0/node";
    let heard = second.declare_subscriber(forged).wait().unwrap();
    for _ in 0..10 {
        robot2.put(forged, "forged").wait().unwrap();
        std::thread::sleep(Duration::from_millis(100));
    }
    assert!(
        heard.try_recv().ok().flatten().is_none(),
        "robot2 put on robot0's node key, and the other host heard it"
    );
    assert!(
        carried(&robot0, &second, forged),
        "robot0 itself gets through"
    );
    drop((robot0, robot2, first, second));
    std::fs::remove_dir_all(&dir).ok();
}

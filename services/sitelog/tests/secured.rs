//! NATS secured like the robot link: three servers with TLS on clients and routes,
//! certificates and authorization from `deploy/cluster/make-nats-certs.sh`. A mapper host
//! with its certificate writes and reads a site's log; a client without a certificate, with
//! one from another CA, or with this CA's certificate for a name that is not a mapper host
//! can neither read nor write it. The host's permissions cover the leases' bucket and the
//! nodes' clouds; a gateway's certificate reads the leases and no record.

mod common;

use async_nats::{ConnectOptions, jetstream};
use bytes::Bytes;
use common::{Cluster, TempDir, open_when_ready};
use sitelog::{Appended, CloudRetention, Clouds, Leases, RecordId, RetryPolicy, SiteLog};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

// The leases' bucket as the hosts and gateways name it: auth.conf lets a gateway read it.
use sitelog::LEASES_BUCKET;

fn make_certs(out: &Path, nodes: &str, hosts: &str) {
    make_certs_with_gateways(out, nodes, hosts, None);
}

fn make_certs_with_gateways(out: &Path, nodes: &str, hosts: &str, gateways: Option<&str>) {
    let script =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../deploy/cluster/make-nats-certs.sh");
    testdata::debian::require(&[("openssl", "openssl")]);
    let status = Command::new("bash")
        .arg(&script)
        .arg(out)
        .arg(nodes)
        .arg(hosts)
        .args(gateways)
        .status()
        .expect("run make-nats-certs.sh (bash, openssl)");
    assert!(status.success(), "make-nats-certs.sh failed");
}

/// TLS to the cluster's CA, presenting `name`'s certificate from `dir` if given.
fn tls_options(ca_dir: &Path, client: Option<(&Path, &str)>) -> ConnectOptions {
    let options = ConnectOptions::new()
        .require_tls(true)
        .add_root_certificates(ca_dir.join("ca.pem"))
        .connection_timeout(Duration::from_secs(5));
    match client {
        Some((dir, name)) => options.add_client_certificate(
            dir.join(format!("{name}.pem")),
            dir.join(format!("{name}.key")),
        ),
        None => options,
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn only_a_mapper_host_with_its_certificate_reads_or_writes_a_site_log() {
    let certs = TempDir::new("sitelog-certs");
    make_certs_with_gateways(certs.path(), "n1,n2,n3", "h1,h2", Some("g1"));
    let stranger = TempDir::new("sitelog-other-ca");
    make_certs(stranger.path(), "x1", "h1");
    let cluster = Cluster::start("secured", Some(certs.path()));

    // h1, with its certificate: the site's log opens, takes an append, reads back.
    let started = std::time::Instant::now();
    let h1 = loop {
        match cluster
            .connect_with(tls_options(certs.path(), Some((certs.path(), "h1"))))
            .await
        {
            Ok(client) => break client,
            Err(e) => {
                assert!(
                    started.elapsed() < Duration::from_secs(60),
                    "h1 never connected: {e}"
                );
                eprintln!("waiting for the secured cluster: {e}");
                tokio::time::sleep(Duration::from_millis(500)).await;
            }
        }
    };
    let js = jetstream::new(h1);
    let mut log = open_when_ready(js.clone(), "park").await;
    // Its permissions cover the leases' KV bucket too.
    let leases = Leases::open(&js, LEASES_BUCKET, Duration::from_secs(30), 3)
        .await
        .expect("the leases bucket under h1's permissions");
    assert!(leases.claim("park", "h1").await.unwrap().is_some());
    let id = RecordId::node("r1", 0, 0);
    assert_eq!(
        log.append(&id, Bytes::from_static(b"secret"))
            .await
            .unwrap(),
        Appended::New(1)
    );
    assert_eq!(log.read_from(1).await.unwrap().len(), 1);
    // And the nodes' clouds (levelmap.cloud.*): a put is stored and reads back.
    let clouds = Clouds::open(
        js.clone(),
        3,
        CloudRetention {
            max_age: None,
            max_bytes: None,
        },
    )
    .await
    .expect("the clouds' stream under h1's permissions");
    clouds
        .put("park", 0, Bytes::from_static(b"cloud"))
        .await
        .expect("h1 puts a node's cloud");
    assert_eq!(
        clouds.get("park", 0).await.unwrap().as_deref(),
        Some(&b"cloud"[..])
    );

    let refused: [(&str, ConnectOptions); 3] = [
        ("no client certificate", tls_options(certs.path(), None)),
        (
            "h1's name on another CA's certificate",
            tls_options(certs.path(), Some((stranger.path(), "h1"))),
        ),
        (
            "this CA's certificate for a server, not a mapper host",
            tls_options(certs.path(), Some((certs.path(), "n1"))),
        ),
    ];
    for (who, options) in refused {
        match cluster.connect_with(options).await {
            Err(e) => eprintln!("{who}: refused at connect ({e})"),
            Ok(client) => {
                // Connected: then every read and write of the log must fail.
                let js = jetstream::new(client);
                let retry = RetryPolicy {
                    deadline: Duration::from_secs(2),
                    ..Default::default()
                };
                match SiteLog::open(js.clone(), "park", 3, retry).await {
                    Ok(mut log) => {
                        let appended = log.append(&RecordId::node("r9", 0, 0), Bytes::new()).await;
                        panic!("{who}: opened the site's log (append: {appended:?})");
                    }
                    Err(e) => eprintln!("{who}: connected, log refused ({e})"),
                }
                let publish = js
                    .publish("levelmap.site.park.log", Bytes::from_static(b"forged"))
                    .await;
                let stored = match publish {
                    Ok(ack) => ack.await.is_ok(),
                    Err(_) => false,
                };
                assert!(!stored, "{who}: appended to the site's log");
            }
        }
    }
    // A gateway, with its certificate: it sees who holds the site and that its log exists,
    // and can neither read the log's records nor write anything.
    let g1 = cluster
        .connect_with(tls_options(certs.path(), Some((certs.path(), "g1"))))
        .await
        .expect("g1 connects");
    let js = jetstream::new(g1);
    let seen = Leases::existing(&js, LEASES_BUCKET)
        .await
        .expect("the gateway opens the leases");
    assert_eq!(seen.holder("park").await.unwrap().as_deref(), Some("h1"));
    // A free site: the claim's write is refused (a held one reads as held).
    assert!(
        seen.claim("campus", "g1").await.is_err(),
        "a gateway claims nothing"
    );
    assert!(sitelog::log_exists(&js, "park").await.unwrap());
    assert!(!sitelog::log_exists(&js, "nowhere").await.unwrap());
    let stream = js.get_stream("LEVELMAP_SITE_park").await.expect("info");
    assert!(
        stream.get_raw_message(1).await.is_err(),
        "a gateway read a record of the site's log"
    );
    let forged = match js
        .publish("levelmap.site.park.log", Bytes::from_static(b"forged"))
        .await
    {
        Ok(ack) => ack.await.is_ok(),
        Err(_) => false,
    };
    assert!(!forged, "a gateway appended to the site's log");
    // Nothing but h1's record is in the log.
    let entries = log.read_from(1).await.unwrap();
    assert_eq!(entries.len(), 1, "{entries:?}");
    assert_eq!(entries[0].id, id.as_str());
}

/// `deploy/cluster/nats{1,2,3}.conf`, with the certificates make-nats-certs.sh makes for
/// nats1–nats3 in place of `/etc/levelmap/nats/`: nats-server's own check (`-t`) takes each.
#[test]
fn the_deployed_server_configs_are_valid() {
    let dir = TempDir::new("sitelog-deploy");
    make_certs(dir.path(), "nats1,nats2,nats3", "h1,h2,h3");
    let deploy = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../deploy/cluster");
    for i in 1..=3 {
        let text = std::fs::read_to_string(deploy.join(format!("nats{i}.conf")))
            .expect("a deployed config");
        assert!(text.contains("sync_interval: always"), "nats{i}.conf");
        assert!(
            text.contains("http: 127.0.0.1:8222"),
            "nats{i}.conf: its monitoring"
        );
        // The unit's credential (deploy/systemd/levelmap-nats@.service) is the node's key.
        let credential = format!("/run/credentials/levelmap-nats@nats{i}.service/nats.key");
        assert!(
            text.contains(&credential),
            "nats{i}.conf: its key as the unit's credential"
        );
        let key = dir.path().join(format!("nats{i}.key"));
        let text = text
            .replace(&credential, &key.display().to_string())
            .replace("/etc/levelmap/nats/", &format!("{}/", dir.path().display()))
            .replace(
                "/var/lib/levelmap-nats",
                &dir.path().join("store").display().to_string(),
            );
        let config = dir.path().join(format!("nats{i}.conf"));
        std::fs::write(&config, text).expect("write");
        let out = Command::new(common::nats_server())
            .arg("-c")
            .arg(&config)
            .arg("-t")
            .output()
            .expect("run nats-server -t");
        assert!(
            out.status.success(),
            "nats{i}.conf: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
}

//! The session's configuration: keys, files, TLS checks, environment overrides.

use super::*;
use std::path::Path;

// Well-formed PEM around meaningless bytes: what is checked at start is the files, not
// the cryptography (rustls does that when a link opens).
const CERT: &str = "-----BEGIN CERTIFICATE-----\nMIIBozCCAUmgAwIBAgIU\n-----END CERTIFICATE-----\n";
const KEY: &str = "-----BEGIN PRIVATE KEY-----\nMIGHAgEAMBMGByqGSM49\n-----END PRIVATE KEY-----\n";

struct Dir(PathBuf);

impl Dir {
    fn new(name: &str) -> Dir {
        let dir =
            std::env::temp_dir().join(format!("runtime-session-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        Dir(dir)
    }

    fn file(&self, name: &str, text: &str) -> PathBuf {
        let path = self.0.join(name);
        std::fs::write(&path, text).unwrap();
        path
    }
}

impl Drop for Dir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn value(config: &zenoh::Config, key: &str) -> serde_json::Value {
    serde_json::from_str(&config.get_json(key).unwrap()).unwrap()
}

fn error(config: &SessionConfig, role: Role) -> String {
    let e = config.to_zenoh(role).expect_err("a bad setting is refused");
    let message = format!("{e:#}");
    assert!(!message.contains('\n'), "one line: {message}");
    message
}

#[test]
fn unset_keys_take_the_defaults_of_the_role() {
    let router = SessionConfig::default().to_zenoh(Role::Router).unwrap();
    assert_eq!(value(&router, "mode"), "router");
    assert_eq!(
        value(&router, "listen/endpoints"),
        serde_json::json!(["tcp/0.0.0.0:7447"])
    );
    assert_eq!(value(&router, "connect/endpoints"), serde_json::json!([]));
    assert_eq!(value(&router, "scouting/multicast/enabled"), false);
    let client = SessionConfig::default().to_zenoh(Role::Client).unwrap();
    assert_eq!(value(&client, "mode"), "client");
    assert_eq!(
        value(&client, "connect/endpoints"),
        serde_json::json!(["tcp/127.0.0.1:7447"])
    );
    assert_eq!(value(&client, "scouting/multicast/enabled"), false);
    assert_eq!(
        value(&client, "transport/link/rx/max_message_size"),
        MAX_MESSAGE_BYTES
    );
    // No TLS unless asked for.
    assert_eq!(
        value(&client, "transport/link/tls/enable_mtls"),
        serde_json::Value::Null
    );
}

#[test]
fn the_deploy_files_state_the_session_defaults_in_their_comments() {
    for (file, role) in [("edge.toml", Role::Client), ("mapper.toml", Role::Router)] {
        let path = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../deploy")
            .join(file);
        let text = std::fs::read_to_string(&path).unwrap();
        // The [zenoh] table with its commented session keys set as written.
        let mut section = "";
        let stated: String = text
            .lines()
            .map(|line| {
                if line.starts_with('[') {
                    section = line;
                }
                let key = line.trim_start_matches("# ").split(" = ").next().unwrap();
                let session_key =
                    ["mode", "listen", "connect", "multicast_scouting"].contains(&key);
                match line.strip_prefix("# ") {
                    Some(setting) if section == "[zenoh]" && session_key => setting,
                    _ => line,
                }
            })
            .collect::<Vec<_>>()
            .join("\n");
        let table: toml::Table = toml::from_str(&stated).unwrap();
        let stated: SessionConfig = table["zenoh"].clone().try_into().unwrap();
        assert!(
            stated.mode.is_some() && stated.multicast_scouting.is_some(),
            "{file}"
        );
        let (stated, default) = (
            stated.to_zenoh(role).unwrap(),
            SessionConfig::default().to_zenoh(role).unwrap(),
        );
        for key in [
            "mode",
            "listen/endpoints",
            "connect/endpoints",
            "scouting/multicast/enabled",
        ] {
            assert_eq!(value(&stated, key), value(&default, key), "{file}: {key}");
        }
    }
}

#[test]
fn the_file_sets_what_the_table_leaves_unset_and_the_table_wins() {
    let dir = Dir::new("merge");
    let file = dir.file(
        "zenoh.json5",
        r#"{ mode: "router", listen: { endpoints: ["tcp/127.0.0.1:7999"] },
             scouting: { multicast: { enabled: true } }, queries_default_timeout: 1234 }"#,
    );
    let from_file = SessionConfig {
        config_file: Some(file.clone()),
        ..SessionConfig::default()
    };
    // The file's mode beats the role's; a router's connect default follows.
    let config = from_file.to_zenoh(Role::Client).unwrap();
    assert_eq!(value(&config, "mode"), "router");
    assert_eq!(
        value(&config, "listen/endpoints"),
        serde_json::json!(["tcp/127.0.0.1:7999"])
    );
    assert_eq!(value(&config, "connect/endpoints"), serde_json::json!([]));
    assert_eq!(value(&config, "scouting/multicast/enabled"), true);
    assert_eq!(value(&config, "queries_default_timeout"), 1234);

    let over = SessionConfig {
        mode: Some("peer".into()),
        listen: Some(vec!["tcp/127.0.0.1:7000".into()]),
        multicast_scouting: Some(false),
        ..from_file
    };
    let config = over.to_zenoh(Role::Client).unwrap();
    assert_eq!(value(&config, "mode"), "peer");
    assert_eq!(
        value(&config, "listen/endpoints"),
        serde_json::json!(["tcp/127.0.0.1:7000"])
    );
    assert_eq!(value(&config, "scouting/multicast/enabled"), false);
    assert_eq!(value(&config, "queries_default_timeout"), 1234);
}

#[test]
fn tls_files_become_zenoh_keys_with_mutual_tls() {
    let dir = Dir::new("tls");
    let tls = TlsConfig {
        root_ca: Some(dir.file("ca.pem", CERT)),
        cert: Some(dir.file("me.pem", CERT)),
        key: Some(dir.file("me.key", KEY)),
    };
    let config = SessionConfig {
        listen: Some(vec!["tls/127.0.0.1:7447".into()]),
        tls: tls.clone(),
        ..SessionConfig::default()
    }
    .to_zenoh(Role::Router)
    .unwrap();
    let path = |p: &Option<PathBuf>| serde_json::json!(p.as_ref().unwrap().to_str().unwrap());
    for (key, file) in [
        ("root_ca_certificate", &tls.root_ca),
        ("listen_certificate", &tls.cert),
        ("connect_certificate", &tls.cert),
        ("listen_private_key", &tls.key),
        ("connect_private_key", &tls.key),
    ] {
        assert_eq!(value(&config, &format!("{TLS}/{key}")), path(file), "{key}");
    }
    assert_eq!(value(&config, &format!("{TLS}/enable_mtls")), true);
}

#[test]
fn a_bad_tls_setting_is_one_line_naming_the_key_and_file() {
    let dir = Dir::new("bad");
    let (ca, cert, key) = (
        dir.file("ca.pem", CERT),
        dir.file("me.pem", CERT),
        dir.file("me.key", KEY),
    );
    let with = |root_ca: &Path, cert: &Path, key: &Path| SessionConfig {
        connect: Some(vec!["tls/127.0.0.1:7447".into()]),
        tls: TlsConfig {
            root_ca: Some(root_ca.into()),
            cert: Some(cert.into()),
            key: Some(key.into()),
        },
        ..SessionConfig::default()
    };
    let missing = dir.0.join("missing.pem");
    let e = error(&with(&ca, &missing, &key), Role::Client);
    assert!(
        e.starts_with("[zenoh.tls] cert: ") && e.contains(&*missing.to_string_lossy()),
        "{e}"
    );
    assert!(e.contains("cannot read it"), "{e}");

    let e = error(&with(&ca, &cert, &cert), Role::Client);
    assert!(
        e.starts_with("[zenoh.tls] key: ") && e.contains("no private key"),
        "{e}"
    );
    let garbage = dir.file("garbage.pem", "not a certificate\n");
    let e = error(&with(&garbage, &cert, &key), Role::Client);
    assert!(
        e.starts_with("[zenoh.tls] root_ca: ") && e.contains("no certificate"),
        "{e}"
    );
    let cut = dir.file("cut.pem", &CERT[..CERT.len() - 30]);
    let e = error(&with(&ca, &cut, &key), Role::Client);
    assert!(e.contains("cut.pem: bad PEM"), "{e}");

    let half = SessionConfig {
        tls: TlsConfig {
            cert: Some(cert.clone()),
            ..TlsConfig::default()
        },
        ..SessionConfig::default()
    };
    assert_eq!(
        error(&half, Role::Client),
        "[zenoh.tls] cert is set without key"
    );

    let bare = SessionConfig {
        listen: Some(vec!["tls/0.0.0.0:7447".into()]),
        ..SessionConfig::default()
    };
    let e = error(&bare, Role::Router);
    assert!(
        e.starts_with("listen endpoint tls/0.0.0.0:7447 needs a certificate and key"),
        "{e}"
    );
    let no_ca = SessionConfig {
        tls: TlsConfig {
            root_ca: None,
            ..with(&ca, &cert, &key).tls
        },
        ..bare
    };
    let e = error(&no_ca, Role::Router);
    assert!(e.contains("mutual TLS needs the CA"), "{e}");

    // Keys set in the config file are named with the file.
    let file = dir.file(
        "zenoh.json5",
        &format!(
            r#"{{ transport: {{ link: {{ tls: {{ listen_certificate: "{}", listen_private_key: "{}" }} }} }} }}"#,
            missing.display(),
            key.display()
        ),
    );
    let from_file = SessionConfig {
        config_file: Some(file.clone()),
        ..SessionConfig::default()
    };
    let e = error(&from_file, Role::Router);
    assert!(
        e.starts_with(&format!(
            "{TLS}/listen_certificate in {}: {}",
            file.display(),
            missing.display()
        )),
        "{e}"
    );
    let e = error(
        &SessionConfig {
            config_file: Some(dir.0.join("none.json5")),
            ..SessionConfig::default()
        },
        Role::Router,
    );
    assert!(
        e.starts_with("[zenoh] config_file ") && e.contains("none.json5"),
        "{e}"
    );
    let broken = dir.file("broken.json5", "{ mode: \"router\",\n");
    let e = error(
        &SessionConfig {
            config_file: Some(broken),
            ..SessionConfig::default()
        },
        Role::Router,
    );
    assert!(
        e.starts_with("[zenoh] config_file ") && !e.contains(".rs:"),
        "{e}"
    );
    let typo = SessionConfig {
        mode: Some("routr".into()),
        ..SessionConfig::default()
    };
    assert_eq!(
        error(&typo, Role::Router),
        r#"[zenoh] mode "routr": one of "router", "peer", "client""#
    );
}

/// A SIGTERM sent after the call, before the future is awaited (a service still starting),
/// is caught: the process is not killed, and the wait ends.
#[tokio::test]
async fn a_stop_signal_sent_before_the_wait_is_caught() {
    let stop = shutdown_signal();
    let me = std::process::id().to_string();
    let sent = std::process::Command::new("kill")
        .args(["-TERM", &me])
        .status()
        .expect("kill runs");
    assert!(sent.success());
    tokio::time::timeout(std::time::Duration::from_secs(5), stop)
        .await
        .expect("the SIGTERM ended the wait");
}

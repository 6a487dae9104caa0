//! Config keys set from the environment: `LEVELMAP_<KEY>`, `__` between nested keys
//! (`LEVELMAP_ZENOH__CONNECT='["tcp/10.0.0.1:7447"]'` sets `connect` in `[zenoh]`). They are
//! applied to the TOML table before it is deserialized, so each key's type and the checks for
//! unknown keys hold as they do in the file. Pure: the environment is a parameter.

use std::ffi::OsString;
use toml::{Table, Value};

/// The prefix of the variables that set config keys.
pub const ENV_PREFIX: &str = "LEVELMAP_";

/// `LEVELMAP_…` variables that are not config keys: the test data's folder and list, the
/// scripts' shared folder, the dashboard's files, binary, artifacts and URL, the kill-loop
/// drill's seed. The certificate scripts' variables are `MAKE_CERTS_…`, not these. They are never
/// taken as keys, so the services start in the shells and CI jobs that set them.
pub const NOT_CONFIG_VARS: &[&str] = &[
    "LEVELMAP_DATA",
    "LEVELMAP_DATA_LIST",
    "LEVELMAP_SHARED",
    "LEVELMAP_WEB_DIR",
    "LEVELMAP_WEB_ARTIFACTS",
    "LEVELMAP_BIN",
    "LEVELMAP_URL",
    "LEVELMAP_DRILL_SEED",
];

/// One config key set from the environment.
#[derive(Clone, Debug, PartialEq)]
pub struct EnvOverride {
    /// The variable, e.g. `LEVELMAP_ZENOH__CONNECT`.
    pub var: String,
    /// The key's path, e.g. `["zenoh", "connect"]`.
    pub path: Vec<String>,
    /// The variable's value as given.
    pub raw: String,
}

impl EnvOverride {
    /// The key as the TOML file writes it, e.g. `zenoh.connect`.
    pub fn dotted(&self) -> String {
        self.path.join(".")
    }
}

/// The config keys among `vars`: every `LEVELMAP_…` variable but [`NOT_CONFIG_VARS`], sorted
/// by name. A variable that names no key (an empty part, a name or value that is not UTF-8)
/// is an error.
pub fn env_overrides(
    vars: impl IntoIterator<Item = (OsString, OsString)>,
) -> anyhow::Result<Vec<EnvOverride>> {
    let mut found = Vec::new();
    for (name, value) in vars {
        let Some(name) = name.to_str() else {
            anyhow::ensure!(
                !name.to_string_lossy().starts_with(ENV_PREFIX),
                "{}: not UTF-8",
                name.to_string_lossy()
            );
            continue;
        };
        let Some(key) = name.strip_prefix(ENV_PREFIX) else {
            continue;
        };
        if NOT_CONFIG_VARS.contains(&name) {
            continue;
        }
        let raw = value
            .into_string()
            .map_err(|_| anyhow::anyhow!("{name}: its value is not UTF-8"))?;
        let path: Vec<String> = key.split("__").map(str::to_ascii_lowercase).collect();
        anyhow::ensure!(
            path.iter().all(|p| !p.is_empty()),
            "{name} names no config key (`__` separates nested keys: LEVELMAP_ZENOH__CONNECT)"
        );
        found.push(EnvOverride {
            var: name.to_owned(),
            path,
            raw,
        });
    }
    found.sort_by(|a, b| a.var.cmp(&b.var));
    Ok(found)
}

/// Sets each override in `table`. The value is read as a TOML value where it parses as one
/// (numbers, booleans, arrays, inline tables), else taken as a string; where the key holds a
/// string (in `table`, else in `defaults`), it is a string either way, so `LEVELMAP_ROBOT=007`
/// stays `"007"`. A table on the path that `table` lacks is taken from `defaults`: a nested
/// struct's missing keys would otherwise get that struct's own defaults, not the service's
/// (`LEVELMAP_ZENOH__LISTEN` alone must leave the mapper a router). A path through a value
/// that is not a table is an error.
pub fn apply_overrides(
    table: &mut Table,
    defaults: &Table,
    overrides: &[EnvOverride],
) -> anyhow::Result<()> {
    for o in overrides {
        let holds_string = matches!(
            lookup(table, &o.path).or_else(|| lookup(defaults, &o.path)),
            Some(Value::String(_))
        );
        let value = match o.raw.parse::<Value>() {
            Ok(Value::String(s)) => Value::String(s),
            Ok(_) | Err(_) if holds_string => Value::String(o.raw.clone()),
            Ok(v) => v,
            Err(_) => Value::String(o.raw.clone()),
        };
        let (last, parents) = o.path.split_last().expect("paths are not empty");
        let mut at = &mut *table;
        for (depth, part) in parents.iter().enumerate() {
            let next = at.entry(part.clone()).or_insert_with(|| {
                match lookup(defaults, &o.path[..=depth]) {
                    Some(Value::Table(t)) => Value::Table(t.clone()),
                    _ => Value::Table(Table::new()),
                }
            });
            at = next.as_table_mut().ok_or_else(|| {
                anyhow::anyhow!("{}: {} is not a table", o.var, o.path[..=depth].join("."))
            })?;
        }
        at.insert(last.clone(), value);
    }
    Ok(())
}

/// Checks that each override reached the config: `config` is the deserialized config
/// serialized again, so a key its type ignores (one not denied as unknown) is missing there.
/// (A field that skips itself when serialized while unset, as `[zenoh]`'s optional keys do, is
/// set by its override, so it is there.)
pub fn check_taken(config: &Table, overrides: &[EnvOverride]) -> anyhow::Result<()> {
    for o in overrides {
        anyhow::ensure!(
            lookup(config, &o.path).is_some(),
            "{} names no config key ({} is not one)",
            o.var,
            o.dotted()
        );
    }
    Ok(())
}

fn lookup<'a>(table: &'a Table, path: &[String]) -> Option<&'a Value> {
    let (first, rest) = path.split_first()?;
    let value = table.get(first)?;
    if rest.is_empty() {
        return Some(value);
    }
    lookup(value.as_table()?, rest)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Exported in an operator's shell, a script's variable must not stop a service: every
    /// `LEVELMAP_…` name the shipped scripts and the CI read is one the loader leaves alone.
    #[test]
    fn the_scripts_read_no_variable_the_services_take_for_a_key() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
        let mut read = Vec::new();
        for dir in ["deploy", "deploy/zenoh", "deploy/cluster", "scripts", ".ci"] {
            for entry in std::fs::read_dir(root.join(dir)).unwrap() {
                let path = entry.unwrap().path();
                if !path.is_file() {
                    continue;
                }
                let Ok(text) = std::fs::read_to_string(&path) else {
                    continue;
                };
                for (i, _) in text.match_indices("${LEVELMAP_") {
                    let name: String = text[i + 2..]
                        .chars()
                        .take_while(|c| c.is_ascii_uppercase() || *c == '_')
                        .collect();
                    read.push((path.display().to_string(), name));
                }
            }
        }
        assert!(
            !read.is_empty(),
            "no script reads LEVELMAP_DATA: the scan is broken"
        );
        let taken: Vec<_> = read
            .iter()
            .filter(|(_, name)| !NOT_CONFIG_VARS.contains(&name.as_str()))
            .collect();
        assert!(
            taken.is_empty(),
            "read by scripts, taken as config keys: {taken:?}"
        );
    }

    fn vars(pairs: &[(&str, &str)]) -> Vec<(OsString, OsString)> {
        pairs
            .iter()
            .map(|(k, v)| (OsString::from(k), OsString::from(v)))
            .collect()
    }

    fn applied(file: &str, defaults: &str, env: &[(&str, &str)]) -> anyhow::Result<Table> {
        let mut table: Table = toml::from_str(file).unwrap();
        let defaults: Table = toml::from_str(defaults).unwrap();
        apply_overrides(&mut table, &defaults, &env_overrides(vars(env))?)?;
        Ok(table)
    }

    #[test]
    fn names_become_lowercase_paths_split_on_double_underscores() {
        let found = env_overrides(vars(&[
            ("PATH", "/bin"),
            ("LEVELMAP_ZENOH__CONNECT", "[]"),
            ("LEVELMAP_HTTP_LISTEN", "0.0.0.0:8080"),
            ("LEVELMAP_DATA", "../shared/data"),
        ]))
        .unwrap();
        let paths: Vec<(&str, String)> = found.iter().map(|o| (&o.var[..], o.dotted())).collect();
        assert_eq!(
            paths,
            [
                ("LEVELMAP_HTTP_LISTEN", "http_listen".to_owned()),
                ("LEVELMAP_ZENOH__CONNECT", "zenoh.connect".to_owned())
            ]
        );
    }

    #[test]
    fn an_empty_part_names_no_key() {
        for name in ["LEVELMAP_", "LEVELMAP_ZENOH__", "LEVELMAP_A____B"] {
            let e = env_overrides(vars(&[(name, "1")])).unwrap_err();
            assert!(e.to_string().contains(name), "{e}");
        }
    }

    #[test]
    fn values_are_toml_where_they_parse_and_strings_elsewhere() {
        let t = applied(
            "",
            "",
            &[
                ("LEVELMAP_SOLVE_INTERVAL_MS", "250"),
                ("LEVELMAP_MAX_RANGE_M", "35.5"),
                ("LEVELMAP_LINGER_FOR_ACKS", "false"),
                ("LEVELMAP_ZENOH__CONNECT", r#"["tcp/10.0.0.1:7447"]"#),
                ("LEVELMAP_HTTP_LISTEN", "0.0.0.0:8080"),
                ("LEVELMAP_TOKEN", ""),
                (
                    "LEVELMAP_DATUM",
                    "{ latitude_deg = 52.39, longitude_deg = 9.71 }",
                ),
            ],
        )
        .unwrap();
        let expected: Table = toml::from_str(
            r#"
            solve_interval_ms = 250
            max_range_m = 35.5
            linger_for_acks = false
            http_listen = "0.0.0.0:8080"
            token = ""
            datum = { latitude_deg = 52.39, longitude_deg = 9.71 }
            [zenoh]
            connect = ["tcp/10.0.0.1:7447"]
            "#,
        )
        .unwrap();
        assert_eq!(t, expected);
    }

    #[test]
    fn a_key_that_holds_a_string_takes_the_text_as_it_is() {
        let t = applied(
            "fleet = \"park\"",
            "robot = \"robot0\"",
            &[
                ("LEVELMAP_ROBOT", "007"),
                ("LEVELMAP_FLEET", "true"),
                ("LEVELMAP_OUTBOX_PATH", "\"quoted.redb\""),
            ],
        )
        .unwrap();
        assert_eq!(t["robot"].as_str(), Some("007"));
        assert_eq!(t["fleet"].as_str(), Some("true"));
        // A quoted TOML string is read as one.
        assert_eq!(t["outbox_path"].as_str(), Some("quoted.redb"));
    }

    #[test]
    fn the_environment_wins_over_the_file_and_keeps_its_siblings() {
        let t = applied(
            "[zenoh]\nmode = \"client\"\nconnect = [\"tcp/a:1\"]",
            "",
            &[("LEVELMAP_ZENOH__CONNECT", r#"["tcp/b:2"]"#)],
        )
        .unwrap();
        assert_eq!(t["zenoh"]["mode"].as_str(), Some("client"));
        assert_eq!(t["zenoh"]["connect"][0].as_str(), Some("tcp/b:2"));
    }

    #[test]
    fn a_table_the_file_lacks_starts_from_the_defaults() {
        let defaults = "[zenoh]\nmode = \"router\"\nlisten = [\"tcp/0.0.0.0:7447\"]";
        let env = [("LEVELMAP_ZENOH__LISTEN", r#"["tcp/10.0.0.1:7447"]"#)];
        let t = applied("", defaults, &env).unwrap();
        assert_eq!(t["zenoh"]["mode"].as_str(), Some("router"));
        assert_eq!(t["zenoh"]["listen"][0].as_str(), Some("tcp/10.0.0.1:7447"));
        // A table the file has is the file's.
        let t = applied("[zenoh]\nmode = \"peer\"", defaults, &env).unwrap();
        assert_eq!(t["zenoh"].as_table().unwrap().len(), 2);
        assert_eq!(t["zenoh"]["mode"].as_str(), Some("peer"));
    }

    #[test]
    fn a_path_through_a_value_is_an_error() {
        let e = applied("token = \"x\"", "", &[("LEVELMAP_TOKEN__INNER", "1")]).unwrap_err();
        assert_eq!(e.to_string(), "LEVELMAP_TOKEN__INNER: token is not a table");
    }

    #[test]
    fn a_key_the_config_dropped_is_named() {
        let overrides = env_overrides(vars(&[
            ("LEVELMAP_MAPPING__ODOMETRY_SIGMA", "1"),
            ("LEVELMAP_TOKEN", "t"),
        ]))
        .unwrap();
        let config: Table = toml::from_str("token = \"t\"\n[mapping]\nx = 1").unwrap();
        let e = check_taken(&config, &overrides).unwrap_err();
        assert_eq!(
            e.to_string(),
            "LEVELMAP_MAPPING__ODOMETRY_SIGMA names no config key (mapping.odometry_sigma is not one)"
        );
    }
}

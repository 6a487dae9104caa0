//! The one configuration loader of levelmap's services: a service's TOML file (none: every
//! key at its default), then the `LEVELMAP_…` variables of the environment ([`mod@env`]).
//! Pure but for the file and the environment it is given; no Zenoh, no Tokio, so the
//! cluster's gateway loads its file as the mapper and the edge do.

use serde::Serialize;
use serde::de::DeserializeOwned;
use std::path::Path;

pub mod env;
#[cfg(feature = "testing")]
pub mod typos;

/// Reads a service's config: its TOML file (none: every key at its default), then the
/// `LEVELMAP_…` variables of the environment ([`mod@env`]). Unknown keys are errors, in the file
/// when `T` denies them, in the environment always (a typo must not silently become a
/// default). Errors name the file or the variable.
pub fn load_toml<T>(path: Option<&Path>) -> anyhow::Result<T>
where
    T: DeserializeOwned + Serialize + Default,
{
    load_toml_with(path, std::env::vars_os())
}

/// [`load_toml`] with the environment given: `vars` as `std::env::vars_os` yields them.
pub fn load_toml_with<T>(
    path: Option<&Path>,
    vars: impl IntoIterator<Item = (std::ffi::OsString, std::ffi::OsString)>,
) -> anyhow::Result<T>
where
    T: DeserializeOwned + Serialize + Default,
{
    let overrides = env::env_overrides(vars)?;
    let mut table = match path {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
            // The file alone first: its errors keep their line and column.
            let alone: T =
                toml::from_str(&text).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
            if overrides.is_empty() {
                return Ok(alone);
            }
            toml::from_str::<toml::Table>(&text)?
        }
        None => toml::Table::new(),
    };
    let defaults = toml::Table::try_from(T::default())?;
    env::apply_overrides(&mut table, &defaults, &overrides)?;
    let vars: Vec<&str> = overrides.iter().map(|o| o.var.as_str()).collect();
    let origin = match path {
        Some(path) => format!("{} with {}", path.display(), vars.join(", ")),
        None => vars.join(", "),
    };
    let config: T = toml::Value::Table(table)
        .try_into()
        .map_err(|e| anyhow::anyhow!("{origin}: {e}"))?;
    env::check_taken(&toml::Table::try_from(&config)?, &overrides)?;
    Ok(config)
}

/// The line (from 1) of the key at `path` (`["source", "mcap", "cloud_topc"]`) in the TOML
/// `text`: for the errors of checks made after the file is read.
pub fn line_of(text: &str, path: &[&str]) -> Option<usize> {
    let root = toml::de::DeTable::parse(text).ok()?;
    let mut table = root.get_ref();
    let mut start = None;
    for (depth, key) in path.iter().enumerate() {
        let (name, value) = table.iter().find(|(name, _)| name.get_ref() == key)?;
        start = Some(name.span().start);
        if depth + 1 < path.len() {
            match value.get_ref() {
                toml::de::DeValue::Table(inner) => table = inner,
                _ => return None,
            }
        }
    }
    Some(text[..start?].matches('\n').count() + 1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_keys_line_is_found_in_tables_and_dotted_headers() {
        let text = "fleet = \"park\"\n\n[source.mcap]\npath = \"a.mcap\"\ncloud_topc = \"/x\"\n";
        assert_eq!(line_of(text, &["fleet"]), Some(1));
        assert_eq!(line_of(text, &["source", "mcap", "cloud_topc"]), Some(5));
        assert_eq!(line_of(text, &["source", "mcap", "nothing"]), None);
    }
}

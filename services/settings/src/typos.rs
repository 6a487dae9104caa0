//! For the services' tests: a file per table of a config, each with one misspelt key, so a
//! test can check that every table refuses it (feature `testing`).

use serde::Serialize;

/// The key the files misspell.
pub const MISSPELT: &str = "misspelt_key";

/// One TOML text per table of `T`'s defaults (nested ones too, by their dotted path; `""` is
/// the top level) and per table of `absent` (tables the defaults leave out, such as an unset
/// `[cluster]`), each holding only [`MISSPELT`] in that table.
pub fn misspelt_files<T: Serialize + Default>(absent: &[&str]) -> Vec<(String, String)> {
    let defaults = toml::Table::try_from(T::default()).expect("the defaults serialize");
    let mut paths = vec![String::new()];
    collect(&defaults, "", &mut paths);
    paths.extend(absent.iter().map(|p| p.to_string()));
    paths
        .into_iter()
        .map(|path| {
            let text = if path.is_empty() {
                format!("{MISSPELT} = 1\n")
            } else {
                format!("[{path}]\n{MISSPELT} = 1\n")
            };
            (path, text)
        })
        .collect()
}

fn collect(table: &toml::Table, prefix: &str, out: &mut Vec<String>) {
    for (key, value) in table {
        if let toml::Value::Table(inner) = value {
            let path = if prefix.is_empty() {
                key.clone()
            } else {
                format!("{prefix}.{key}")
            };
            out.push(path.clone());
            collect(inner, &path, out);
        }
    }
}

/// Panics unless `error` (a load's, of `file` with [`misspelt_files`]'s text for `table`)
/// names the file, the line, the misspelt key and what was expected instead.
pub fn assert_refused(table: &str, file: &std::path::Path, error: &str) {
    let file = file.display().to_string();
    assert!(
        error.contains(&file)
            && error.contains("line")
            && error.contains(MISSPELT)
            && error.contains("expected"),
        "[{table}]: a misspelt key's error must name the file, the line, the key and the keys \
         expected: {error}"
    );
}

/// Writes each of [`misspelt_files`]'s files for `T` in a scratch folder and loads it with
/// `load`: every one must be refused as [`assert_refused`] says. Panics naming the table that
/// took a misspelt key. `min_tables` guards the walk itself (a config whose defaults
/// serialize to fewer tables than that is a broken walk, not a pass).
pub fn assert_every_table_refuses<T, C>(
    absent: &[&str],
    min_tables: usize,
    load: impl Fn(&std::path::Path) -> anyhow::Result<C>,
) where
    T: Serialize + Default,
{
    let dir = std::env::temp_dir().join(format!(
        "settings-typos-{}-{}",
        std::any::type_name::<T>().replace("::", "-"),
        std::process::id()
    ));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("config.toml");
    let files = misspelt_files::<T>(absent);
    assert!(files.len() >= min_tables, "{files:?}");
    for (table, text) in files {
        std::fs::write(&path, text).unwrap();
        let error = match load(&path) {
            Ok(_) => panic!("[{table}] took a misspelt key"),
            Err(e) => format!("{e:#}"),
        };
        assert_refused(&table, &path, &error);
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

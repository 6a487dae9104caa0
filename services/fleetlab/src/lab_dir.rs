//! The folder of a lab run (`--dir`): its stores, configs and logs. A run empties it first,
//! but only a folder levelmap made: one holding [`MARKER`], or a new or empty one. Anything
//! else (`--dir .`, `--dir ~/maps`) is refused and left as it is.

use anyhow::{Context, Result, bail};
use std::path::Path;

/// The file that marks a folder as a lab run's, to be emptied by the next run.
pub const MARKER: &str = ".levelmap-lab";

/// Makes `dir` an empty lab folder (with its marker): created if missing, emptied if it holds
/// the marker. Refuses a file, or a folder with anything in it but no marker.
pub fn prepare(dir: &Path) -> Result<()> {
    if dir.exists() {
        if !dir.is_dir() {
            bail!("--dir {}: not a folder", dir.display());
        }
        let marked = dir.join(MARKER).is_file();
        let empty = std::fs::read_dir(dir)
            .with_context(|| format!("--dir {}: cannot list", dir.display()))?
            .next()
            .is_none();
        if !marked && !empty {
            bail!(
                "--dir {}: the folder holds files levelmap did not make (no {MARKER} in it); \
                 refusing to empty it: name a new or empty folder",
                dir.display()
            );
        }
        if marked {
            std::fs::remove_dir_all(dir)
                .with_context(|| format!("--dir {}: cannot empty", dir.display()))?;
        }
    }
    std::fs::create_dir_all(dir)
        .with_context(|| format!("--dir {}: cannot create", dir.display()))?;
    std::fs::write(
        dir.join(MARKER),
        "A levelmap lab run's folder: the next run with this --dir empties it.\n",
    )
    .with_context(|| format!("--dir {}: cannot write {MARKER}", dir.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("lab-dir-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        dir
    }

    #[test]
    fn a_new_folder_is_made_and_marked_and_a_marked_one_emptied() {
        let dir = scratch("marked");
        prepare(&dir).unwrap();
        assert!(dir.join(MARKER).is_file());
        std::fs::write(dir.join("mapper.redb"), b"a run's store").unwrap();
        prepare(&dir).unwrap();
        assert!(
            !dir.join("mapper.redb").exists(),
            "the last run's files are gone"
        );
        assert!(dir.join(MARKER).is_file());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn an_empty_folder_is_taken() {
        let dir = scratch("empty");
        std::fs::create_dir_all(&dir).unwrap();
        prepare(&dir).unwrap();
        assert!(dir.join(MARKER).is_file());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_folder_holding_a_users_file_is_refused_and_left_as_it_is() {
        let dir = scratch("user");
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("thesis.tex"), b"two years of work").unwrap();
        let why = prepare(&dir).unwrap_err().to_string();
        assert!(
            why.contains("did not make") && why.contains(MARKER),
            "{why}"
        );
        assert_eq!(
            std::fs::read(dir.join("thesis.tex")).unwrap(),
            b"two years of work"
        );
        assert!(!dir.join(MARKER).exists());
        let file = dir.join("thesis.tex");
        assert!(
            prepare(&file)
                .unwrap_err()
                .to_string()
                .contains("not a folder")
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}

//! SemanticKITTI `.label` files: one little-endian uint32 per point, semantic class in the
//! lower 16 bits. Used to score segmentation (which points are ground).

use crate::{LoadError, read_nonempty};
use std::path::Path;

/// Which class ids a label file uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LabelScheme {
    /// The dataset's raw ids (road 40, parking 44, sidewalk 48, other-ground 49,
    /// lane-marking 60, terrain 72; unlabeled 0 and outlier 1 are not scored).
    SemanticKitti,
    /// 0-based 19-class training ids, as segmentation networks write them (road 8, parking 9,
    /// sidewalk 10, other-ground 11, terrain 16; ids ≥ 19 are not scored).
    Train19,
}

/// Per-point ground truth: ground, not ground, or not scored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GroundTruth {
    /// A ground class of the scheme.
    Ground,
    /// Any other scored class.
    NotGround,
    /// A class the scheme does not score (unlabelled, outlier).
    Unscored,
}

/// A label file's per-point classes.
#[derive(Clone, Debug)]
pub struct Labels {
    /// How the ids are read.
    pub scheme: LabelScheme,
    /// The semantic class id of each point, in the scan's order.
    pub ids: Vec<u16>,
}

impl Labels {
    /// Reads a `.label` file holding `expected_points` labels; the scheme is detected: every
    /// id below 20 means network training ids.
    pub fn load(path: &Path, expected_points: usize) -> Result<Labels, LoadError> {
        Labels::parse(&read_nonempty(path)?, path, expected_points)
    }

    /// Parses the bytes of a `.label` file (`path` names it in errors), as [`Labels::load`].
    pub fn parse(bytes: &[u8], path: &Path, expected_points: usize) -> Result<Labels, LoadError> {
        if bytes.is_empty() {
            return Err(LoadError::Empty {
                path: path.to_owned(),
            });
        }
        if !bytes.len().is_multiple_of(4) {
            return Err(LoadError::Truncated {
                path: path.to_owned(),
                len: bytes.len(),
                point_bytes: 4,
            });
        }
        let ids: Vec<u16> = bytes
            .chunks_exact(4)
            .map(|c| (u32::from_le_bytes([c[0], c[1], c[2], c[3]]) & 0xFFFF) as u16)
            .collect();
        if ids.len() != expected_points {
            return Err(LoadError::invalid(
                path,
                format!(
                    "{} labels for a scan of {expected_points} points",
                    ids.len()
                ),
            ));
        }
        let scheme = if ids.iter().all(|&id| id < 20) {
            LabelScheme::Train19
        } else {
            LabelScheme::SemanticKitti
        };
        Ok(Labels { scheme, ids })
    }

    /// Whether the point with file index `index` is ground; `None` where the labels do not
    /// score it. The form [`leveling::Precision::score`] takes.
    pub fn is_ground(&self, index: usize) -> Option<bool> {
        match self.truth(index) {
            GroundTruth::Ground => Some(true),
            GroundTruth::NotGround => Some(false),
            GroundTruth::Unscored => None,
        }
    }

    /// Ground truth of the point with file index `index`.
    pub fn truth(&self, index: usize) -> GroundTruth {
        let id = self.ids[index];
        match self.scheme {
            LabelScheme::SemanticKitti => match id {
                0 | 1 => GroundTruth::Unscored,
                40 | 44 | 48 | 49 | 60 | 72 => GroundTruth::Ground,
                _ => GroundTruth::NotGround,
            },
            LabelScheme::Train19 => match id {
                8..=11 | 16 => GroundTruth::Ground,
                19.. => GroundTruth::Unscored,
                _ => GroundTruth::NotGround,
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parse_reads_the_lower_16_bits_and_wants_a_label_per_point() {
        let path = Path::new("t.label");
        let bytes: Vec<u8> = [40u32 | 7 << 16, 10, 1]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let labels = Labels::parse(&bytes, path, 3).unwrap();
        assert_eq!(labels.ids, [40, 10, 1]);
        assert_eq!(labels.scheme, LabelScheme::SemanticKitti);
        assert_eq!(labels.truth(0), GroundTruth::Ground);
        assert!(matches!(
            Labels::parse(&bytes, path, 4),
            Err(LoadError::Invalid { .. })
        ));
        assert!(matches!(
            Labels::parse(&bytes[..5], path, 1),
            Err(LoadError::Truncated { .. })
        ));
        assert!(matches!(
            Labels::parse(&[], path, 0),
            Err(LoadError::Empty { .. })
        ));
    }
}

//! Localization's configuration (`[localization]`): the versions' maps kept built, the
//! localizations kept per robot, and how a map is searched and a robot followed.

use serde::{Deserialize, Serialize};
use slam::localize::{LocalizeParams, TrackParams};
use std::num::NonZeroUsize;

/// Localization (`[localization]`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LocalizationConfig {
    /// Versions' maps kept built at once (the newest used): each takes a byte per 0.1 m cell
    /// per pooled level, about 8 MB per tile of 64 m (the park's map: 6 tiles).
    pub max_maps: NonZeroUsize,
    /// Localizations kept per robot for `GET …/robots/{robot}/localization`.
    pub history: NonZeroUsize,
    /// How a map is rasterized and searched (`slam::localize::LocalizeParams`).
    pub search: LocalizeParams,
    /// How a robot is followed from node to node (`slam::localize::TrackParams`).
    pub track: TrackParams,
}

impl Default for LocalizationConfig {
    fn default() -> Self {
        LocalizationConfig {
            max_maps: NonZeroUsize::new(4).expect("nonzero"),
            history: NonZeroUsize::new(1024).expect("nonzero"),
            search: LocalizeParams::default(),
            track: TrackParams::default(),
        }
    }
}

//! What a fleet is mapped with: its empty map as the configuration sets it up, and the
//! mapping version the store records with its rows (a fleet stored under another version is
//! rebuilt from its nodes at start: [`crate::restore`]).

use crate::config::MapperConfig;
use crate::store::MappingVersion;
use fleetmap::FleetMap;

/// Fleet `id`'s empty map under `config`.
pub fn new_fleet(config: &MapperConfig, id: &str) -> FleetMap {
    FleetMap::new(
        id,
        config.mapping.clone(),
        config
            .datum
            .map(|origin| slam::geodesy::GeoDatum { origin }),
        config.max_range_m,
    )
}

/// The mapping version of `config`: [`fleetmap::MAPPING_CODE`] and a digest of what it maps
/// with (`[mapping]`, `datum`, `max_range_m`).
pub fn mapping_version(config: &MapperConfig) -> MappingVersion {
    let parameters = serde_json::to_vec(&(&config.mapping, &config.datum, config.max_range_m))
        .expect("mapping parameters serialize");
    MappingVersion {
        code: fleetmap::MAPPING_CODE.to_owned(),
        parameters: format!("{:08x}", crc32fast::hash(&parameters)),
    }
}

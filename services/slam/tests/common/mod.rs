//! A public 2D log mapped whole by `Mapper2d` at the default parameters, and scored by its
//! relations: what the real-log tests share.

use graphio::carmen::{self, CarmenLog};
use graphio::relations::{self, Relation};
use slam::matching::metric::RelationMetric;
use slam::{Mapper2d, Mapper2dParams, Placed};
use testdata::shared_data;

/// The log `radish_2d_laser_logs/{name}.clf.bz2` with its relations, mapped.
pub struct MappedLog {
    pub log: CarmenLog,
    pub relations: Vec<Relation>,
    pub mapper: Mapper2d,
    pub placed: Vec<Placed>,
}

impl MappedLog {
    /// Maps every scan of the log, then optimizes once more.
    pub fn map(name: &str) -> MappedLog {
        let path = |ext: &str| shared_data(&format!("radish_2d_laser_logs/{name}.{ext}"));
        let log = carmen::read(&path("clf.bz2")).expect("log");
        let relations = relations::read(&path("relations")).expect("relations");
        let mut mapper = Mapper2d::new(Mapper2dParams::default());
        let placed = log
            .scans
            .iter()
            .map(|s| mapper.add_scan(s.laser_pose, s.to_scan2()).expect("add"))
            .collect();
        mapper.finish().expect("optimize");
        MappedLog {
            log,
            relations,
            mapper,
            placed,
        }
    }

    /// The error of the scans' poses against `relations`.
    pub fn score(&self, relations: &[Relation]) -> RelationMetric {
        relations::score(relations, &self.log.scans, |k| {
            self.mapper.pose_of(self.placed[k])
        })
        .expect("every relation has its scans")
    }
}

//! A public 2D log mapped whole by `Mapper2d` at the default parameters, and scored by its
//! relations: what the real-log tests share.

// Each test crate that includes this module uses a part of it.
#![allow(dead_code)]

use graphio::carmen::{self, CarmenLog};
use graphio::relations::{self, Relation};
use slam::matching::metric::RelationMetric;
use slam::{Mapper2d, Mapper2dParams, Placed, WrongClosures, WrongMatches};
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
        let (mapper, placed, _) = map_injecting(&log, 0.0);
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

/// Maps every scan of `log` at the default parameters, injecting `fraction` wrong closures
/// per loop-closure match (seed 12; 0: none), then optimizes once more.
pub fn map_injecting(log: &CarmenLog, fraction: f64) -> (Mapper2d, Vec<Placed>, WrongClosures) {
    let (mapper, placed, closures, _) = map_with_faults(log, fraction, 0.0);
    (mapper, placed, closures)
}

/// Maps every scan of `log` at the default parameters, injecting `closures` wrong closures
/// per loop-closure match and `matches` wrong sequential matches per node (seed 12; 0:
/// none), then optimizes once more.
pub fn map_with_faults(
    log: &CarmenLog,
    closures: f64,
    matches: f64,
) -> (Mapper2d, Vec<Placed>, WrongClosures, WrongMatches) {
    let mut mapper = Mapper2d::new(Mapper2dParams::default());
    let mut wrong_closures = WrongClosures::new(closures, 12);
    let mut wrong_matches = WrongMatches::new(matches, 12);
    let mut placed = Vec::with_capacity(log.scans.len());
    for s in &log.scans {
        placed.push(mapper.add_scan(s.laser_pose, s.to_scan2()).expect("add"));
        wrong_closures.inject(&mut mapper).expect("inject");
        wrong_matches.inject(&mut mapper);
    }
    mapper.finish().expect("optimize");
    (mapper, placed, wrong_closures, wrong_matches)
}

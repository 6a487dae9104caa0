//! `[ros2_out]` on the mapper: each fleet's map as `nav_msgs/OccupancyGrid` on
//! `/levelmap/<fleet>/map` (the fleet id made a ROS name token), for RViz, Nav2 and any ROS 2
//! node. The grid is the one `map.png` and `map.pgm` serve at their default resolution
//! (coarser when the map outgrows their cell cap), as map_server publishes a map it loaded
//! (`map_values`: trinary, 0 free, 100 occupied, −1 unknown; or scale, the evidence between
//! the thresholds as 1–99), made off the mapping worker, at most every
//! `map_period_ms` when the map changed, and again every [`REPUBLISH_PERIODS`] periods
//! unchanged. Transient-local-like: a queryable on the same key answers the last grid to
//! late joiners at once.

use crate::views::Shared;
use anyhow::Result;
use fleetmap::FleetView;
use runtime::ros2::{Durability, MapValues, RosOut, RosOutConfig, RosPublisher, ros_name_token};
use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// An unchanged grid goes out again after this many periods (for late joiners that do not
/// query).
pub const REPUBLISH_PERIODS: u32 = 10;

/// The topic of a fleet's map.
pub fn map_topic(fleet: &str) -> String {
    format!("/levelmap/{}/map", ros_name_token(fleet))
}

/// The grid params of the published map: the HTTP grid's defaults, coarsened to fit.
fn grid_params() -> slam::GridParams {
    slam::GridParams {
        coarsen_to_fit: true,
        ..slam::GridParams::default()
    }
}

/// A fleet's view as an `OccupancyGrid` sample in `frame`, its cells as `values` says.
pub fn occupancy_grid_sample(
    view: &FleetView,
    frame: &str,
    values: MapValues,
) -> Result<Vec<u8>, slam::GridError> {
    let grid = view.grid(&grid_params())?;
    let mode = match values {
        MapValues::Trinary => graphio::gridmap::MapMode::Trinary,
        MapValues::Scale => graphio::gridmap::MapMode::Scale,
    };
    let stamp = ros2msg::Time::from_ns(view.updated_ns);
    let message = ros2msg::OccupancyGrid {
        header: ros2msg::Header {
            stamp,
            frame_id: frame.to_owned(),
        },
        info: ros2msg::MapMetaData {
            map_load_time: stamp,
            resolution: grid.resolution_m as f32,
            width: grid.width as u32,
            height: grid.height as u32,
            origin: ros2msg::Pose {
                position: ros2msg::Vector3 {
                    x: grid.origin_m[0],
                    y: grid.origin_m[1],
                    z: 0.0,
                },
                orientation: ros2msg::Quaternion::default(),
            },
        },
        // As map_server publishes a map it loaded in `mode`.
        data: grid
            .cells
            .iter()
            .map(|&c| graphio::gridmap::map_server_value(&grid, c, mode))
            .collect(),
    };
    Ok(ros2msg::encode(&message))
}

/// One fleet's publication: its publisher, the last grid (for queries), when it was made.
struct FleetMapOut {
    publisher: RosPublisher,
    last: Arc<Mutex<Option<Arc<[u8]>>>>,
    updated_ns: u64,
    unchanged_periods: u32,
}

/// How long to wait before trying `[ros2_out]`'s session again.
const RETRY: Duration = Duration::from_secs(5);

/// Starts publishing the maps of `fleets` once the ROS 2 network is reachable (tried again
/// every `RETRY`), until the mapper stops.
pub fn start_when_reachable(config: RosOutConfig, shared: Arc<Shared>, fleets: Vec<String>) {
    tokio::spawn(async move {
        let mut stopping = shared.stopping.subscribe();
        loop {
            match start(&config, shared.clone(), &fleets).await {
                Ok(()) => return,
                Err(e) => tracing::warn!("[ros2_out] not open ({e:#}); retrying"),
            }
            tokio::select! {
                _ = stopping.wait_for(|s| *s) => return,
                _ = tokio::time::sleep(RETRY) => {}
            }
        }
    });
}

/// Starts publishing the maps of `fleets` until the mapper stops.
pub async fn start(config: &RosOutConfig, shared: Arc<Shared>, fleets: &[String]) -> Result<()> {
    let ros = RosOut::open(config).await?;
    let mut outs = HashMap::new();
    for fleet in fleets {
        let topic = map_topic(fleet);
        let publisher = ros
            .publisher(
                &topic,
                &ros2msg::types::OCCUPANCY_GRID,
                Durability::TransientLocal,
            )
            .await?;
        let last: Arc<Mutex<Option<Arc<[u8]>>>> = Arc::default();
        let answer = last.clone();
        ros.answer_queries(publisher.key(), move || {
            let grid = answer.lock().expect("map lock").clone();
            grid.map(|g| g.to_vec())
        })?;
        tracing::info!(fleet, "ROS 2 out: the map on {}", publisher.key());
        outs.insert(
            fleet.clone(),
            FleetMapOut {
                publisher,
                last,
                updated_ns: 0,
                unchanged_periods: 0,
            },
        );
    }
    let period = Duration::from_millis(config.map_period_ms.max(100));
    let frame = config.map_frame.clone();
    let values = config.map_values;
    let mut stopping = shared.stopping.subscribe();
    tokio::spawn(async move {
        let _ros = ros;
        let mut tick = tokio::time::interval(period);
        loop {
            tokio::select! {
                _ = stopping.wait_for(|s| *s) => return,
                _ = tick.tick() => {}
            }
            for (fleet, out) in outs.iter_mut() {
                publish_fleet(&shared, fleet, out, &frame, values).await;
            }
        }
    });
    Ok(())
}

/// One period of one fleet: a new grid when the map changed, the last one again now and then.
async fn publish_fleet(
    shared: &Shared,
    fleet: &str,
    out: &mut FleetMapOut,
    frame: &str,
    values: MapValues,
) {
    let Some(view) = shared.fleet(fleet) else {
        return;
    };
    if view.updated_ns == out.updated_ns {
        out.unchanged_periods += 1;
        if out.unchanged_periods >= REPUBLISH_PERIODS {
            out.unchanged_periods = 0;
            let last = out.last.lock().expect("map lock").clone();
            if let Some(grid) = last {
                out.publisher.put(grid.to_vec());
            }
        }
        return;
    }
    let updated_ns = view.updated_ns;
    let frame = frame.to_owned();
    let made =
        tokio::task::spawn_blocking(move || occupancy_grid_sample(&view, &frame, values)).await;
    match made {
        Ok(Ok(sample)) => {
            let kept: Arc<[u8]> = Arc::from(sample.as_slice());
            *out.last.lock().expect("map lock") = Some(kept);
            out.publisher.put(sample);
            out.updated_ns = updated_ns;
            out.unchanged_periods = 0;
        }
        Ok(Err(e)) => tracing::warn!(fleet, "ROS 2 map not made: {e}"),
        Err(e) => tracing::error!(fleet, "ROS 2 map task: {e}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fleetmap::FleetMap;

    #[test]
    fn the_published_grid_is_trinary_or_the_evidence_as_map_server_loads_it() {
        let mut map = FleetMap::new("site", slam::Mapper2dParams::default(), None, 40.0);
        map.ingest(&fleetmap::testing::node("r0", 1, 0, 0, 0.0))
            .expect("a node");
        let view = FleetView::of(&map, None, 0.0, 5);
        let grid = view.grid(&grid_params()).expect("a grid");
        let decoded = |values| {
            let sample = occupancy_grid_sample(&view, "map", values).expect("a sample");
            ros2msg::decode::<ros2msg::OccupancyGrid>(&sample).expect("decodes")
        };
        let (trinary, scale) = (decoded(MapValues::Trinary), decoded(MapValues::Scale));
        assert_eq!(trinary.data.len(), grid.cells.len());
        assert!(trinary.data.iter().all(|v| [-1, 0, 100].contains(v)));
        assert!(trinary.data.contains(&0) && trinary.data.contains(&100));
        // Seen but undecided cells carry their evidence in scale mode only.
        let (mut undecided, mut same) = (0, 0);
        for ((&t, &s), &c) in trinary.data.iter().zip(&scale.data).zip(&grid.cells) {
            match grid.classify(c) {
                slam::CellState::Unknown if c >= 0 => {
                    undecided += 1;
                    assert!(t == -1 && (1..=99).contains(&s), "cell {c}: {t} / {s}");
                }
                _ => same += usize::from(t == s),
            }
        }
        assert!(undecided > 0, "the test grid has undecided cells");
        assert_eq!(same + undecided, grid.cells.len());
    }
}

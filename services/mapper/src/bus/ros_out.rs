//! `[ros2_out]` on the mapper: each fleet's map as `nav_msgs/OccupancyGrid` on
//! `/levelmap/<fleet>/map` (the fleet id made a ROS name token), for RViz, Nav2 and any ROS 2
//! node. The grid is the one `map.png` and `map.pgm` serve at their default resolution
//! (coarser when the map outgrows their cell cap), trinary as map_server publishes a loaded
//! map (0 free, 100 occupied, −1 unknown), made off the mapping worker, at most every
//! `map_period_ms` when the map changed, and again every [`REPUBLISH_PERIODS`] periods
//! unchanged. Transient-local-like: a queryable on the same key answers the last grid to
//! late joiners at once.

use crate::views::Shared;
use anyhow::Result;
use fleetmap::FleetView;
use runtime::ros2::{Durability, RosOut, RosOutConfig, RosPublisher, ros_name_token};
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

/// A fleet's view as an `OccupancyGrid` sample in `frame`.
pub fn occupancy_grid_sample(view: &FleetView, frame: &str) -> Result<Vec<u8>, slam::GridError> {
    let grid = view.grid(&grid_params())?;
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
        // Trinary, as map_server publishes a map: Nav2's static layer takes only 100 as an
        // obstacle and every other known value as free.
        data: grid
            .cells
            .iter()
            .map(|&c| {
                graphio::gridmap::map_server_value(&grid, c, graphio::gridmap::MapMode::Trinary)
            })
            .collect(),
    };
    Ok(ros2msg::encode(&message))
}

/// One fleet's publication: its publisher, the last grid (for queries), when it was made.
struct FleetMapOut {
    publisher: RosPublisher,
    last: Arc<Mutex<Option<Arc<Vec<u8>>>>>,
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
        let last: Arc<Mutex<Option<Arc<Vec<u8>>>>> = Arc::default();
        let answer = last.clone();
        ros.answer_queries(publisher.key(), move || {
            let grid = answer.lock().expect("map lock").clone();
            grid.map(|g| g.as_ref().clone())
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
                publish_fleet(&shared, fleet, out, &frame).await;
            }
        }
    });
    Ok(())
}

/// One period of one fleet: a new grid when the map changed, the last one again now and then.
async fn publish_fleet(shared: &Shared, fleet: &str, out: &mut FleetMapOut, frame: &str) {
    let Some(view) = shared.fleet(fleet) else {
        return;
    };
    if view.updated_ns == out.updated_ns {
        out.unchanged_periods += 1;
        if out.unchanged_periods >= REPUBLISH_PERIODS {
            out.unchanged_periods = 0;
            let last = out.last.lock().expect("map lock").clone();
            if let Some(grid) = last {
                out.publisher.put(grid.as_ref().clone());
            }
        }
        return;
    }
    let updated_ns = view.updated_ns;
    let frame = frame.to_owned();
    let made = tokio::task::spawn_blocking(move || occupancy_grid_sample(&view, &frame)).await;
    match made {
        Ok(Ok(sample)) => {
            let sample = Arc::new(sample);
            *out.last.lock().expect("map lock") = Some(sample.clone());
            out.publisher.put(sample.as_ref().clone());
            out.updated_ns = updated_ns;
            out.unchanged_periods = 0;
        }
        Ok(Err(e)) => tracing::warn!(fleet, "ROS 2 map not made: {e}"),
        Err(e) => tracing::error!(fleet, "ROS 2 map task: {e}"),
    }
}

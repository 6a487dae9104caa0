//! What the feed publishes, from the mapper's views, in each fleet's map frame:
//!
//! | topic | schema | when |
//! |---|---|---|
//! | `/{fleet}/robots/{robot}/pose` | `foxglove.PoseInFrame` | every `poses_every_ms` |
//! | `/tf` | `foxglove.FrameTransforms` (map → `{fleet}/{robot}`) | every `poses_every_ms` |
//! | `/{fleet}/robots/{robot}/scan` | `foxglove.LaserScan` (the node's leveled scan at its pose) | each new node |
//! | `/{fleet}/robots/{robot}/cloud` | `foxglove.PointCloud` (the node's 3D cloud, from the store) | each new node that has one |
//! | `/{fleet}/robots/{robot}/gps` | `foxglove.LocationFix` (the node's fixes) | each new node's fixes |
//! | `/{fleet}/grid` | `foxglove.Grid` (occupancy per cent, INT8) | the map changed, at most every `map_every_ms` and ten times its making's time |
//! | `/{fleet}/graph` | `foxglove.SceneUpdate` (the pose graph's edges) | as the grid |
//!
//! Nothing is made for a channel no client subscribes to: a grid is made from every node's
//! scan and a cloud is a store read, all on the feed's background thread (the lowest CPU
//! priority: [`crate::background`]).

use crate::background::Background;
use crate::convert;
use fleetmap::FleetView;
use foxglove::messages::{FrameTransforms, Grid, LaserScan, LocationFix, PointCloud};
use foxglove::messages::{PoseInFrame, SceneUpdate};
use foxglove::{Channel, ChannelBuilder, Context};
use foxglove_schemas as schemas;
use mapper::config::FoxgloveConfig;
use mapper::views::Shared;
use mapper::views::clouds::Clouds;
use slam::Pose2;
use std::collections::HashMap;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// New nodes a fleet's tick publishes at most (the newest): a mapper that restored a large
/// map, or a burst, is not replayed whole to the clients.
const NODES_PER_TICK: usize = 512;

/// A grid's cells at most (2²², 8 MiB a message at two bytes a cell: 205 m square at 0.1 m);
/// a larger map's cells are coarsened to fit. A client gets the grid every `map_every_ms`
/// while the map changes: at the HTTP API's cap (2²⁴) that would be 32 MiB each time.
const GRID_MAX_CELLS: usize = 1 << 22;

/// A fleet's next map waits at least this many times as long as its last one took to make
/// (wall time on the background thread, its waits for a core included): the live map takes
/// at most about a tenth of a core, and less the busier the cores are, whatever the site's
/// size. A small site's map takes milliseconds and comes every `map_every_ms`.
const MAP_WAIT_PER_MAKING: u32 = 10;

/// A robot's channels.
struct RobotChannels {
    pose: Channel<PoseInFrame>,
    scan: Channel<LaserScan>,
    cloud: Channel<PointCloud>,
    gps: Channel<LocationFix>,
}

/// A fleet's channels.
struct FleetChannels {
    grid: Channel<Grid>,
    graph: Channel<SceneUpdate>,
}

/// The channels, made as fleets and robots appear.
pub(crate) struct Channels {
    context: Arc<Context>,
    tf: Channel<FrameTransforms>,
    robots: HashMap<(String, String), Arc<RobotChannels>>,
    fleets: HashMap<String, Arc<FleetChannels>>,
}

impl Channels {
    pub(crate) fn new(context: Arc<Context>) -> Channels {
        let tf = ChannelBuilder::new("/tf").context(&context).build();
        Channels {
            context,
            tf,
            robots: HashMap::new(),
            fleets: HashMap::new(),
        }
    }

    fn robot(&mut self, fleet: &str, robot: &str) -> &Arc<RobotChannels> {
        let context = &self.context;
        self.robots
            .entry((fleet.to_owned(), robot.to_owned()))
            .or_insert_with(|| {
                let topic = |what: &str| format!("/{fleet}/robots/{robot}/{what}");
                Arc::new(RobotChannels {
                    pose: ChannelBuilder::new(topic("pose")).context(context).build(),
                    scan: ChannelBuilder::new(topic("scan")).context(context).build(),
                    cloud: ChannelBuilder::new(topic("cloud")).context(context).build(),
                    gps: ChannelBuilder::new(topic("gps")).context(context).build(),
                })
            })
    }

    fn fleet(&mut self, fleet: &str) -> &Arc<FleetChannels> {
        let context = &self.context;
        self.fleets.entry(fleet.to_owned()).or_insert_with(|| {
            let topic = |what: &str| format!("/{fleet}/{what}");
            Arc::new(FleetChannels {
                grid: ChannelBuilder::new(topic("grid")).context(context).build(),
                graph: ChannelBuilder::new(topic("graph")).context(context).build(),
            })
        })
    }
}

/// What was last sent of a fleet: its map (the view's time, and when the next may come),
/// the map being made (when it started, and its end to come), and how many of its nodes.
struct Sent {
    map: Option<(u64, Instant)>,
    making: Option<(Instant, tokio::sync::oneshot::Receiver<Instant>)>,
    nodes: usize,
}

impl Sent {
    /// Whether no map is being made: a map that was, and is done now, sets when the next may
    /// come.
    fn map_made(&mut self, map_every: Duration) -> bool {
        let Some((started, making)) = &mut self.making else {
            return true;
        };
        let finished = match making.try_recv() {
            Ok(finished) => finished,
            Err(tokio::sync::oneshot::error::TryRecvError::Empty) => return false,
            // The job was dropped (the thread is gone): counted as taking until now.
            Err(tokio::sync::oneshot::error::TryRecvError::Closed) => Instant::now(),
        };
        let wait = map_every.max((finished - *started) * MAP_WAIT_PER_MAKING);
        if let Some((_, next)) = &mut self.map {
            *next = *started + wait;
        }
        self.making = None;
        true
    }
}

/// A new node's cloud to read: its robot's channels, fleet, node, its pose, its time.
type CloudWanted = (Arc<RobotChannels>, String, usize, Pose2, u64);

/// Publishes every fleet's robots each `poses_every_ms`, their new nodes, and its map when
/// it changed (at most each `map_every_ms`, and only while a client subscribes).
pub(crate) async fn publish(
    config: FoxgloveConfig,
    shared: Arc<Shared>,
    clouds: Clouds,
    mut channels: Channels,
    background: Background,
) {
    let mut tick = tokio::time::interval(Duration::from_millis(config.poses_every_ms.max(10)));
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let map_every = Duration::from_millis(config.map_every_ms);
    let mut sent: HashMap<String, Sent> = HashMap::new();
    loop {
        tick.tick().await;
        let views = shared.views();
        let now_ns = runtime::session::now_ns();
        let mut transforms = Vec::new();
        let mut wanted = Vec::new();
        for view in &views {
            for robot in &view.robots {
                let (pose, stamp_ns, _) = shared.robot_pose(view, robot);
                let stamp_ns = if stamp_ns == 0 { now_ns } else { stamp_ns };
                let frame = || schemas::map_frame(&view.id);
                let channel = &channels.robot(&view.id, &robot.id).pose;
                if channel.has_sinks() {
                    channel.log(&schemas::pose_in_frame(frame(), &pose, stamp_ns));
                }
                let child = schemas::robot_frame(&view.id, &robot.id);
                transforms.push(schemas::transform(frame(), child, &pose, stamp_ns));
            }
            // A fleet first seen (the mapper just started) is published from its next node.
            let len = view.nodes.len();
            let fleet_sent = sent.entry(view.id.clone()).or_insert(Sent {
                map: None,
                making: None,
                nodes: len,
            });
            let from = fleet_sent.nodes.max(len.saturating_sub(NODES_PER_TICK));
            fleet_sent.nodes = len;
            wanted.extend(publish_nodes(view, from..len, &mut channels));
            let watched = {
                let fleet = channels.fleet(&view.id);
                fleet.grid.has_sinks() || fleet.graph.has_sinks()
            };
            if !watched {
                // A client that subscribes later gets the map at once.
                fleet_sent.map = None;
                continue;
            }
            let due = fleet_sent.map_made(map_every)
                && fleet_sent.map.is_none_or(|(updated, next)| {
                    updated != view.updated_ns && Instant::now() >= next
                });
            if due {
                let started = Instant::now();
                let fleet = channels.fleet(&view.id).clone();
                if let Some(making) = publish_map(view, now_ns, fleet, &background) {
                    fleet_sent.making = Some((started, making));
                }
                // The next when this one is made (`map_made`).
                fleet_sent.map = Some((view.updated_ns, started + map_every));
            }
        }
        if !transforms.is_empty() {
            channels.tf.log(&FrameTransforms { transforms });
        }
        if !wanted.is_empty() {
            publish_clouds(&clouds, wanted, &background);
        }
    }
}

/// Publishes the scans and fixes of `view`'s nodes `nodes`; the clouds to read, of those
/// whose cloud channel a client subscribes to.
fn publish_nodes(
    view: &FleetView,
    nodes: std::ops::Range<usize>,
    channels: &mut Channels,
) -> Vec<CloudWanted> {
    let mut wanted = Vec::new();
    for i in nodes {
        let (Some(node), Some(pose)) = (view.nodes.get(i), view.poses.get(i)) else {
            continue;
        };
        let Some(robot) = view.robots.get(node.robot) else {
            continue;
        };
        let robot_channels = channels.robot(&view.id, &robot.id);
        let frame = || schemas::map_frame(&view.id);
        if robot_channels.scan.has_sinks() {
            robot_channels
                .scan
                .log(&schemas::laser_scan(frame(), pose, &node.scan));
        }
        if let (true, Some(datum)) = (robot_channels.gps.has_sinks(), &view.datum) {
            for observation in &node.gps {
                let fix = schemas::observed_fix(frame(), datum, observation, node.stamp_ns);
                robot_channels.gps.log(&fix);
            }
        }
        if robot_channels.cloud.has_sinks() {
            wanted.push((
                robot_channels.clone(),
                view.id.clone(),
                i,
                *pose,
                node.stamp_ns,
            ));
        }
    }
    wanted
}

/// Reads the wanted clouds from the store and publishes them, on the background thread.
fn publish_clouds(clouds: &Clouds, wanted: Vec<CloudWanted>, background: &Background) {
    let clouds = clouds.clone();
    let count = wanted.len();
    let handed = background.spawn(move || {
        for (channels, fleet, node, pose, stamp_ns) in wanted {
            match clouds.get(&fleet, node as u64) {
                Ok(Some(cloud)) => {
                    let frame = schemas::map_frame(&fleet);
                    channels
                        .cloud
                        .log(&schemas::point_cloud(frame, &pose, &cloud, stamp_ns));
                }
                Ok(None) => {}
                Err(e) => tracing::debug!(fleet, node, "foxglove: no cloud: {e:#}"),
            }
        }
    });
    if handed.is_none() {
        tracing::warn!("foxglove: the background thread is behind: {count} clouds not sent");
    }
}

/// Makes and publishes a fleet's graph and grid, to whichever a client subscribes to, on the
/// background thread: when they are done comes on the receiver. None when the thread is
/// behind (no map this time).
fn publish_map(
    view: &Arc<FleetView>,
    now_ns: u64,
    fleet: Arc<FleetChannels>,
    background: &Background,
) -> Option<tokio::sync::oneshot::Receiver<Instant>> {
    let v = view.clone();
    // The HTTP grid's defaults, coarsened to fit GRID_MAX_CELLS: a larger site gets larger
    // cells, not no grid.
    let params = slam::GridParams {
        coarsen_to_fit: true,
        max_cells: GRID_MAX_CELLS,
        ..slam::GridParams::default()
    };
    let handed = background.spawn(move || {
        if fleet.graph.has_sinks() {
            fleet.graph.log(&convert::graph(&v, now_ns));
        }
        if fleet.grid.has_sinks() {
            let grid = v
                .grid(&params)
                .map(|g| schemas::grid(schemas::map_frame(&v.id), &g, now_ns));
            match grid {
                Ok(grid) => fleet.grid.log(&grid),
                Err(e) => tracing::debug!(fleet = v.id, "foxglove: no grid: {e}"),
            }
        }
        Instant::now()
    });
    if handed.is_none() {
        tracing::warn!(
            fleet = view.id,
            "foxglove: the background thread is behind: no map this time"
        );
    }
    handed
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_next_map_waits_ten_times_its_making() {
        let map_every = Duration::from_secs(2);
        let started = Instant::now();
        let (done, making) = tokio::sync::oneshot::channel();
        let mut sent = Sent {
            map: Some((1, started + map_every)),
            making: Some((started, making)),
            nodes: 0,
        };
        assert!(!sent.map_made(map_every), "still being made");
        done.send(started + Duration::from_secs(1))
            .expect("waited for");
        assert!(sent.map_made(map_every));
        assert_eq!(sent.map, Some((1, started + Duration::from_secs(10))));
        // A quick one: map_every rules.
        let (done, making) = tokio::sync::oneshot::channel();
        sent.making = Some((started, making));
        done.send(started + Duration::from_millis(5))
            .expect("waited for");
        assert!(sent.map_made(map_every));
        assert_eq!(sent.map, Some((1, started + map_every)));
    }
}

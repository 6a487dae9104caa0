//! The fleets live in Foxglove (docs/foxglove.md): a Foxglove WebSocket server (the official
//! `foxglove` SDK) fed from the mapper's views, which it only reads. Per fleet, in its map
//! frame `{fleet}/map`:
//!
//! | topic | schema | when |
//! |---|---|---|
//! | `/{fleet}/robots/{robot}/pose` | `foxglove.PoseInFrame` | every `poses_every_ms` |
//! | `/tf` | `foxglove.FrameTransforms` (map → `{fleet}/{robot}`) | every `poses_every_ms` |
//! | `/{fleet}/grid` | `foxglove.Grid` (occupancy per cent, INT8) | the map changed, at most every `map_every_ms` |
//! | `/{fleet}/graph` | `foxglove.SceneUpdate` (the pose graph's edges) | as the grid |
//!
//! A grid is made only while a client subscribes to it (it is made from every node's scan,
//! off the async threads). The protocol has no access control: a mapper with a read token
//! serves it on a loopback address only.

pub mod convert;

use anyhow::{Context as _, Result, bail};
use foxglove::messages::{FrameTransforms, Grid, PoseInFrame, SceneUpdate};
use foxglove::{Channel, ChannelBuilder, Context, WebSocketServer, WebSocketServerHandle};
use mapper::config::FoxgloveConfig;
use mapper::views::Shared;
use std::collections::HashMap;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// The Foxglove server running beside a mapper.
pub struct Feed {
    /// Where it listens.
    pub addr: SocketAddr,
    server: WebSocketServerHandle,
    publisher: tokio::task::JoinHandle<()>,
}

impl Feed {
    /// Stops publishing and closes the server.
    pub async fn stop(self) {
        self.publisher.abort();
        let _ = self.publisher.await;
        self.server.stop().wait().await;
    }
}

/// Starts the server on `config.listen` and its publisher over `shared`'s views. Refused on
/// an address other than loopback when the mapper has a read token (`read_token`).
pub async fn start(config: &FoxgloveConfig, read_token: &str, shared: Arc<Shared>) -> Result<Feed> {
    let addr: SocketAddr = config
        .listen
        .parse()
        .with_context(|| format!("[foxglove] listen = {:?}: not an address", config.listen))?;
    if !read_token.is_empty() && !addr.ip().is_loopback() {
        bail!(
            "[foxglove] listen = {addr}: the mapper has a read token and the Foxglove protocol \
             no access control; listen on loopback (127.0.0.1) and reach it through an SSH \
             tunnel"
        );
    }
    let context = Context::new();
    let server = WebSocketServer::new()
        .name("levelmap")
        .context(&context)
        .bind(addr.ip().to_string(), addr.port())
        .start()
        .await
        .with_context(|| format!("[foxglove] listen = {addr}"))?;
    let addr = SocketAddr::new(addr.ip(), server.port());
    let channels = Channels::new(context);
    let publisher = tokio::spawn(publish(config.clone(), shared, channels));
    tracing::info!("foxglove: ws://{addr} (the fleets' grids, robots and pose graphs)");
    Ok(Feed {
        addr,
        server,
        publisher,
    })
}

/// The channels, made as fleets and robots appear.
struct Channels {
    context: Arc<Context>,
    tf: Channel<FrameTransforms>,
    poses: HashMap<(String, String), Channel<PoseInFrame>>,
    grids: HashMap<String, Channel<Grid>>,
    graphs: HashMap<String, Channel<SceneUpdate>>,
}

impl Channels {
    fn new(context: Arc<Context>) -> Channels {
        let tf = ChannelBuilder::new("/tf").context(&context).build();
        Channels {
            context,
            tf,
            poses: HashMap::new(),
            grids: HashMap::new(),
            graphs: HashMap::new(),
        }
    }

    fn pose(&mut self, fleet: &str, robot: &str) -> &Channel<PoseInFrame> {
        let topic = || format!("/{fleet}/robots/{robot}/pose");
        let key = (fleet.to_owned(), robot.to_owned());
        channel(&self.context, &mut self.poses, key, topic)
    }

    fn grid(&mut self, fleet: &str) -> &Channel<Grid> {
        let topic = || format!("/{fleet}/grid");
        channel(&self.context, &mut self.grids, fleet.to_owned(), topic)
    }

    fn graph(&mut self, fleet: &str) -> &Channel<SceneUpdate> {
        let topic = || format!("/{fleet}/graph");
        channel(&self.context, &mut self.graphs, fleet.to_owned(), topic)
    }
}

/// The channel of `key`, made on `topic` the first time.
fn channel<'a, K: Eq + std::hash::Hash, T: foxglove::Encode>(
    context: &Arc<Context>,
    channels: &'a mut HashMap<K, Channel<T>>,
    key: K,
    topic: impl FnOnce() -> String,
) -> &'a Channel<T> {
    channels
        .entry(key)
        .or_insert_with(|| ChannelBuilder::new(topic()).context(context).build())
}

/// What was last sent of a fleet's map: its view's time, and when.
struct MapSent {
    updated_ns: u64,
    at: Instant,
}

/// Publishes every fleet's robots each `poses_every_ms`, and its map when it changed (at
/// most each `map_every_ms`, and only while a client subscribes).
async fn publish(config: FoxgloveConfig, shared: Arc<Shared>, mut channels: Channels) {
    let mut tick = tokio::time::interval(Duration::from_millis(config.poses_every_ms.max(10)));
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let map_every = Duration::from_millis(config.map_every_ms);
    let mut sent: HashMap<String, MapSent> = HashMap::new();
    loop {
        tick.tick().await;
        let views = shared.views();
        let now_ns = runtime::session::now_ns();
        let mut transforms = Vec::new();
        for view in &views {
            for robot in &view.robots {
                let (pose, stamp_ns, _) = shared.robot_pose(view, robot);
                let stamp_ns = if stamp_ns == 0 { now_ns } else { stamp_ns };
                let channel = channels.pose(&view.id, &robot.id);
                channel.log(&convert::robot_pose(&view.id, &pose, stamp_ns));
                transforms.push(convert::robot_transform(
                    &view.id, &robot.id, &pose, stamp_ns,
                ));
            }
            let watched =
                channels.grid(&view.id).has_sinks() || channels.graph(&view.id).has_sinks();
            if !watched {
                // A client that subscribes later gets the map at once.
                sent.remove(&view.id);
                continue;
            }
            let due = sent
                .get(&view.id)
                .is_none_or(|s| s.updated_ns != view.updated_ns && s.at.elapsed() >= map_every);
            if due {
                if channels.graph(&view.id).has_sinks() {
                    channels.graph(&view.id).log(&convert::graph(view, now_ns));
                }
                if channels.grid(&view.id).has_sinks() {
                    let v = view.clone();
                    let made =
                        tokio::task::spawn_blocking(move || v.grid(&slam::GridParams::default()))
                            .await;
                    match made {
                        Ok(Ok(g)) => channels
                            .grid(&view.id)
                            .log(&convert::grid(&view.id, &g, now_ns)),
                        Ok(Err(e)) => tracing::debug!(fleet = view.id, "foxglove: no grid: {e}"),
                        Err(e) => tracing::warn!(fleet = view.id, "foxglove: the grid failed: {e}"),
                    }
                }
                let (updated_ns, at) = (view.updated_ns, Instant::now());
                sent.insert(view.id.clone(), MapSent { updated_ns, at });
            }
        }
        if !transforms.is_empty() {
            channels.tf.log(&FrameTransforms { transforms });
        }
    }
}

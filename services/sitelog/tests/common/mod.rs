//! The cluster tests' servers (`servers.rs`) and their clients.

#![allow(dead_code)]

mod servers;
pub mod tmpfs;

pub use servers::*;

use async_nats::jetstream;
use sitelog::{RetryPolicy, SiteLog};
use std::time::{Duration, Instant};

impl Cluster {
    pub fn urls(&self) -> Vec<async_nats::ServerAddr> {
        self.ports()
            .iter()
            .map(|p| {
                format!("nats://127.0.0.1:{p}")
                    .parse()
                    .expect("server address")
            })
            .collect()
    }

    /// Connects with `options` (no retry: a refused client must fail, not wait).
    pub async fn connect_with(
        &self,
        options: async_nats::ConnectOptions,
    ) -> Result<async_nats::Client, async_nats::ConnectError> {
        options.connect(self.urls()).await
    }

    pub async fn client(&self) -> async_nats::Client {
        async_nats::ConnectOptions::new()
            .retry_on_initial_connect()
            .connect(self.urls())
            .await
            .expect("connect to the cluster")
    }
}

/// Site `site`'s stream as its leader reports it: its leader, and its followers as (name,
/// current).
pub async fn stream_replicas(js: &jetstream::Context, site: &str) -> (String, Vec<(String, bool)>) {
    let mut stream = js
        .get_stream(format!("LEVELMAP_SITE_{site}"))
        .await
        .expect("the stream");
    let info = stream.info().await.expect("stream info");
    let cluster = info.cluster.clone().expect("a clustered stream");
    let followers = cluster.replicas.iter().map(|p| (p.name.clone(), p.current));
    (cluster.leader.expect("a leader"), followers.collect())
}

/// The site's log opened once the cluster has elected its JetStream meta leader.
pub async fn open_when_ready(js: jetstream::Context, site: &str) -> SiteLog {
    when_ready(|| SiteLog::open(js.clone(), site, 3, RetryPolicy::default())).await
}

/// What `open` opens, once the cluster answers (a minute at most).
pub async fn when_ready<T, F>(mut open: impl FnMut() -> F) -> T
where
    F: std::future::Future<Output = Result<T, sitelog::LogError>>,
{
    let started = Instant::now();
    loop {
        match open().await {
            Ok(opened) => return opened,
            Err(e) if started.elapsed() < Duration::from_secs(60) => {
                eprintln!("waiting for the cluster: {e}");
                tokio::time::sleep(Duration::from_millis(500)).await;
            }
            Err(e) => panic!("the cluster never answered: {e}"),
        }
    }
}

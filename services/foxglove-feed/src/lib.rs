//! The fleets live in Foxglove (docs/foxglove.md): a Foxglove WebSocket server (the official
//! `foxglove` SDK) fed from the mapper's views, which it only reads. Per fleet, in its map
//! frame `{fleet}/map` ([`publish`] has the topics): the grid, the pose graph, the robots'
//! poses and frames, and each new node's leveled scan, 3D cloud and GPS fixes.
//!
//! The protocol has no access control of its own. A mapper with a read token puts a token
//! front ([`front`]) on the configured address, and the SDK's server on a loopback port
//! behind it: a connection passes only with the read or write token.

mod background;
pub mod convert;
pub mod front;
mod publish;

use anyhow::{Context as _, Result};
use foxglove::{Context, WebSocketServer, WebSocketServerHandle};
use mapper::config::FoxgloveConfig;
use mapper::tokens::Tokens;
use mapper::views::Shared;
use mapper::views::clouds::Clouds;
use std::net::{Ipv4Addr, SocketAddr};
use std::sync::Arc;

/// The Foxglove server running beside a mapper.
pub struct Feed {
    /// Where clients connect (the token front's address when there is one).
    pub addr: SocketAddr,
    server: WebSocketServerHandle,
    publisher: tokio::task::JoinHandle<()>,
    front: Option<tokio::task::JoinHandle<()>>,
}

impl Feed {
    /// Stops publishing and closes the server.
    pub async fn stop(self) {
        self.publisher.abort();
        let _ = self.publisher.await;
        if let Some(front) = self.front {
            front.abort();
            let _ = front.await;
        }
        self.server.stop().wait().await;
    }
}

/// Starts the server on `config.listen` and its publisher over `shared`'s views (the nodes'
/// clouds from `clouds`). With a read token in `tokens`, the token front listens there and
/// the SDK's server on an ephemeral loopback port.
pub async fn start(
    config: &FoxgloveConfig,
    tokens: Tokens,
    shared: Arc<Shared>,
    clouds: Clouds,
) -> Result<Feed> {
    let listen: SocketAddr = config
        .listen
        .parse()
        .with_context(|| format!("[foxglove] listen = {:?}: not an address", config.listen))?;
    let guarded = tokens.read_required();
    let sdk_addr = match guarded {
        true => SocketAddr::from((Ipv4Addr::LOCALHOST, 0)),
        false => listen,
    };
    let context = Context::new();
    let server = WebSocketServer::new()
        .name("levelmap")
        .context(&context)
        .bind(sdk_addr.ip().to_string(), sdk_addr.port())
        .start()
        .await
        .with_context(|| format!("[foxglove] listen = {sdk_addr}"))?;
    let sdk_addr = SocketAddr::new(sdk_addr.ip(), server.port());
    let (addr, front) = match guarded {
        true => {
            let listener = tokio::net::TcpListener::bind(listen)
                .await
                .with_context(|| format!("[foxglove] listen = {listen}"))?;
            let addr = listener.local_addr()?;
            let front = front::serve(listener, sdk_addr, Arc::new(tokens));
            (addr, Some(front))
        }
        false => (sdk_addr, None),
    };
    let channels = publish::Channels::new(context);
    let background = background::Background::start().context("the foxglove thread")?;
    let publisher = tokio::spawn(publish::publish(
        config.clone(),
        shared,
        clouds,
        channels,
        background,
    ));
    let guard = if guarded {
        ", the read token needed"
    } else {
        ""
    };
    tracing::info!("foxglove: ws://{addr} (the fleets' maps, robots, scans, clouds, fixes{guard})");
    Ok(Feed {
        addr,
        server,
        publisher,
        front,
    })
}

//! A site's record log on NATS JetStream: the first piece of the cluster mode (issue 26,
//! docs/cluster.md). In cluster mode a site's record (nodes, spans, chains, modes, versions)
//! is a JetStream stream of its own, replicated by the NATS servers (R3, file storage, the
//! servers run with `sync_interval: always`), not by a protocol of ours.
//!
//! Every append carries two guards the server checks:
//! - **the expected last sequence** (`Nats-Expected-Last-Sequence`): the writer says which
//!   sequence it believes is last; if another host appended since, the server refuses
//!   (error 10071) and the writer must drop the site: that is the fence between an old owner
//!   and a new one;
//! - **a message id** (`Nats-Msg-Id`, robot/chain/seq for a node): an append retried after
//!   a lost ack is recognised as a duplicate within the stream's window and acked with the
//!   sequence it already has, so a record is never stored twice.
//!
//! An append is only reported done once JetStream acked it; while no server answers (a
//! stream leader lost: a new one takes 4–9 s), it is retried with a backoff up to a deadline.
//!
//! Without its default feature `client` the crate is the cluster's configuration types only
//! ([`NatsAccess`]) and the site order ([`host_order`]): no async-nats, no Tokio, so the
//! mapper's configuration names the NATS servers without linking a client.

mod access;
#[cfg(feature = "client")]
mod client;
#[cfg(feature = "client")]
mod clouds;
#[cfg(feature = "client")]
mod lease;
#[cfg(feature = "client")]
pub mod local;
mod placement;
#[cfg(feature = "client")]
mod snapshots;
#[cfg(feature = "client")]
mod versions;

pub use access::NatsAccess;
/// A JetStream client, as [`NatsAccess::jetstream`] opens it.
#[cfg(feature = "client")]
pub use async_nats::jetstream::Context as JetStream;
#[cfg(feature = "client")]
pub use client::*;
#[cfg(feature = "client")]
pub use clouds::{CLOUDS_STREAM, CloudRetention, Clouds};
#[cfg(feature = "client")]
pub use lease::{LEASES_BUCKET, Lease, Leases};
pub use placement::host_order;
#[cfg(feature = "client")]
pub use snapshots::{SnapshotTag, Snapshots};
#[cfg(feature = "client")]
pub use versions::VersionFiles;

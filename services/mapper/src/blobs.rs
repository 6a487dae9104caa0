//! What a host keeps beside its record and shares with other hosts: the files of map
//! versions and the nodes' clouds. On a single machine nothing is shared ([`NotShared`]): the
//! store holds both. In cluster mode (the `cluster` crate's `ClusterBlobs`) an added version's
//! file is put in the cluster's object store before its record is journaled (a host reading
//! the site's log fetches it from there), and a cloud this host's store lacks (its node came
//! before a takeover) is read from the clouds' stream.

use futures_util::future::BoxFuture;

/// The blobs a host shares, as the HTTP API reaches them.
pub trait Blobs: Send + Sync {
    /// Puts version `number`'s file of `fleet` where other hosts find it; the name of the
    /// host it is filed under (the record names it).
    fn put_version_file<'a>(
        &'a self,
        fleet: &'a str,
        number: u64,
        file: &'a [u8],
    ) -> BoxFuture<'a, Result<String, String>>;

    /// Deletes a deleted version's shared file (the record is the truth: a file left behind
    /// is only space).
    fn delete_version_file<'a>(
        &'a self,
        fleet: &'a str,
        number: u64,
    ) -> BoxFuture<'a, Result<(), String>>;

    /// Node `node`'s cloud of `fleet` when this host's store lacks it.
    fn cloud<'a>(
        &'a self,
        fleet: &'a str,
        node: u64,
    ) -> BoxFuture<'a, Result<Option<Vec<u8>>, String>>;
}

/// A single machine's: nothing shared.
pub struct NotShared;

impl Blobs for NotShared {
    fn put_version_file<'a>(
        &'a self,
        _fleet: &'a str,
        _number: u64,
        _file: &'a [u8],
    ) -> BoxFuture<'a, Result<String, String>> {
        Box::pin(async { Ok(String::new()) })
    }

    fn delete_version_file<'a>(
        &'a self,
        _fleet: &'a str,
        _number: u64,
    ) -> BoxFuture<'a, Result<(), String>> {
        Box::pin(async { Ok(()) })
    }

    fn cloud<'a>(
        &'a self,
        _fleet: &'a str,
        _node: u64,
    ) -> BoxFuture<'a, Result<Option<Vec<u8>>, String>> {
        Box::pin(async { Ok(None) })
    }
}

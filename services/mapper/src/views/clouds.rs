//! The nodes' clouds for readers beside the mapper (the Foxglove feed): no view holds them,
//! so they are read from the store, which this handle only reads.

use crate::store::Store;
use std::sync::Arc;

/// Reads the nodes' segmented clouds from the store.
#[derive(Clone)]
pub struct Clouds {
    store: Arc<Store>,
}

impl Clouds {
    pub(crate) fn new(store: Arc<Store>) -> Clouds {
        Clouds { store }
    }

    /// Node `node`'s cloud in fleet `fleet`, decoded and checked; `None` when the store holds
    /// none (the robot sent none, it was pruned, or another host mapped the node). A disk
    /// read: call it off the async threads.
    pub fn get(&self, fleet: &str, node: u64) -> anyhow::Result<Option<wire::ClassifiedCloud>> {
        match self.store.cloud(fleet, node)? {
            Some(bytes) => Ok(Some(wire::decode_cloud(&bytes)?)),
            None => Ok(None),
        }
    }
}

//! An append-only list that successive snapshots share: full chunks are kept behind an `Arc`,
//! so a new snapshot of a list that only grew copies at most one chunk. The fleet views hold
//! the nodes and the network's edges this way: copied whole at every batch, they cost the worker tens of
//! MB per batch on a large map.

use std::sync::Arc;

/// Items per shared chunk.
const CHUNK: usize = 4096;

/// A snapshot of an append-only list.
#[derive(Clone, Debug)]
pub struct SharedLog<T> {
    chunks: Vec<Arc<[T]>>,
    len: usize,
}

impl<T> Default for SharedLog<T> {
    fn default() -> Self {
        SharedLog {
            chunks: Vec::new(),
            len: 0,
        }
    }
}

impl<T: Clone> SharedLog<T> {
    /// A snapshot of `items`, sharing the full chunks of `previous` (a snapshot of the same
    /// list when it was shorter or as long; anything else is copied whole).
    pub fn extend(previous: &SharedLog<T>, items: &[T]) -> SharedLog<T> {
        let mut chunks: Vec<Arc<[T]>> = previous
            .chunks
            .iter()
            .take_while(|c| c.len() == CHUNK)
            .take(items.len() / CHUNK)
            .cloned()
            .collect();
        if previous.len > items.len() {
            chunks.clear();
        }
        let shared = chunks.len() * CHUNK;
        chunks.extend(items[shared..].chunks(CHUNK).map(Arc::from));
        SharedLog {
            chunks,
            len: items.len(),
        }
    }

    /// Every item, in order.
    pub fn iter(&self) -> impl Iterator<Item = &T> + '_ {
        self.chunks.iter().flat_map(|c| c.iter())
    }

    /// How many.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The item at `index`, if there is one.
    pub fn get(&self, index: usize) -> Option<&T> {
        self.chunks.get(index / CHUNK)?.get(index % CHUNK)
    }

    /// A copy as one vector.
    pub fn to_vec(&self) -> Vec<T> {
        self.iter().cloned().collect()
    }
}

impl<T: Clone> std::ops::Index<usize> for SharedLog<T> {
    type Output = T;

    fn index(&self, index: usize) -> &T {
        self.get(index).expect("index within the log")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn snapshots_share_their_full_chunks_and_hold_every_item() {
        let items: Vec<u32> = (0..3 * CHUNK as u32 + 5).collect();
        let first = SharedLog::extend(&SharedLog::default(), &items[..CHUNK + 7]);
        assert_eq!(first.to_vec(), items[..CHUNK + 7]);
        let second = SharedLog::extend(&first, &items);
        assert_eq!(second.to_vec(), items);
        assert_eq!(second.len(), items.len());
        assert_eq!(
            (second[CHUNK + 3], second.get(items.len())),
            (CHUNK as u32 + 3, None)
        );
        assert!(Arc::ptr_eq(&first.chunks[0], &second.chunks[0]), "shared");
        assert!(
            !Arc::ptr_eq(&first.chunks[1], &second.chunks[1]),
            "the tail grew"
        );
        // A shorter list than the previous snapshot's shares nothing.
        let shorter = SharedLog::extend(&second, &items[..10]);
        assert_eq!(shorter.to_vec(), items[..10]);
    }
}

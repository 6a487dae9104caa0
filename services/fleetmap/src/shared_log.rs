//! A list that successive snapshots share: chunks are kept behind an `Arc`, so a new snapshot
//! copies only the chunks that changed. The fleet views hold the nodes and the network's edges
//! this way (append-only: a new snapshot copies at most one chunk) and the poses (changed in
//! place: a node's window moves a few, a solve all); copied whole at every batch, they cost the
//! worker tens of MB per batch on a large map.

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

    /// A snapshot of `items`, a list whose items may change in place: each chunk of
    /// `previous` that equals the one at its place in `items` is shared, the rest copied. The
    /// comparison reads both lists but allocates and writes only what changed.
    pub fn refresh(previous: &SharedLog<T>, items: &[T]) -> SharedLog<T>
    where
        T: PartialEq,
    {
        let chunks = items
            .chunks(CHUNK)
            .enumerate()
            .map(|(i, now)| match previous.chunks.get(i) {
                Some(before) if **before == *now => Arc::clone(before),
                _ => Arc::from(now),
            })
            .collect();
        SharedLog {
            chunks,
            len: items.len(),
        }
    }

    /// The first item, if there is one.
    pub fn first(&self) -> Option<&T> {
        self.get(0)
    }

    /// Every item, in order.
    pub fn iter(&self) -> impl Iterator<Item = &T> + '_ {
        self.into_iter()
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

impl<'a, T: Clone> IntoIterator for &'a SharedLog<T> {
    type Item = &'a T;
    type IntoIter = std::iter::FlatMap<
        std::slice::Iter<'a, Arc<[T]>>,
        std::slice::Iter<'a, T>,
        fn(&'a Arc<[T]>) -> std::slice::Iter<'a, T>,
    >;

    fn into_iter(self) -> Self::IntoIter {
        self.chunks.iter().flat_map(|c| c.iter())
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

    #[test]
    fn a_refreshed_snapshot_shares_the_chunks_that_did_not_change() {
        let mut items: Vec<u32> = (0..3 * CHUNK as u32 + 5).collect();
        let first = SharedLog::refresh(&SharedLog::default(), &items);
        items[CHUNK + 1] = 7;
        items.push(9);
        let second = SharedLog::refresh(&first, &items);
        assert_eq!(second.to_vec(), items);
        assert_eq!(second.first(), Some(&0));
        let shared: Vec<bool> = (first.chunks.iter().zip(&second.chunks))
            .map(|(a, b)| Arc::ptr_eq(a, b))
            .collect();
        // The changed chunk and the one that grew are copied; the others shared.
        assert_eq!(shared, [true, false, true, false]);
        let shorter = SharedLog::refresh(&second, &items[..CHUNK + 2]);
        assert_eq!(shorter.to_vec(), items[..CHUNK + 2]);
        assert!(Arc::ptr_eq(&shorter.chunks[0], &second.chunks[0]));
    }
}

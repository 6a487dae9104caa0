//! How much the API takes on at once. Heavy requests (CPU or disk work on the blocking pool:
//! the grid, the graph, covariances, nodes' details and clouds, GeoJSON) are bounded in
//! number and in how long they are waited for; event streams are bounded in number. One over
//! a bound is answered 503 with `Retry-After: 1` at once: nothing queues.

use super::{ApiError, Reply};
use crate::config::HttpConfig;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;
use tokio::sync::{OwnedSemaphorePermit, Semaphore};

/// The bounds, and the refusals counted for `/metrics`.
pub(super) struct Limits {
    heavy: Arc<Semaphore>,
    heavy_max: usize,
    heavy_timeout: Duration,
    streams: Arc<Semaphore>,
    streams_max: usize,
    /// Heavy requests refused because every slot was taken.
    pub(super) refused_busy: AtomicU64,
    /// Heavy requests answered 503 after `heavy_timeout`.
    pub(super) refused_timeout: AtomicU64,
    /// Event streams refused because every slot was taken.
    pub(super) refused_streams: AtomicU64,
}

impl Limits {
    pub(super) fn new(config: &HttpConfig) -> Limits {
        let (heavy_max, streams_max) = (config.heavy_requests.get(), config.event_streams.get());
        Limits {
            heavy: Arc::new(Semaphore::new(heavy_max)),
            heavy_max,
            heavy_timeout: Duration::from_millis(config.heavy_timeout_ms.get()),
            streams: Arc::new(Semaphore::new(streams_max)),
            streams_max,
            refused_busy: AtomicU64::new(0),
            refused_timeout: AtomicU64::new(0),
            refused_streams: AtomicU64::new(0),
        }
    }

    /// Runs `work` on the blocking pool in a free heavy slot, waiting at most the timeout.
    /// The slot goes with the work, not with the request: work whose request was answered 503
    /// after the timeout keeps its slot until it ends, so abandoned work cannot pile up.
    pub(super) async fn heavy<T: Send + 'static>(
        &self,
        work: impl FnOnce() -> Reply<T> + Send + 'static,
    ) -> Reply<T> {
        let task = self.in_heavy_slot(work)?;
        match tokio::time::timeout(self.heavy_timeout, task).await {
            Ok(done) => done.map_err(ApiError::internal)?,
            // Dropping the handle detaches the task: it runs on, holding its slot.
            Err(_) => {
                self.refused_timeout.fetch_add(1, Ordering::Relaxed);
                Err(ApiError::Busy(format!(
                    "not done within {} ms: try again, or ask for less (a bbox, max_cells)",
                    self.heavy_timeout.as_millis()
                )))
            }
        }
    }

    /// Heavy work whose outcome must be told (a write): bounded in number as [`Self::heavy`],
    /// but waited for to its end, since a 503 after the timeout would hide a write that still
    /// happens.
    pub(super) async fn heavy_write<T: Send + 'static>(
        &self,
        work: impl FnOnce() -> Reply<T> + Send + 'static,
    ) -> Reply<T> {
        let task = self.in_heavy_slot(work)?;
        task.await.map_err(ApiError::internal)?
    }

    /// `work` started on the blocking pool in a free heavy slot, which goes with it; busy
    /// when every slot is taken.
    fn in_heavy_slot<T: Send + 'static>(
        &self,
        work: impl FnOnce() -> Reply<T> + Send + 'static,
    ) -> Reply<tokio::task::JoinHandle<Reply<T>>> {
        let Ok(slot) = self.heavy.clone().try_acquire_owned() else {
            self.refused_busy.fetch_add(1, Ordering::Relaxed);
            return Err(ApiError::Busy(format!(
                "busy: {} heavy requests are being worked on, the most this mapper takes",
                self.heavy_max
            )));
        };
        Ok(tokio::task::spawn_blocking(move || {
            let _slot = slot;
            work()
        }))
    }

    /// A place for one event stream, held as long as the stream is open.
    pub(super) fn stream_slot(&self) -> Reply<OwnedSemaphorePermit> {
        self.streams.clone().try_acquire_owned().map_err(|_| {
            self.refused_streams.fetch_add(1, Ordering::Relaxed);
            ApiError::Busy(format!(
                "busy: {} event streams are open, the most this mapper serves",
                self.streams_max
            ))
        })
    }

    /// Heavy requests being worked on now (abandoned ones included).
    pub(super) fn heavy_running(&self) -> usize {
        self.heavy_max - self.heavy.available_permits()
    }

    /// Event streams open now.
    pub(super) fn streams_open(&self) -> usize {
        self.streams_max - self.streams.available_permits()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::num::{NonZeroU64, NonZeroUsize};
    use std::sync::mpsc;

    fn limits(heavy: usize, timeout_ms: u64, streams: usize) -> Limits {
        Limits::new(&HttpConfig {
            heavy_requests: NonZeroUsize::new(heavy).unwrap(),
            heavy_timeout_ms: NonZeroU64::new(timeout_ms).unwrap(),
            event_streams: NonZeroUsize::new(streams).unwrap(),
            ..HttpConfig::default()
        })
    }

    /// Work that runs until `release` is sent, then answers `v`.
    fn held(
        v: u32,
    ) -> (
        impl FnOnce() -> Reply<u32> + Send + 'static,
        mpsc::Sender<()>,
    ) {
        let (release, wait) = mpsc::channel::<()>();
        (
            move || {
                let _ = wait.recv();
                Ok(v)
            },
            release,
        )
    }

    fn is_busy(r: &Reply<u32>, says: &str) -> bool {
        matches!(r, Err(ApiError::Busy(why)) if why.contains(says))
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_full_limit_refuses_at_once_and_a_slot_frees_when_its_work_ends() {
        let l = Arc::new(limits(1, 60_000, 1));
        let (work, release) = held(7);
        let first = tokio::spawn({
            let l = l.clone();
            async move { l.heavy(work).await }
        });
        // Wait for the first to take its slot (no sleep: a bounded poll).
        while l.heavy_running() == 0 {
            tokio::time::sleep(Duration::from_millis(1)).await;
        }
        let second = l.heavy(|| Ok(8)).await;
        assert!(is_busy(&second, "busy: 1 heavy"), "{second:?}");
        release.send(()).unwrap();
        assert_eq!(first.await.unwrap().unwrap(), 7);
        assert_eq!(l.heavy_running(), 0);
        assert_eq!(l.heavy(|| Ok(9)).await.unwrap(), 9);
        assert_eq!(l.refused_busy.load(Ordering::Relaxed), 1);
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_timed_out_request_keeps_its_slot_until_its_work_ends() {
        let l = limits(1, 20, 1);
        let (work, release) = held(7);
        let late = l.heavy(work).await;
        assert!(is_busy(&late, "not done within 20 ms"), "{late:?}");
        // Its work still runs: the slot is still taken.
        assert_eq!(l.heavy_running(), 1);
        assert!(is_busy(&l.heavy(|| Ok(8)).await, "busy"));
        release.send(()).unwrap();
        while l.heavy_running() != 0 {
            tokio::time::sleep(Duration::from_millis(1)).await;
        }
        assert_eq!(l.heavy(|| Ok(9)).await.unwrap(), 9);
        assert_eq!(l.refused_timeout.load(Ordering::Relaxed), 1);
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_write_is_waited_for_past_the_timeout_and_holds_a_slot() {
        let l = Arc::new(limits(1, 20, 1));
        let (work, release) = held(7);
        let write = tokio::spawn({
            let l = l.clone();
            async move { l.heavy_write(work).await }
        });
        while l.heavy_running() == 0 {
            tokio::time::sleep(Duration::from_millis(1)).await;
        }
        assert!(is_busy(&l.heavy(|| Ok(8)).await, "busy: 1 heavy"));
        // Past the 20 ms a read would be answered in: the write's outcome still comes.
        tokio::time::sleep(Duration::from_millis(60)).await;
        release.send(()).unwrap();
        assert_eq!(write.await.unwrap().unwrap(), 7);
        assert_eq!(l.refused_timeout.load(Ordering::Relaxed), 0);
    }

    #[test]
    fn stream_slots_are_counted_and_given_back() {
        let l = limits(1, 1, 2);
        let a = l.stream_slot().unwrap();
        let _b = l.stream_slot().unwrap();
        assert!(matches!(l.stream_slot(), Err(ApiError::Busy(_))));
        assert_eq!(l.streams_open(), 2);
        drop(a);
        assert!(l.stream_slot().is_ok());
        assert_eq!(l.refused_streams.load(Ordering::Relaxed), 1);
    }
}

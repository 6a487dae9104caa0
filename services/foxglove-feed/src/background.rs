//! The feed's heavy work (a fleet's grid, clouds read from the store) on a thread of its own
//! at the lowest CPU priority: on busy cores the mapping, the acks and the HTTP API go first,
//! and the live view takes the time they leave (a grid comes later, a robot's node does not).

use std::sync::mpsc;

/// A job for the thread.
type Job = Box<dyn FnOnce() + Send>;

/// The thread's nice value: below the solver's (10), the lowest.
const FEED_NICE: i32 = 19;

/// Jobs waiting at most: the publisher waits for each of its jobs, so there is one.
const QUEUE: usize = 1;

/// The feed's background thread; it ends when this is dropped.
pub(crate) struct Background {
    jobs: mpsc::SyncSender<Job>,
}

impl Background {
    /// Starts the thread.
    pub(crate) fn start() -> std::io::Result<Background> {
        let (jobs, taken) = mpsc::sync_channel::<Job>(QUEUE);
        std::thread::Builder::new()
            .name("levelmap-foxglove".into())
            .spawn(move || {
                if let Err(e) = runtime::priority::lower_this_thread(FEED_NICE) {
                    tracing::warn!("the foxglove thread keeps its priority: {e}");
                }
                for job in taken {
                    job();
                }
            })?;
        Ok(Background { jobs })
    }

    /// `work`'s result, made on the thread; None when a job is waiting already or the
    /// thread is gone (it panicked).
    pub(crate) async fn run<T: Send + 'static>(
        &self,
        work: impl FnOnce() -> T + Send + 'static,
    ) -> Option<T> {
        let (done, result) = tokio::sync::oneshot::channel();
        let job: Job = Box::new(move || {
            let _ = done.send(work());
        });
        self.jobs.try_send(job).ok()?;
        result.await.ok()
    }
}

//! The feed's heavy work (a fleet's grid and graph, clouds read from the store) on a thread
//! of its own at the lowest CPU priority: on busy cores the mapping, the acks and the HTTP
//! API go first, and the live view takes the time they leave (a grid comes later, a robot's
//! node does not). The jobs publish what they make themselves: the publisher hands them over
//! and goes on, so the robots' poses keep coming while a grid is made.

use std::sync::mpsc;

/// A job for the thread.
type Job = Box<dyn FnOnce() + Send>;

/// The thread's nice value: below the solver's (10), the lowest.
const FEED_NICE: i32 = 19;

/// Jobs waiting at most (a fleet's map, each tick's clouds): one handed over beyond is
/// dropped, and what it would have published with it.
const QUEUE: usize = 16;

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

    /// Hands `work` to the thread: its result comes on the receiver once made. None when
    /// [`QUEUE`] jobs are waiting already or the thread is gone (it panicked).
    pub(crate) fn spawn<T: Send + 'static>(
        &self,
        work: impl FnOnce() -> T + Send + 'static,
    ) -> Option<tokio::sync::oneshot::Receiver<T>> {
        let (done, result) = tokio::sync::oneshot::channel();
        let job: Job = Box::new(move || {
            let _ = done.send(work());
        });
        self.jobs.try_send(job).ok()?;
        Some(result)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn jobs_run_in_order_and_a_full_queue_refuses_more() {
        let background = Background::start().expect("thread");
        let (started, running) = mpsc::channel::<()>();
        let (hold, held) = mpsc::channel::<()>();
        // The first job holds the thread until told: QUEUE more wait, one more is refused.
        let first = background
            .spawn(move || {
                started.send(()).expect("the test waits");
                held.recv().is_ok()
            })
            .expect("taken");
        running.recv().expect("the first job runs");
        let waiting: Vec<_> = (0..QUEUE)
            .map(|k| background.spawn(move || k).expect("a place in the queue"))
            .collect();
        assert!(background.spawn(|| 0).is_none(), "the queue is full");
        hold.send(()).expect("the first job waits");
        assert!(first.await.expect("made"));
        for (k, job) in waiting.into_iter().enumerate() {
            assert_eq!(job.await.expect("made"), k);
        }
    }
}

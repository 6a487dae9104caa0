//! How long the edge waits, without ack progress, before re-sending its unacked nodes: from
//! `resend_after_ms`, doubling after each re-send that brought no progress, up to
//! `resend_max_after_ms`. A dead link then costs one window of re-sends every few seconds
//! rather than every second (the partition drill counted 832–1,312 re-sends per robot before),
//! while any ack progress, or a new session, brings the wait back to its start.

use std::time::Duration;

/// The wait before the next re-send.
#[derive(Clone, Debug, PartialEq)]
pub struct ResendBackoff {
    first: Duration,
    max: Duration,
    now: Duration,
}

impl ResendBackoff {
    /// From `first`, doubling up to `max` (at least `first`).
    pub fn new(first: Duration, max: Duration) -> ResendBackoff {
        let max = max.max(first);
        ResendBackoff {
            first,
            max,
            now: first,
        }
    }

    /// The wait now.
    pub fn wait(&self) -> Duration {
        self.now
    }

    /// A re-send went out with no progress since the last: wait twice as long next time.
    pub fn resent(&mut self) {
        self.now = (self.now * 2).min(self.max);
    }

    /// Progress (an ack moved on) or a new session: back to the first wait.
    pub fn reset(&mut self) {
        self.now = self.first;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_wait_doubles_up_to_its_cap_and_progress_resets_it() {
        let s = Duration::from_secs;
        let mut backoff = ResendBackoff::new(s(1), s(8));
        let mut waits = Vec::new();
        for _ in 0..6 {
            waits.push(backoff.wait());
            backoff.resent();
        }
        assert_eq!(waits, [s(1), s(2), s(4), s(8), s(8), s(8)]);
        backoff.reset();
        assert_eq!(backoff.wait(), s(1));
        // A cap below the first wait is the first wait: no backoff, never shorter.
        let mut flat = ResendBackoff::new(s(2), s(1));
        flat.resent();
        assert_eq!(flat.wait(), s(2));
    }
}

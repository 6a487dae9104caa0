//! A site's ownership on one host, as a state machine free of I/O: what the host knows of
//! the site, what it observes (the lease's holder, the live hosts, the hosts whose process
//! is gone, the time, the outcome of what it did) and the next thing to do. The keeper
//! (the `keeper` module) only reads, writes and sends; every rule of who claims, keeps, drops and
//! hands back a site is here, each with a table test.
//!
//! A site is [`Waiting`] on a host that does not hold it, and [`Holding`] on the one that
//! does. Waiting, a host claims a free site when its turn comes (its rank in the site's
//! order over the live hosts, the last holder left out, times the stagger); the standby
//! (rank 0) takes the site from a holder whose process is gone, and follows the site's log
//! meanwhile. Holding, the host takes the site over, renews its lease every third of the
//! lease, drops the site when the lease is lost, and hands it back to a live host before it
//! in the order once that host has stayed alive.

use std::time::{Duration, Instant};

/// How often a site's standby reads what was appended to the site's log since.
pub const FOLLOW_EVERY: Duration = Duration::from_secs(1);

/// The pause before a failed takeover is tried again; doubled after each failure up to
/// [`MAX_TAKEOVER_RETRY`], but for an open of the log given up after its bound.
pub const FIRST_TAKEOVER_RETRY: Duration = Duration::from_millis(250);
/// The longest pause between failed takeovers.
pub const MAX_TAKEOVER_RETRY: Duration = Duration::from_secs(5);

/// A host that handed a site back does not claim it again for this long: the site's home
/// host claims it meanwhile.
pub const HAND_BACK_HOLD_OFF: Duration = Duration::from_secs(3);

/// A site is handed back at most this often: a home host that is alive but does not claim
/// it does not make the site bounce.
pub const HAND_BACK_EVERY: Duration = Duration::from_secs(60);

/// The times a site's ownership is ruled by (`[cluster]`).
#[derive(Clone, Copy, Debug)]
pub struct Times {
    /// A lease's time to live.
    pub ttl: Duration,
    /// Each host before another in a site's order gets this long to claim first.
    pub stagger: Duration,
    /// A holder keeps a site this long without a renewal answered (the lease and the grace).
    pub unrenewed_limit: Duration,
    /// A host before the holder in the order must have been alive this long to get the
    /// site back, and the holder must have held it this long.
    pub hand_back_after: Duration,
}

/// What a waiting host sees on one look.
pub struct Look<'a> {
    /// Now.
    pub now: Instant,
    /// This host.
    pub this: &'a str,
    /// The site's order over the live hosts; `None` before the hosts were first read.
    pub live: Option<Vec<&'a str>>,
    /// The lease's holder, or why it could not be read.
    pub holder: Result<Option<String>, String>,
    /// Whether a host's process is gone (its Zenoh token went).
    pub gone: &'a dyn Fn(&str) -> bool,
}

/// What a waiting host does after a look.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Act {
    /// Nothing this time.
    Wait,
    /// Read what was appended to the site's log since (the standby).
    Follow,
    /// Claim the free lease.
    Claim,
    /// Take the lease from its holder, whose process is gone.
    ClaimFrom(String),
}

/// What the keeper tells the operator of a look.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Note {
    /// The lease is read again after it could not be.
    ReadAgain,
    /// The lease could not be read (first time since it last was).
    Unread(String),
    /// The lease lapsed and its holder's process is gone: the standby does not wait for it.
    HolderGone(String),
    /// A claim failed (first time since the last success).
    ClaimFailed(String),
}

/// How a claim went.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Claimed {
    /// This host holds the lease now.
    Held,
    /// Another host was first.
    NotHeld,
    /// The bucket did not answer.
    Failed(String),
}

/// How a host's holding of a site ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Ended {
    /// The lease was lost (or the site could not be kept): dropped.
    Lost,
    /// Handed back to the site's home host: dropped, the lease released.
    HandedBack,
}

/// A site on a host that does not hold it.
#[derive(Debug)]
pub struct Waiting {
    times: Times,
    /// Since when the lease has been seen free, this time round.
    free_since: Option<Instant>,
    /// A failure was told and nothing has succeeded since.
    complained: bool,
    /// When the standby next reads the site's log.
    next_follow: Instant,
    /// No claim before this (a hand-back's hold-off).
    claim_from: Instant,
    /// When this host last handed the site back.
    handed_back: Option<Instant>,
    /// A lease's time after the lease last could not be read (an election): until then the
    /// holder, if alive, may claim its lapsed lease again first.
    unread_hold_off: Instant,
    /// The holder last seen: once the site is free, the ranks are taken without it.
    last_holder: Option<String>,
}

impl Waiting {
    /// A site this host has not looked at yet, at `now`.
    pub fn new(times: Times, now: Instant) -> Waiting {
        Waiting {
            times,
            free_since: None,
            complained: false,
            next_follow: now,
            claim_from: now,
            handed_back: None,
            unread_hold_off: now,
            last_holder: None,
        }
    }

    /// The next thing to do after `look`, and what to tell of it.
    pub fn step(&mut self, look: &Look) -> (Act, Vec<Note>) {
        let now = look.now;
        let mut notes = Vec::new();
        if self.complained && look.holder.is_ok() {
            notes.push(Note::ReadAgain);
            self.complained = false;
        }
        let act = match (&look.live, &look.holder) {
            (None, Ok(_)) => Act::Wait,
            (Some(live), Ok(None)) => self.free(look, live, &mut notes),
            (Some(live), Ok(Some(holder))) => {
                self.free_since = None;
                self.last_holder = Some(holder.clone());
                let standby = live.iter().find(|h| **h != holder.as_str()) == Some(&look.this);
                if standby && (look.gone)(holder) {
                    // Its process is gone (its Zenoh token went with its links): the lease
                    // would lapse only within a lease's time. Taken over now; were the holder
                    // alive after all, its renewal is refused and its append fenced.
                    Act::ClaimFrom(holder.clone())
                } else if standby && now >= self.next_follow {
                    self.next_follow = now + FOLLOW_EVERY;
                    Act::Follow
                } else {
                    Act::Wait
                }
            }
            (_, Err(e)) => {
                // The bucket may be electing a leader: once it answers, the site's holder
                // gets a lease's time to claim again a lease that lapsed meanwhile.
                self.unread_hold_off = now + self.times.ttl;
                if !self.complained {
                    notes.push(Note::Unread(e.clone()));
                    self.complained = true;
                }
                Act::Wait
            }
        };
        (act, notes)
    }

    /// A free lease: claimed once this host's turn has come.
    fn free(&mut self, look: &Look, live: &[&str], notes: &mut Vec<Note>) -> Act {
        let now = look.now;
        let last = self.last_holder.as_deref();
        let rank = live
            .iter()
            .filter(|h| last != Some(**h) || **h == look.this)
            .position(|h| *h == look.this)
            .unwrap_or(0) as u32;
        let holder_gone = last.is_some_and(|h| h != look.this && (look.gone)(h));
        if holder_gone && rank == 0 && self.unread_hold_off > now {
            notes.push(Note::HolderGone(last.unwrap_or_default().to_owned()));
            self.unread_hold_off = now;
        }
        let since = *self.free_since.get_or_insert(now);
        if now >= self.claim_at(rank, holder_gone, since) {
            self.free_since = None;
            Act::Claim
        } else {
            Act::Wait
        }
    }

    /// When a host of `rank` claims a site free since `free_since`. The standby (rank 0)
    /// need not wait for a gone holder; every other host still holds off, for the standby,
    /// whose reads of the bucket may come back later than its own after an election. The
    /// stagger counts from the end of a hold-off: hosts whose hold-offs end apart still
    /// claim in the site's order.
    fn claim_at(&self, rank: u32, holder_gone: bool, free_since: Instant) -> Instant {
        let hold_off = if holder_gone && rank == 0 {
            self.claim_from
        } else {
            self.claim_from.max(self.unread_hold_off)
        };
        free_since.max(hold_off) + self.times.stagger * rank
    }

    /// How the claim `act` asked for went; what to tell of it.
    pub fn claimed(&mut self, act: &Act, claimed: &Claimed) -> Option<Note> {
        match claimed {
            Claimed::Held => None,
            Claimed::NotHeld => {
                if matches!(act, Act::Claim | Act::ClaimFrom(_)) {
                    self.complained = false;
                }
                None
            }
            Claimed::Failed(e) if !self.complained => {
                self.complained = true;
                Some(Note::ClaimFailed(e.clone()))
            }
            Claimed::Failed(_) => None,
        }
    }

    /// Whether a holding that starts at `now` may hand the site back: not within
    /// [`HAND_BACK_EVERY`] of the last hand-back.
    pub fn may_hand_back(&self, now: Instant) -> bool {
        self.handed_back
            .is_none_or(|t| now.duration_since(t) >= HAND_BACK_EVERY)
    }

    /// This host's holding ended at `now`, as `ended` says.
    pub fn ended(&mut self, ended: Ended, now: Instant) {
        if ended == Ended::HandedBack {
            self.handed_back = Some(now);
            self.claim_from = now + HAND_BACK_HOLD_OFF;
        }
    }
}

/// How a takeover went.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum TakeoverEnded {
    /// The site is the worker's.
    Taken,
    /// The site's log did not open within its bound (it waited that long already).
    LogNotOpened,
    /// Anything else (its stream without a leader, the store).
    Failed,
}

/// How a renewal went.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Renewal {
    /// Renewed (or, lapsed while the bucket did not answer and claimed by nobody, claimed
    /// again).
    Renewed,
    /// Another host holds the lease now.
    Claimed,
    /// The bucket did not answer in time.
    Failed(String),
}

/// What a holding host does after a renewal.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Keep {
    /// Goes on holding the site.
    Hold,
    /// A renewal failed and is tried again (told).
    Retry(String),
    /// Takes the site over again: its journal was fenced, yet the lease is still this
    /// host's (a writer that lost its lease without knowing appended): the log is read
    /// again, its records with it.
    TakeOverAgain,
    /// Drops the site: the lease is lost.
    Drop(String),
    /// Hands the site back to this live host before it in the order.
    HandBack(String),
}

/// A site on the host that holds its lease.
#[derive(Debug)]
pub struct Holding {
    times: Times,
    claimed: Instant,
    renewed: Instant,
    /// The pause before the next takeover, if this one fails.
    retry: Duration,
    /// A takeover is under way.
    taking_over: bool,
    /// The worker holds the site.
    taken: bool,
    /// The site's journal was fenced since the last renewal that could act on it.
    fenced: bool,
    may_hand_back: bool,
}

impl Holding {
    /// The lease claimed at `now`: a takeover starts.
    pub fn new(times: Times, now: Instant, may_hand_back: bool) -> Holding {
        Holding {
            times,
            claimed: now,
            renewed: now,
            retry: FIRST_TAKEOVER_RETRY,
            taking_over: true,
            taken: false,
            fenced: false,
            may_hand_back,
        }
    }

    /// A takeover ended; the pause before the next one when it failed.
    pub fn takeover_ended(&mut self, ended: TakeoverEnded) -> Option<Duration> {
        match ended {
            TakeoverEnded::Taken => {
                self.taking_over = false;
                self.taken = true;
                self.retry = FIRST_TAKEOVER_RETRY;
                None
            }
            // Its stream may have no leader yet (an election takes 4–9 s): the site is
            // ours and nobody else serves it, so try again. An open given up has waited
            // its bound already: no longer pause.
            failed => {
                let pause = self.retry;
                self.retry = match failed {
                    TakeoverEnded::LogNotOpened => FIRST_TAKEOVER_RETRY,
                    _ => (self.retry * 2).min(MAX_TAKEOVER_RETRY),
                };
                Some(pause)
            }
        }
    }

    /// Whether the worker holds the site (its feeds may be declared).
    pub fn taken(&self) -> bool {
        self.taken
    }

    /// The site's journal was fenced.
    pub fn fence_rang(&mut self) {
        self.fenced = true;
    }

    /// After a renewal at `now`, with `home` the first live host before this one in the
    /// site's order that has been alive for `hand_back_after` (if any).
    pub fn renewed(&mut self, now: Instant, renewal: Renewal, home: Option<&str>) -> Keep {
        match renewal {
            Renewal::Renewed => self.renewed = now,
            Renewal::Claimed => return Keep::Drop("its lease was claimed by another host".into()),
            // Past the lease and its grace: the bucket does not come back, or this host is
            // cut from it. (Meanwhile another host may have claimed the site; if so, the
            // log fences this host's next append.)
            Renewal::Failed(e)
                if now.duration_since(self.renewed) >= self.times.unrenewed_limit =>
            {
                return Keep::Drop(format!("not renewed: {e}"));
            }
            Renewal::Failed(e) => return Keep::Retry(e),
        }
        if self.fenced {
            self.fenced = false;
            self.taking_over = true;
            return Keep::TakeOverAgain;
        }
        // Not within `hand_back_after` of the claim either: a site just taken over under
        // duress (its standby slow to claim) is not moved twice in a row.
        let settled = now.duration_since(self.claimed) >= self.times.hand_back_after;
        match home {
            Some(home) if self.may_hand_back && !self.taking_over && settled => {
                Keep::HandBack(home.to_owned())
            }
            _ => Keep::Hold,
        }
    }
}

#[cfg(test)]
mod tests;

//! One site's keeper on one host: claims the site's lease when it is free and this host's
//! turn has come (or, as the site's standby, takes it from a holder whose process is gone),
//! takes the site over, renews the lease, and drops the site when the lease is lost.

use super::Host;
use super::replay::{LogNotOpened, follow_round, take_over, take_over_after};
use crate::worker::Work;
use anyhow::Result;
use sitelog::{Lease, SiteLog};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// How often a host looks whether a site it does not own is free.
const POLL: Duration = Duration::from_millis(250);

/// How often a site's standby reads what was appended to the site's log since.
const FOLLOW_EVERY: Duration = Duration::from_secs(1);

/// The pause before a failed takeover is tried again; doubled after each failure up to
/// `MAX_TAKEOVER_RETRY`, but for an open of the log given up after its bound.
const FIRST_TAKEOVER_RETRY: Duration = Duration::from_millis(250);
const MAX_TAKEOVER_RETRY: Duration = Duration::from_secs(5);

/// A host that handed a site back does not claim it again for this long: the site's home
/// host claims it meanwhile.
const HAND_BACK_HOLD_OFF: Duration = Duration::from_secs(3);

/// A site is handed back at most this often: a home host that is alive but does not claim
/// it does not make the site bounce.
const HAND_BACK_EVERY: Duration = Duration::from_secs(60);

/// How a host claims a site.
enum Claim {
    /// Free: its lease lapsed or was released.
    Free,
    /// From its holder, whose process is gone.
    From(String),
}

/// When a host's turn comes to claim a free site.
struct Turn {
    /// Its place in the site's order over the live hosts, the last holder left out.
    rank: u32,
    /// Each host before it in that order gets this long to claim first.
    stagger: Duration,
    /// The last holder's process is gone (its Zenoh token went): it claims nothing again.
    holder_gone: bool,
    /// No claim before this (a hand-back's hold-off).
    claim_from: Instant,
    /// A lease's time after the lease last could not be read (an election): until then the
    /// holder, if alive, may claim its lapsed lease again first.
    unread_hold_off: Instant,
}

impl Turn {
    /// For a site free since `free_since`. The standby (rank 0) need not wait for a gone
    /// holder; every other host still holds off, for the standby, whose reads of the bucket may
    /// come back later than its own after an election. The stagger counts from the end of a
    /// hold-off: hosts whose hold-offs end apart still claim in the site's order.
    fn claim_at(&self, free_since: Instant) -> Instant {
        let hold_off = if self.holder_gone && self.rank == 0 {
            self.claim_from
        } else {
            self.claim_from.max(self.unread_hold_off)
        };
        free_since.max(hold_off) + self.stagger * self.rank
    }
}

/// How a host's ownership of a site ended.
enum Owned {
    /// The mapper is stopping.
    Stopping,
    /// The lease was lost (or the site could not be kept): dropped.
    Lost,
    /// Handed back to the site's home host: dropped, the lease released.
    HandedBack,
}

/// Keeps `site` on this host while it may, until the mapper stops.
pub(super) async fn keep(host: Arc<Host>, site: String) {
    let names: Vec<&str> = host.cluster.hosts.iter().map(String::as_str).collect();
    let order = sitelog::host_order(&site, &names);
    let this = host.cluster.host.as_str();
    let mut stopping = host.shared.stopping.subscribe();
    let mut free_since: Option<Instant> = None;
    let mut complained = false;
    // While another host owns the site and this one is next in its order: its log, as read.
    let mut follower: Option<SiteLog> = None;
    let mut next_follow = Instant::now();
    let mut follow_failed = false;
    let (mut claim_from, mut handed_back) = (Instant::now(), None::<Instant>);
    // After the lease could not be read (the bucket electing a leader): until then the site's
    // holder, if alive, may claim its lapsed lease again first.
    let mut unread_hold_off = Instant::now();
    // The holder last seen: once the site is free, the ranks are taken without it, so that
    // its standby claims at once and the others after their stagger.
    let mut last_holder: Option<String> = None;
    loop {
        if *stopping.borrow() {
            return;
        }
        // The order over the live hosts, once this host has read who is alive.
        let live = host.presence.live_order(&order, this);
        // Bounded: a read lost in an election would time out only after the client's 5 s,
        // and the hold-off after it (below) would start that much later.
        let ttl = host.leases.ttl();
        let holder = sitelog::within(ttl / 3, host.leases.holder(&site)).await;
        if complained && holder.is_ok() {
            tracing::info!(site, "cluster: the lease is read again");
            complained = false;
        }
        let claim = match (live, holder) {
            (None, Ok(_)) => None,
            (Some(live), Ok(None)) => {
                let rank = live
                    .iter()
                    .filter(|h| last_holder.as_deref() != Some(**h) || **h == this)
                    .position(|h| *h == this)
                    .unwrap_or(0) as u32;
                let holder_gone = last_holder
                    .as_deref()
                    .is_some_and(|h| h != this && host.tokens.gone(h));
                if holder_gone && rank == 0 && unread_hold_off > Instant::now() {
                    tracing::info!(
                        site,
                        holder = last_holder.as_deref(),
                        "cluster: the lease lapsed and its holder's process is gone (its \
                         Zenoh token went): not waiting for it to claim again"
                    );
                    unread_hold_off = Instant::now();
                }
                let turn = Turn {
                    rank,
                    stagger: Duration::from_millis(host.cluster.claim_stagger_ms),
                    holder_gone,
                    claim_from,
                    unread_hold_off,
                };
                let since = *free_since.get_or_insert_with(Instant::now);
                (Instant::now() >= turn.claim_at(since)).then(|| {
                    free_since = None;
                    Claim::Free
                })
            }
            (Some(live), Ok(Some(holder))) => {
                free_since = None;
                last_holder = Some(holder.clone());
                let standby = live.iter().find(|h| **h != holder) == Some(&this);
                if standby && host.tokens.gone(&holder) {
                    // Its process is gone (its Zenoh token went with its links): the lease
                    // would lapse only within a lease's time. Taken over now; were the
                    // holder alive after all, its renewal is refused and its append fenced.
                    Some(Claim::From(holder))
                } else {
                    if standby && Instant::now() >= next_follow {
                        next_follow = Instant::now() + FOLLOW_EVERY;
                        follow_round(&host, &site, &mut follower, &mut follow_failed).await;
                    }
                    None
                }
            }
            (_, Err(e)) => {
                // The bucket may be electing a leader: once it answers, the site's holder
                // gets a lease's time to claim again a lease that lapsed meanwhile.
                unread_hold_off = Instant::now() + ttl;
                if !complained {
                    tracing::warn!(site, "cluster: the lease cannot be read: {e}");
                    complained = true;
                }
                None
            }
        };
        let claimed = match &claim {
            Some(Claim::Free) => host.leases.claim(&site, this).await,
            Some(Claim::From(holder)) => host.leases.claim_from(&site, this, holder).await,
            None => Ok(None),
        };
        if let (Some(Claim::From(holder)), Ok(Some(_))) = (&claim, &claimed) {
            tracing::info!(
                site,
                holder,
                "cluster: the holder's process is gone (its Zenoh token went): its lease \
                 taken over before it lapsed"
            );
            host.shared.instruments.leases_taken_from_gone.inc();
        }
        match claimed {
            Ok(Some(lease)) => {
                let may_hand_back = handed_back.is_none_or(|t| t.elapsed() >= HAND_BACK_EVERY);
                match own(&host, lease, &order, may_hand_back, &mut stopping).await {
                    Owned::Stopping => return,
                    Owned::Lost => {}
                    Owned::HandedBack => {
                        handed_back = Some(Instant::now());
                        claim_from = Instant::now() + HAND_BACK_HOLD_OFF;
                    }
                }
            }
            Ok(None) => {
                if claim.is_some() {
                    complained = false;
                }
            }
            Err(e) if !complained => {
                tracing::warn!(site, "cluster: claiming the lease: {e}");
                complained = true;
            }
            Err(_) => {}
        }
        tokio::select! {
            _ = tokio::time::sleep(POLL) => {}
            _ = stopping.changed() => {}
        }
    }
}

/// Owns the site while `lease` holds: takes it over, renews the lease, and, when
/// `may_hand_back`, hands the site back to a live host before this one in its `order`
/// once that host has been alive for `hand_back_after_ms`. The lease is left held when the
/// mapper stops, for `Cluster::release_all` once the worker stopped.
async fn own(
    host: &Arc<Host>,
    lease: Lease,
    order: &[&str],
    may_hand_back: bool,
    stopping: &mut tokio::sync::watch::Receiver<bool>,
) -> Owned {
    let site = lease.site.clone();
    let claimed = Instant::now();
    tracing::info!(site, "cluster: lease claimed; taking the site over");
    host.held
        .lock()
        .expect("leases lock")
        .insert(site.clone(), lease);
    let mut takeover = Some(tokio::spawn(take_over(host.clone(), site.clone())));
    let ttl = host.leases.ttl();
    let mut renewed = Instant::now();
    let mut retry = FIRST_TAKEOVER_RETRY;
    // The site's feeds, declared once it is taken over, undeclared when this returns.
    let (mut taken, mut feeds) = (false, None);
    loop {
        tokio::select! {
            done = async { takeover.as_mut().expect("guarded").await }, if takeover.is_some() => {
                takeover = None;
                match done {
                    Ok(Ok(records)) => {
                        crate::views::instruments::Instruments::time(
                            &host.shared.instruments.takeover,
                            claimed.elapsed(),
                        );
                        tracing::info!(
                            site,
                            records,
                            "cluster: site taken over {:.0} ms after its lease was claimed",
                            claimed.elapsed().as_secs_f64() * 1e3
                        );
                        taken = true;
                    }
                    Ok(Err(e)) => {
                        // Its stream may have no leader yet (an election takes 4–9 s): the
                        // site is ours and nobody else serves it, so try again.
                        tracing::warn!(
                            site,
                            "cluster: takeover failed, trying again in {retry:?}: {e:#}"
                        );
                        takeover = Some(tokio::spawn(take_over_after(
                            retry,
                            host.clone(),
                            site.clone(),
                        )));
                        // An open given up has waited its bound already: no longer pause.
                        retry = if e.is::<LogNotOpened>() {
                            FIRST_TAKEOVER_RETRY
                        } else {
                            (retry * 2).min(MAX_TAKEOVER_RETRY)
                        };
                    }
                    Err(e) => tracing::error!(site, "cluster: takeover failed: {e}"),
                }
            }
            _ = tokio::time::sleep(ttl / 3) => {}
            _ = stopping.changed() => return Owned::Stopping,
        }
        if taken && feeds.is_none() {
            match host.feeds.declare(&site).await {
                Ok(declared) => feeds = Some(declared),
                Err(e) => tracing::warn!(site, "cluster: the site's feeds not declared yet: {e:#}"),
            }
        }
        let fenced = host.fenced.lock().expect("fenced lock").remove(&site);
        let Some(mut lease) = host.held.lock().expect("leases lock").get(&site).cloned() else {
            return Owned::Lost;
        };
        // A renewal that does not answer within a third of the lease counts as failed: a
        // host cut off from NATS must notice before its lease lapses.
        let renewal = sitelog::within(ttl / 3, host.leases.renew(&mut lease)).await;
        let renewal = match renewal {
            // Lapsed while the bucket did not answer, and nobody claimed it (or renewed
            // without this host hearing the answer): ours again.
            Ok(false) => match host.leases.claim_again(&site, &host.cluster.host).await {
                Ok(Some(again)) => {
                    tracing::warn!(
                        site,
                        "cluster: the lease lapsed unrenewed; claimed again, the map kept"
                    );
                    host.shared.instruments.leases_reclaimed.inc();
                    lease = again;
                    Ok(true)
                }
                Ok(None) => Ok(false),
                Err(e) => Err(e),
            },
            other => other,
        };
        let lost = match renewal {
            Ok(true) => {
                renewed = Instant::now();
                host.held
                    .lock()
                    .expect("leases lock")
                    .insert(site.clone(), lease);
                if fenced {
                    // The worker dropped the site on a fenced append, yet the lease is
                    // still ours: a writer that lost its lease without knowing appended.
                    // Read the log again, its records with it, and go on.
                    tracing::warn!(
                        site,
                        "cluster: fenced while holding the lease; taking the site over again"
                    );
                    finish(takeover.take()).await;
                    takeover = Some(tokio::spawn(take_over(host.clone(), site.clone())));
                }
                None
            }
            Ok(false) => Some("its lease was claimed by another host".to_owned()),
            // Past the lease and its grace: the bucket does not come back, or this host is
            // cut from it. (Meanwhile another host may have claimed the site; if so, the
            // log fences this host's next append.)
            Err(e) if renewed.elapsed() >= host.cluster.unrenewed_limit() => {
                Some(format!("not renewed: {e}"))
            }
            Err(e) => {
                tracing::warn!(site, "cluster: renewal failed, retrying: {e}");
                None
            }
        };
        if let Some(why) = lost {
            tracing::warn!(site, "cluster: lease lost ({why}); dropping the site");
            host.held.lock().expect("leases lock").remove(&site);
            // A takeover under way hands the site to the worker first: drop it after.
            finish(takeover).await;
            drop_site(host, &site).await;
            return Owned::Lost;
        }
        // Not within `hand_back_after_ms` of the claim either: a site just taken over under
        // duress (its standby slow to claim) is not moved twice in a row.
        let settled = Duration::from_millis(host.cluster.hand_back_after_ms);
        if may_hand_back
            && takeover.is_none()
            && claimed.elapsed() >= settled
            && let Some(home) = host
                .presence
                .home_before(order, &host.cluster.host, settled)
        {
            hand_back(host, &site, home).await;
            return Owned::HandedBack;
        }
    }
}

/// Gives `site` to `home`, a live host before this one in its order: the site dropped here
/// first (no more appends or acks from this host), then its lease released, so that `home`
/// claims it at once. Its robots see a pause of acks.
async fn hand_back(host: &Arc<Host>, site: &str, home: &str) {
    tracing::info!(
        site,
        home,
        "cluster: handing the site back to {home}, before this host in its order"
    );
    drop_site(host, site).await;
    let lease = host.held.lock().expect("leases lock").remove(site);
    if let Some(lease) = lease
        && let Err(e) = host.leases.release(lease).await
    {
        tracing::warn!(site, "cluster: lease not released (it lapses): {e}");
    }
    host.shared.instruments.sites_handed_back.inc();
}

/// Waits for a takeover under way to end.
async fn finish(takeover: Option<tokio::task::JoinHandle<Result<usize>>>) {
    if let Some(t) = takeover {
        let _ = t.await;
    }
}

/// Tells the worker to drop `site`, and waits until it did.
async fn drop_site(host: &Host, site: &str) {
    let (reply, dropped) = tokio::sync::oneshot::channel();
    let work = host.work.clone();
    let drop = Work::Drop {
        site: site.to_owned(),
        reply,
    };
    if tokio::task::spawn_blocking(move || work.send(drop))
        .await
        .is_ok_and(|sent| sent.is_ok())
    {
        let _ = dropped.await;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn turn(rank: u32, holder_gone: bool, now: Instant) -> Turn {
        Turn {
            rank,
            stagger: Duration::from_millis(500),
            holder_gone,
            claim_from: now,
            unread_hold_off: now + Duration::from_secs(3),
        }
    }

    #[test]
    fn after_an_election_the_standby_alone_skips_the_wait_for_a_gone_holder() {
        let now = Instant::now();
        assert_eq!(turn(0, true, now).claim_at(now), now);
        // CI saw h2 read the free lease 1.2 s before the standby: it must still wait.
        let second = turn(1, true, now).claim_at(now);
        assert_eq!(second, now + Duration::from_millis(3500));
    }

    #[test]
    fn a_live_holder_gets_its_lease_time_and_the_order_holds_after_it() {
        let now = Instant::now();
        let standby = turn(0, false, now).claim_at(now);
        let second = turn(1, false, now).claim_at(now);
        assert_eq!(standby, now + Duration::from_secs(3));
        assert_eq!(second - standby, Duration::from_millis(500));
        // Without a hold-off the stagger counts from when the site was seen free.
        let free = Turn {
            unread_hold_off: now,
            ..turn(2, false, now)
        };
        assert_eq!(free.claim_at(now), now + Duration::from_secs(1));
    }
}

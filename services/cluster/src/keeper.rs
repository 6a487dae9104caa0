//! One site's keeper on one host: the driver of the site's ownership state machine
//! ([`crate::ownership`]). It reads the lease and the live hosts, claims, takes the site over,
//! renews, drops and hands back as the state machine says; the rules are all there.

use super::Host;
use super::ownership::{
    Act, Claimed, Ended, Holding, Keep, Look, Note, Renewal, TakeoverEnded, Times, Waiting,
};
use super::replay::{LogNotOpened, TakenOver, follow_round, take_over, take_over_after};
use anyhow::Result;
use mapper::inbox::Work;
use sitelog::{Lease, SiteLog};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// How often a host looks whether a site it does not own is free.
const POLL: Duration = Duration::from_millis(250);

/// How a host's holding of a site ended, for the keeper's loop.
enum Owned {
    /// The mapper is stopping.
    Stopping,
    /// Lost or handed back.
    Ended(Ended),
}

/// The times `[cluster]` sets.
fn times(host: &Host) -> Times {
    Times {
        ttl: host.cluster.ttl(),
        stagger: Duration::from_millis(host.cluster.claim_stagger_ms),
        unrenewed_limit: host.cluster.unrenewed_limit(),
        hand_back_after: Duration::from_millis(host.cluster.hand_back_after_ms),
    }
}

/// Keeps `site` on this host while it may, until the mapper stops: looks at the lease and
/// the live hosts, does what [`Waiting::step`] says, and holds the site when a claim wins.
pub(super) async fn keep(host: Arc<Host>, site: String) {
    let names: Vec<&str> = host.cluster.hosts.iter().map(String::as_str).collect();
    let order = sitelog::host_order(&site, &names);
    let this = host.cluster.host.as_str();
    let mut stopping = host.shared.stopping.subscribe();
    let mut waiting = Waiting::new(times(&host), Instant::now());
    // While another host owns the site and this one is next in its order: its log, as read.
    let mut follower: Option<SiteLog> = None;
    let mut follow_failed = false;
    loop {
        if *stopping.borrow() {
            return;
        }
        // Bounded: a read lost in an election would time out only after the client's 5 s,
        // and the hold-off after it would start that much later.
        let ttl = host.leases.ttl();
        let holder = sitelog::within(ttl / 3, host.leases.holder(&site)).await;
        let gone = |h: &str| host.tokens.gone(h);
        let (act, notes) = waiting.step(&Look {
            now: Instant::now(),
            this,
            // The order over the live hosts, once this host has read who is alive.
            live: host.presence.live_order(&order, this),
            holder: holder.map_err(|e| e.to_string()),
            gone: &gone,
        });
        for note in notes {
            tell(&site, &note);
        }
        let claimed = match &act {
            Act::Wait => None,
            Act::Follow => {
                follow_round(&host, &site, &mut follower, &mut follow_failed).await;
                None
            }
            Act::Claim => Some(host.leases.claim(&site, this).await),
            Act::ClaimFrom(holder) => Some(host.leases.claim_from(&site, this, holder).await),
        };
        if let Some(claimed) = claimed {
            let outcome = match &claimed {
                Ok(Some(_)) => Claimed::Held,
                Ok(None) => Claimed::NotHeld,
                Err(e) => Claimed::Failed(e.to_string()),
            };
            if let Some(note) = waiting.claimed(&act, &outcome) {
                tell(&site, &note);
            }
            if let Ok(Some(lease)) = claimed {
                if let Act::ClaimFrom(holder) = &act {
                    tracing::info!(
                        site,
                        holder,
                        "cluster: the holder's process is gone (its Zenoh token went): its \
                         lease taken over before it lapsed"
                    );
                    host.shared.instruments.leases_taken_from_gone.inc();
                }
                let may_hand_back = waiting.may_hand_back(Instant::now());
                match own(&host, lease, &order, may_hand_back, &mut stopping).await {
                    Owned::Stopping => return,
                    Owned::Ended(ended) => waiting.ended(ended, Instant::now()),
                }
            }
        }
        tokio::select! {
            _ = tokio::time::sleep(POLL) => {}
            _ = stopping.changed() => {}
        }
    }
}

/// Logs what a look or a claim told.
fn tell(site: &str, note: &Note) {
    match note {
        Note::ReadAgain => tracing::info!(site, "cluster: the lease is read again"),
        Note::Unread(e) => tracing::warn!(site, "cluster: the lease cannot be read: {e}"),
        Note::HolderGone(holder) => tracing::info!(
            site,
            holder,
            "cluster: the lease lapsed and its holder's process is gone (its Zenoh token \
             went): not waiting for it to claim again"
        ),
        Note::ClaimFailed(e) => tracing::warn!(site, "cluster: claiming the lease: {e}"),
    }
}

/// A takeover under way, and the fence alarm of the last one that succeeded.
type Takeover = tokio::task::JoinHandle<Result<TakenOver>>;

/// Owns the site while `lease` holds: takes it over, renews the lease every third of its
/// time, and does what [`Holding::renewed`] says. The lease is left held when the mapper
/// stops, for `Cluster::release_all` once the worker stopped.
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
    let mut holding = Holding::new(times(host), claimed, may_hand_back);
    let mut takeover: Option<Takeover> = Some(tokio::spawn(take_over(host.clone(), site.clone())));
    let ttl = host.leases.ttl();
    // The site's feeds, declared once it is taken over, undeclared when this returns.
    let mut feeds = None;
    // Rings when the journal's append was fenced while this host holds the site.
    let mut fence_alarm: Option<tokio::sync::oneshot::Receiver<()>> = None;
    loop {
        tokio::select! {
            rang = async { fence_alarm.as_mut().expect("guarded").await }, if fence_alarm.is_some() => {
                fence_alarm = None;
                // Dropped unrung: the site left the journal without a fence.
                if rang.is_ok() {
                    holding.fence_rang();
                }
            }
            done = async { takeover.as_mut().expect("guarded").await }, if takeover.is_some() => {
                takeover = None;
                let ended = match done {
                    Ok(Ok((records, alarm))) => {
                        fence_alarm = Some(alarm);
                        mapper::views::instruments::Instruments::time(
                            &host.shared.instruments.takeover,
                            claimed.elapsed(),
                        );
                        tracing::info!(
                            site,
                            records,
                            "cluster: site taken over {:.0} ms after its lease was claimed",
                            claimed.elapsed().as_secs_f64() * 1e3
                        );
                        TakeoverEnded::Taken
                    }
                    Ok(Err(e)) if e.is::<LogNotOpened>() => {
                        tracing::warn!(site, "cluster: takeover failed: {e:#}");
                        TakeoverEnded::LogNotOpened
                    }
                    Ok(Err(e)) => {
                        tracing::warn!(site, "cluster: takeover failed: {e:#}");
                        TakeoverEnded::Failed
                    }
                    Err(e) => {
                        tracing::error!(site, "cluster: takeover failed: {e}");
                        TakeoverEnded::Failed
                    }
                };
                if let Some(pause) = holding.takeover_ended(ended) {
                    tracing::info!(site, "cluster: takeover tried again in {pause:?}");
                    let again = take_over_after(pause, host.clone(), site.clone());
                    takeover = Some(tokio::spawn(again));
                }
            }
            _ = tokio::time::sleep(ttl / 3) => {}
            _ = stopping.changed() => return Owned::Stopping,
        }
        if holding.taken() && feeds.is_none() {
            match host.feeds.declare(&site).await {
                Ok(declared) => feeds = Some(declared),
                Err(e) => tracing::warn!(site, "cluster: the site's feeds not declared yet: {e:#}"),
            }
        }
        let Some(lease) = host.held.lock().expect("leases lock").get(&site).cloned() else {
            return Owned::Ended(Ended::Lost);
        };
        let renewal = renew(host, &site, lease).await;
        let settled = Duration::from_millis(host.cluster.hand_back_after_ms);
        let home = host
            .presence
            .home_before(order, &host.cluster.host, settled);
        match holding.renewed(Instant::now(), renewal, home) {
            Keep::Hold => {}
            Keep::Retry(e) => tracing::warn!(site, "cluster: renewal failed, retrying: {e}"),
            Keep::TakeOverAgain => {
                tracing::warn!(
                    site,
                    "cluster: fenced while holding the lease; taking the site over again"
                );
                finish(takeover.take()).await;
                takeover = Some(tokio::spawn(take_over(host.clone(), site.clone())));
            }
            Keep::Drop(why) => {
                tracing::warn!(site, "cluster: lease lost ({why}); dropping the site");
                host.held.lock().expect("leases lock").remove(&site);
                // A takeover under way hands the site to the worker first: drop it after.
                finish(takeover).await;
                drop_site(host, &site).await;
                return Owned::Ended(Ended::Lost);
            }
            Keep::HandBack(home) => {
                hand_back(host, &site, &home).await;
                return Owned::Ended(Ended::HandedBack);
            }
        }
    }
}

/// Renews `lease` (bounded by a third of the lease: a host cut off from NATS must notice
/// before its lease lapses); one that lapsed while the bucket did not answer, and that
/// nobody claimed, is claimed again. The lease held is updated.
async fn renew(host: &Host, site: &str, mut lease: Lease) -> Renewal {
    let ttl = host.leases.ttl();
    let renewal = match sitelog::within(ttl / 3, host.leases.renew(&mut lease)).await {
        Ok(true) => Ok(true),
        Ok(false) => match host.leases.claim_again(site, &host.cluster.host).await {
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
        Err(e) => Err(e),
    };
    match renewal {
        Ok(true) => {
            host.held
                .lock()
                .expect("leases lock")
                .insert(site.to_owned(), lease);
            Renewal::Renewed
        }
        Ok(false) => Renewal::Claimed,
        Err(e) => Renewal::Failed(e.to_string()),
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
async fn finish(takeover: Option<Takeover>) {
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

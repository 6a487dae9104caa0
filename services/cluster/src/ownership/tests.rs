//! One table test per rule of a site's ownership: each row is a situation and what the
//! host must do in it.

use super::*;

const TIMES: Times = Times {
    ttl: Duration::from_secs(3),
    stagger: Duration::from_millis(500),
    unrenewed_limit: Duration::from_secs(13),
    hand_back_after: Duration::from_secs(10),
};

const MS: Duration = Duration::from_millis(1);

fn none_gone(_: &str) -> bool {
    false
}

fn h1_gone(host: &str) -> bool {
    host == "h1"
}

/// A look by `this` at `at`, the live order h1 h2 h3, the lease held by `holder`.
fn look<'a>(
    this: &'a str,
    at: Instant,
    holder: Option<&str>,
    gone: &'a dyn Fn(&str) -> bool,
) -> Look<'a> {
    Look {
        now: at,
        this,
        live: Some(vec!["h1", "h2", "h3"]),
        holder: Ok(holder.map(str::to_owned)),
        gone,
    }
}

/// How long after `from`, in steps of 10 ms, `this` claims the free lease; `None` if it does
/// not within 5 s.
fn claims_after(
    waiting: &mut Waiting,
    this: &str,
    from: Instant,
    gone: &dyn Fn(&str) -> bool,
) -> Option<Duration> {
    let mut t = from;
    while t <= from + Duration::from_secs(5) {
        if waiting.step(&look(this, t, None, gone)).0 == Act::Claim {
            return Some(t - from);
        }
        t += 10 * MS;
    }
    None
}

#[test]
fn a_free_site_is_claimed_in_its_order_each_host_a_stagger_after_the_one_before() {
    // (host, how long after the lease is first seen free it claims)
    let table = [("h1", 0), ("h2", 500), ("h3", 1000)];
    for (host, after_ms) in table {
        let start = Instant::now();
        let mut waiting = Waiting::new(TIMES, start);
        let at = claims_after(&mut waiting, host, start, &none_gone);
        assert_eq!(at, Some(after_ms * MS), "{host}");
    }
}

#[test]
fn the_last_holder_is_left_out_of_the_order_so_its_standby_claims_first() {
    // h1 held the site and its lease lapsed: h2 is first now, h3 second, and h1 itself,
    // were it alive, keeps its own rank 0.
    let table = [("h1", 0), ("h2", 0), ("h3", 500)];
    for (host, after_ms) in table {
        let start = Instant::now();
        let mut waiting = Waiting::new(TIMES, start);
        waiting.step(&look(host, start, Some("h1"), &none_gone));
        let at = claims_after(&mut waiting, host, start, &none_gone);
        assert_eq!(at, Some(after_ms * MS), "{host}");
    }
}

#[test]
fn after_an_unread_lease_a_live_holder_gets_a_leases_time_to_claim_again() {
    // The bucket did not answer (an election); then the lease is free. Its holder h1 is
    // alive: h2 (the standby) waits a lease's time, h3 that and a stagger.
    let table = [("h2", 3000), ("h3", 3500)];
    for (host, after_ms) in table {
        let start = Instant::now();
        let mut waiting = Waiting::new(TIMES, start);
        waiting.step(&look(host, start, Some("h1"), &none_gone));
        let unread = Look {
            holder: Err("no leader".into()),
            ..look(host, start, None, &none_gone)
        };
        let (act, notes) = waiting.step(&unread);
        assert_eq!(
            (act, notes),
            (Act::Wait, vec![Note::Unread("no leader".into())])
        );
        let at = claims_after(&mut waiting, host, start, &none_gone);
        assert_eq!(at, Some(after_ms * MS), "{host}");
    }
}

#[test]
fn after_an_unread_lease_only_the_standby_skips_the_wait_for_a_gone_holder() {
    // As above, but h1's process is gone: the standby claims at once; h3 still waits, for
    // the standby, whose reads may come back later than its own (CI saw 1.2 s).
    let table = [("h2", 0, true), ("h3", 3500, false)];
    for (host, after_ms, told) in table {
        let start = Instant::now();
        let mut waiting = Waiting::new(TIMES, start);
        waiting.step(&look(host, start, Some("h1"), &h1_gone));
        let unread = Look {
            holder: Err("no leader".into()),
            ..look(host, start, None, &h1_gone)
        };
        waiting.step(&unread);
        let (act, notes) = waiting.step(&look(host, start, None, &h1_gone));
        let holder_gone = notes.contains(&Note::HolderGone("h1".into()));
        assert_eq!(holder_gone, told, "{host}: {notes:?}");
        assert!(notes.contains(&Note::ReadAgain), "{host}: {notes:?}");
        let at = match act {
            Act::Claim => Some(Duration::ZERO),
            _ => claims_after(&mut waiting, host, start, &h1_gone),
        };
        assert_eq!(at, Some(after_ms * MS), "{host}");
    }
}

#[test]
fn the_standby_takes_the_lease_from_a_holder_whose_process_is_gone_and_no_one_else_does() {
    // (host, whether h1's process is gone, what it does with h1 holding the lease)
    let table = [
        ("h2", true, Act::ClaimFrom("h1".into())),
        ("h3", true, Act::Wait),
        ("h2", false, Act::Follow),
        ("h3", false, Act::Wait),
    ];
    for (host, gone, want) in table {
        let now = Instant::now();
        let mut waiting = Waiting::new(TIMES, now);
        let gone: &dyn Fn(&str) -> bool = if gone { &h1_gone } else { &none_gone };
        let (act, _) = waiting.step(&look(host, now, Some("h1"), gone));
        assert_eq!(act, want, "{host}");
    }
}

#[test]
fn the_standby_follows_the_log_once_a_second() {
    let start = Instant::now();
    let mut waiting = Waiting::new(TIMES, start);
    // (ms after the start, what the standby does)
    let table = [
        (0, Act::Follow),
        (250, Act::Wait),
        (999, Act::Wait),
        (1000, Act::Follow),
    ];
    for (ms, want) in table {
        let (act, _) = waiting.step(&look("h2", start + ms * MS, Some("h1"), &none_gone));
        assert_eq!(act, want, "{ms} ms");
    }
}

#[test]
fn nothing_is_claimed_before_the_live_hosts_are_known() {
    let now = Instant::now();
    let mut waiting = Waiting::new(TIMES, now);
    for t in [0, 1000, 10_000] {
        let blind = Look {
            live: None,
            ..look("h1", now + t * MS, None, &none_gone)
        };
        assert_eq!(waiting.step(&blind).0, Act::Wait, "{t} ms");
    }
}

#[test]
fn a_host_that_handed_a_site_back_holds_off_and_hands_back_at_most_once_a_minute() {
    let start = Instant::now();
    let mut waiting = Waiting::new(TIMES, start);
    assert!(waiting.may_hand_back(start));
    waiting.ended(Ended::HandedBack, start);
    // h1 ranks first, yet it does not claim the site it gave away for the hold-off.
    let at = claims_after(&mut waiting, "h1", start, &none_gone);
    assert_eq!(at, Some(HAND_BACK_HOLD_OFF));
    // (s after the hand-back, whether a holding that starts then may hand back)
    let table = [(1, false), (59, false), (60, true)];
    for (s, want) in table {
        let at = start + Duration::from_secs(s);
        assert_eq!(waiting.may_hand_back(at), want, "{s} s");
    }
    // A holding lost (not handed back) sets no hold-off.
    let mut lost = Waiting::new(TIMES, start);
    lost.ended(Ended::Lost, start);
    let at = claims_after(&mut lost, "h1", start, &none_gone);
    assert_eq!(at, Some(Duration::ZERO));
}

#[test]
fn a_failure_is_told_once_until_something_succeeds() {
    let now = Instant::now();
    let mut waiting = Waiting::new(TIMES, now);
    let failed = Claimed::Failed("timed out".into());
    let table = [
        (failed.clone(), Some(Note::ClaimFailed("timed out".into()))),
        (failed.clone(), None),
        (Claimed::NotHeld, None),
        (failed, Some(Note::ClaimFailed("timed out".into()))),
    ];
    for (i, (claimed, want)) in table.into_iter().enumerate() {
        assert_eq!(waiting.claimed(&Act::Claim, &claimed), want, "row {i}");
    }
}

#[test]
fn a_failed_takeover_is_tried_again_doubling_but_not_after_an_open_given_up() {
    let now = Instant::now();
    let mut holding = Holding::new(TIMES, now, true);
    // (how it ended, the pause before the next)
    let table = [
        (TakeoverEnded::Failed, Some(250 * MS)),
        (TakeoverEnded::Failed, Some(500 * MS)),
        (TakeoverEnded::LogNotOpened, Some(1000 * MS)),
        (TakeoverEnded::LogNotOpened, Some(250 * MS)),
        (TakeoverEnded::Failed, Some(250 * MS)),
        (TakeoverEnded::Failed, Some(500 * MS)),
        (TakeoverEnded::Failed, Some(1000 * MS)),
        (TakeoverEnded::Failed, Some(2000 * MS)),
        (TakeoverEnded::Failed, Some(4000 * MS)),
        (TakeoverEnded::Failed, Some(5000 * MS)),
        (TakeoverEnded::Failed, Some(5000 * MS)),
        (TakeoverEnded::Taken, None),
    ];
    for (i, (ended, want)) in table.into_iter().enumerate() {
        assert_eq!(holding.takeover_ended(ended), want, "row {i}");
    }
    assert!(holding.taken());
}

#[test]
fn a_lease_is_kept_through_failed_renewals_until_the_lease_and_its_grace_have_passed() {
    let start = Instant::now();
    let mut holding = Holding::new(TIMES, start, false);
    holding.takeover_ended(TakeoverEnded::Taken);
    let failed = || Renewal::Failed("timed out".into());
    // (s after the claim, the renewal, what the holder does)
    let table = [
        (1, failed(), Keep::Retry("timed out".into())),
        (12, failed(), Keep::Retry("timed out".into())),
        (13, failed(), Keep::Drop("not renewed: timed out".into())),
    ];
    for (s, renewal, want) in table {
        let at = start + Duration::from_secs(s);
        assert_eq!(holding.renewed(at, renewal, None), want, "{s} s");
    }
    // A renewal that succeeds starts the count again.
    let mut holding = Holding::new(TIMES, start, false);
    let at = |s| start + Duration::from_secs(s);
    assert_eq!(holding.renewed(at(10), Renewal::Renewed, None), Keep::Hold);
    assert_eq!(
        holding.renewed(at(22), failed(), None),
        Keep::Retry("timed out".into())
    );
    let claimed = holding.renewed(at(23), Renewal::Claimed, None);
    assert_eq!(
        claimed,
        Keep::Drop("its lease was claimed by another host".into())
    );
}

#[test]
fn a_fence_under_a_lease_still_held_takes_the_site_over_again_once_renewed() {
    let start = Instant::now();
    let mut holding = Holding::new(TIMES, start, false);
    holding.takeover_ended(TakeoverEnded::Taken);
    holding.fence_rang();
    let at = |ms| start + ms * MS;
    // A renewal that fails keeps the fence for the next one.
    let retry = holding.renewed(at(1000), Renewal::Failed("timed out".into()), None);
    assert_eq!(retry, Keep::Retry("timed out".into()));
    assert_eq!(
        holding.renewed(at(2000), Renewal::Renewed, None),
        Keep::TakeOverAgain
    );
    assert_eq!(
        holding.renewed(at(3000), Renewal::Renewed, None),
        Keep::Hold
    );
}

#[test]
fn a_site_is_handed_back_to_a_settled_home_once_taken_over_and_held_long_enough() {
    let start = Instant::now();
    let at = |s| start + Duration::from_secs(s);
    // (may hand back, taken over, s since the claim, a settled home, what the holder does)
    let table = [
        (true, true, 10, Some("h1"), Keep::HandBack("h1".into())),
        (true, true, 9, Some("h1"), Keep::Hold),
        (true, false, 10, Some("h1"), Keep::Hold),
        (false, true, 10, Some("h1"), Keep::Hold),
        (true, true, 10, None, Keep::Hold),
    ];
    for (i, (may, taken, s, home, want)) in table.into_iter().enumerate() {
        let mut holding = Holding::new(TIMES, start, may);
        if taken {
            holding.takeover_ended(TakeoverEnded::Taken);
        }
        assert_eq!(
            holding.renewed(at(s), Renewal::Renewed, home),
            want,
            "row {i}"
        );
    }
}

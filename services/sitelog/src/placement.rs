//! Which mapper host tries first to own a site: rendezvous (highest random weight) hashing
//! over the live hosts. Every host computes the same order from the same names, with no
//! coordination; the first host claims the site's lease, the second follows its log as the
//! warm standby. Adding or removing a host moves only the sites whose first place it takes or
//! leaves: a new host takes about 1/n of the sites, all from others, and a host that goes
//! leaves exactly its own sites, each to the host that was second.

/// The hosts in the order they should try to own `site`: the first claims it, the second
/// stands by. Ties (equal weights) fall back to the host names, so the order is total.
pub fn host_order<'h>(site: &str, hosts: &[&'h str]) -> Vec<&'h str> {
    let mut weighted: Vec<(u64, &str)> = hosts.iter().map(|h| (weight(site, h), *h)).collect();
    weighted.sort_unstable_by(|a, b| b.cmp(a));
    weighted.dedup_by(|a, b| a.1 == b.1);
    weighted.into_iter().map(|(_, h)| h).collect()
}

/// The pair's weight: FNV-1a over "site\0host", then a 64-bit finalizer (SplitMix64's) so
/// that similar names spread; stable across releases and machines (no std hasher, whose
/// output may change).
fn weight(site: &str, host: &str) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for byte in site.bytes().chain([0]).chain(host.bytes()) {
        h ^= u64::from(byte);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h ^= h >> 30;
    h = h.wrapping_mul(0xbf58_476d_1ce4_e5b9);
    h ^= h >> 27;
    h = h.wrapping_mul(0x94d0_49bb_1331_11eb);
    h ^ (h >> 31)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sites() -> Vec<String> {
        (0..1000).map(|i| format!("site-{i}")).collect()
    }

    fn owners(hosts: &[&str]) -> Vec<String> {
        sites()
            .iter()
            .map(|s| host_order(s, hosts)[0].to_owned())
            .collect()
    }

    #[test]
    fn the_order_is_the_same_whatever_order_the_hosts_are_listed_in() {
        let a = host_order("park", &["h1", "h2", "h3", "h4"]);
        let b = host_order("park", &["h4", "h2", "h1", "h3"]);
        assert_eq!(a, b);
        assert_eq!(a.len(), 4);
        // Pinned (computed apart, in Python), so that a release that changed the hash, and
        // with it every site's owner during a rolling upgrade, fails here.
        assert_eq!(weight("park", "h1"), 0xcef0_45d2_127d_01ea);
        assert_eq!(weight("park", "h2"), 0x8b1a_7382_a8df_c578);
    }

    #[test]
    fn sites_spread_over_the_hosts() {
        let hosts = ["h1", "h2", "h3", "h4", "h5"];
        let owners = owners(&hosts);
        for h in hosts {
            let n = owners.iter().filter(|o| *o == h).count();
            // 200 expected of 1,000; a binomial's 4 σ is about 50.
            assert!((150..=250).contains(&n), "{h} owns {n} of 1,000 sites");
        }
    }

    #[test]
    fn a_host_that_goes_leaves_only_its_own_sites_each_to_its_standby() {
        let all = ["h1", "h2", "h3", "h4", "h5"];
        let without_h3 = ["h1", "h2", "h4", "h5"];
        for site in sites() {
            let before = host_order(&site, &all);
            let after = host_order(&site, &without_h3);
            if before[0] == "h3" {
                assert_eq!(after[0], before[1], "{site}: the standby takes over");
            } else {
                assert_eq!(after[0], before[0], "{site} moved though its owner stayed");
            }
        }
    }

    #[test]
    fn a_new_host_takes_about_its_share_and_only_for_itself() {
        let before = owners(&["h1", "h2", "h3", "h4"]);
        let after = owners(&["h1", "h2", "h3", "h4", "h5"]);
        let moved: Vec<usize> = (0..before.len())
            .filter(|&i| before[i] != after[i])
            .collect();
        assert!(
            moved.iter().all(|&i| after[i] == "h5"),
            "a site moved between old hosts"
        );
        // A fifth of 1,000 expected.
        assert!(
            (150..=250).contains(&moved.len()),
            "{} sites moved",
            moved.len()
        );
    }
}

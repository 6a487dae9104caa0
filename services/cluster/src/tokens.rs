//! Each mapper host's Zenoh liveliness token, `levelmap/cluster/hosts/{name}`, held while it
//! runs. A host's process that dies loses its token as soon as the other routers' links to it
//! close, whatever NATS is doing meanwhile: so when the leases' bucket comes back from an
//! election, a host can tell a site's holder that died (its token seen to go) from one that
//! is alive and will claim its lapsed lease again (docs/cluster.md). The leases stay the only
//! source of ownership; a token only shortens a wait.

use anyhow::{Result, anyhow};
use std::collections::HashSet;
use std::sync::{Arc, Mutex};
use zenoh::sample::SampleKind;

/// The key of host tokens, before the host's name.
const PREFIX: &str = "levelmap/cluster/hosts/";

/// This host's token, and the hosts whose tokens were seen to go.
pub(super) struct Tokens {
    /// Hosts whose token went away and has not come back since.
    gone: Arc<Mutex<HashSet<String>>>,
    _token: zenoh::liveliness::LivelinessToken,
    _watch: zenoh::pubsub::Subscriber<()>,
}

impl Tokens {
    /// Declares `this` host's token on `session` and watches the others'.
    pub async fn declare(session: &zenoh::Session, this: &str) -> Result<Tokens> {
        let token = session
            .liveliness()
            .declare_token(format!("{PREFIX}{this}"))
            .await
            .map_err(|e| anyhow!("this host's liveliness token: {e}"))?;
        let gone = Arc::new(Mutex::new(HashSet::new()));
        let seen = gone.clone();
        let watch = session
            .liveliness()
            .declare_subscriber(format!("{PREFIX}*"))
            .history(true)
            .callback(move |sample| {
                let Some(host) = sample.key_expr().as_str().strip_prefix(PREFIX) else {
                    return;
                };
                let mut gone = seen.lock().expect("tokens lock");
                match sample.kind() {
                    SampleKind::Delete => gone.insert(host.to_owned()),
                    SampleKind::Put => gone.remove(host),
                };
            })
            .await
            .map_err(|e| anyhow!("watching the hosts' liveliness tokens: {e}"))?;
        Ok(Tokens {
            gone,
            _token: token,
            _watch: watch,
        })
    }

    /// Whether `host`'s token was seen to go and has not come back: its process is gone, or
    /// cut from this host's router. A host never seen is not gone.
    pub fn gone(&self, host: &str) -> bool {
        self.gone.lock().expect("tokens lock").contains(host)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use runtime::session::{Role, SessionConfig};
    use std::time::{Duration, Instant};

    /// A router on a free loopback port, connected to `others`.
    async fn router(others: &[String]) -> (zenoh::Session, String) {
        let port = sitelog::local::free_local_port().expect("a free port");
        let endpoint = format!("tcp/127.0.0.1:{port}");
        let config = SessionConfig {
            connect: Some(others.to_vec()),
            ..SessionConfig::router(&endpoint)
        };
        let session = zenoh::open(config.to_zenoh(Role::Router).unwrap())
            .await
            .expect("a router");
        (session, endpoint)
    }

    async fn until(what: &str, check: impl Fn() -> bool) {
        let deadline = Instant::now() + Duration::from_secs(10);
        while !check() {
            assert!(Instant::now() < deadline, "{what}: not within 10 s");
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_host_whose_router_closes_is_gone_until_it_comes_back() {
        let (first, endpoint) = router(&[]).await;
        let h1 = Tokens::declare(&first, "h1").await.unwrap();
        assert!(!h1.gone("h2"), "a host never seen is not gone");

        let (second, _) = router(std::slice::from_ref(&endpoint)).await;
        let h2 = Tokens::declare(&second, "h2").await.unwrap();
        // Seen alive first: its token reached h1 once the routers linked.
        let deadline = Instant::now() + Duration::from_secs(10);
        loop {
            let replies = first
                .liveliness()
                .get("levelmap/cluster/hosts/h2")
                .timeout(Duration::from_millis(500))
                .await
                .unwrap();
            if replies.recv_async().await.is_ok() {
                break;
            }
            assert!(Instant::now() < deadline, "h2's token never reached h1");
        }
        assert!(!h1.gone("h2") && !h2.gone("h1"));

        drop(h2);
        second.close().await.unwrap();
        until("h2 gone", || h1.gone("h2")).await;

        let (again, _) = router(std::slice::from_ref(&endpoint)).await;
        let _h2 = Tokens::declare(&again, "h2").await.unwrap();
        until("h2 back", || !h1.gone("h2")).await;
        assert!(!h1.gone("h1"));
    }
}

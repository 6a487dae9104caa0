//! How a mapper host reaches the NATS servers: their URLs and, in a secured cluster
//! (`deploy/cluster/make-nats-certs.sh`), the CA and the host's own certificate, which the
//! servers map to the host's user.

use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// The NATS servers and this host's credentials for them.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct NatsAccess {
    /// The servers' URLs (`nats://host:4222`, `tls://host:4222`); the client fails over
    /// among them.
    pub servers: Vec<String>,
    /// The CA that signed the servers' certificates; set: TLS is required.
    pub ca: Option<PathBuf>,
    /// This host's certificate (PEM), signed by the cluster's CA, its common name the host.
    pub cert: Option<PathBuf>,
    /// Its private key (PEM).
    pub key: Option<PathBuf>,
}

#[cfg(feature = "client")]
impl NatsAccess {
    /// JetStream over [`Self::connect`].
    pub async fn jetstream(&self, name: &str) -> Result<crate::JetStream, crate::LogError> {
        Ok(async_nats::jetstream::new(self.connect(name).await?))
    }

    /// Connects as `name` (shown in the servers' connection lists). The first connection
    /// is retried until it succeeds, so hosts and servers may start in any order.
    pub async fn connect(&self, name: &str) -> Result<async_nats::Client, crate::LogError> {
        use crate::LogError;
        use async_nats::ConnectOptions;
        use std::time::Duration;
        if self.servers.is_empty() {
            return Err(LogError::JetStream("no NATS servers configured".into()));
        }
        let mut options = ConnectOptions::new()
            .name(name)
            .connection_timeout(Duration::from_secs(5))
            .retry_on_initial_connect();
        if let Some(ca) = &self.ca {
            options = options.require_tls(true).add_root_certificates(ca.clone());
        }
        match (&self.cert, &self.key) {
            (Some(cert), Some(key)) => {
                options = options.add_client_certificate(cert.clone(), key.clone());
            }
            (None, None) => {}
            _ => {
                return Err(LogError::JetStream(
                    "a NATS certificate needs its key, and a key its certificate".into(),
                ));
            }
        }
        options
            .connect(self.servers.as_slice())
            .await
            .map_err(|e| LogError::JetStream(format!("connecting to {:?}: {e}", self.servers)))
    }
}

//! The site's log itself ([`SiteLog`]): appends fenced and deduplicated, reads, the retry
//! policy, and the errors of all of the client's parts.

use async_nats::HeaderMap;
use async_nats::jetstream::context::{Context, PublishErrorKind};
use async_nats::jetstream::message::PublishMessage;
use async_nats::jetstream::stream::{Config, StorageType, Stream};
use bytes::Bytes;
use std::fmt;
use std::time::{Duration, Instant};

/// How long and how often an append is retried while JetStream does not answer.
#[derive(Clone, Debug, PartialEq)]
pub struct RetryPolicy {
    /// Give up after this long: well above a stream leader's election (4–9 s measured).
    pub deadline: Duration,
    /// The first pause between tries; doubled after each, up to `max_backoff`.
    pub first_backoff: Duration,
    /// The longest pause between tries.
    pub max_backoff: Duration,
}

impl Default for RetryPolicy {
    fn default() -> Self {
        RetryPolicy {
            deadline: Duration::from_secs(30),
            first_backoff: Duration::from_millis(50),
            max_backoff: Duration::from_secs(1),
        }
    }
}

/// Which record an append carries: its id is the stream's deduplication key.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct RecordId(String);

impl RecordId {
    /// A robot's node: `node/{robot}/{chain}/{seq}`, the triple that names it on the wire.
    pub fn node(robot: &str, chain: u64, seq: u64) -> RecordId {
        RecordId(format!("node/{robot}/{chain}/{seq}"))
    }

    /// Any other record, by a name the caller keeps unique within the site.
    pub fn named(name: impl Into<String>) -> RecordId {
        RecordId(name.into())
    }

    /// The id as sent in `Nats-Msg-Id`.
    pub fn as_str(&self) -> &str {
        &self.0
    }
}

impl fmt::Display for RecordId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

/// What an append did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Appended {
    /// Stored at this sequence.
    New(u64),
    /// Already stored (the same id), at this sequence: nothing was added.
    Duplicate(u64),
}

impl Appended {
    /// The record's sequence in the stream.
    pub fn sequence(&self) -> u64 {
        match *self {
            Appended::New(seq) | Appended::Duplicate(seq) => seq,
        }
    }
}

/// One record read back.
#[derive(Clone, Debug, PartialEq)]
pub struct Entry {
    /// Its sequence in the stream.
    pub sequence: u64,
    /// Its id (`Nats-Msg-Id`).
    pub id: String,
    /// The record as appended.
    pub payload: Bytes,
}

/// Why a log could not be opened, appended to or read.
#[derive(Debug, thiserror::Error)]
pub enum LogError {
    /// A site name the stream's name cannot hold.
    #[error("site name {0:?}: use letters, digits, '-' and '_' only")]
    BadSite(String),
    /// Another writer appended since this one's last append: this host no longer owns the
    /// site and must drop it.
    #[error("fenced: the log moved past sequence {expected} ({detail})")]
    Fenced {
        /// The last sequence this writer knew.
        expected: u64,
        /// The server's words.
        detail: String,
    },
    /// JetStream did not ack within the retry deadline.
    #[error("no ack from JetStream within {0:?}: {1}")]
    Unavailable(Duration, String),
    /// Anything else JetStream refused or failed at.
    #[error("JetStream: {0}")]
    JetStream(String),
}

impl LogError {
    /// JetStream's own error, in its words.
    pub(crate) fn jetstream(e: impl fmt::Display) -> LogError {
        LogError::JetStream(e.to_string())
    }
}

/// `request`, given `limit` at most: past it, [`LogError::Unavailable`]. A request sent while
/// a stream elects its leader is lost and would wait for the client's own timeout (5 s and
/// more); the lease's work needs to hear sooner.
pub async fn within<T>(
    limit: Duration,
    request: impl std::future::Future<Output = Result<T, LogError>>,
) -> Result<T, LogError> {
    tokio::time::timeout(limit, request)
        .await
        .unwrap_or_else(|_| Err(LogError::Unavailable(limit, "timed out".into())))
}

/// A site's log, as one writer (the site's owner) sees it.
pub struct SiteLog {
    js: Context,
    stream: Stream,
    subject: String,
    last_sequence: u64,
    retry: RetryPolicy,
}

impl SiteLog {
    /// Opens site `site`'s log, creating its stream (`replicas` copies, file storage) if
    /// there is none; the writer starts from the stream's last sequence.
    pub async fn open(
        js: Context,
        site: &str,
        replicas: usize,
        retry: RetryPolicy,
    ) -> Result<SiteLog, LogError> {
        check_site(site)?;
        let config = log_config(site, replicas, None);
        let stream = js
            .get_or_create_stream(config)
            .await
            .map_err(LogError::jetstream)?;
        SiteLog::writer(js, stream, site, retry).await
    }

    /// Creates site `site`'s log anew, its first record to be at `first_sequence`: a log
    /// rebuilt from a host's store (`levelmap site-log rebuild`), numbered past every record
    /// of the one it replaces, so that every host's store finds a gap before it
    /// ([`SiteLog::bounds`]) and reads it from its start. Refused while the site has a log.
    pub async fn create_rebuilt(
        js: Context,
        site: &str,
        replicas: usize,
        retry: RetryPolicy,
        first_sequence: u64,
    ) -> Result<SiteLog, LogError> {
        check_site(site)?;
        let config = log_config(site, replicas, Some(first_sequence));
        let stream = js
            .create_stream(config)
            .await
            .map_err(LogError::jetstream)?;
        SiteLog::writer(js, stream, site, retry).await
    }

    /// The writer of `stream`, starting from its last sequence.
    async fn writer(
        js: Context,
        mut stream: Stream,
        site: &str,
        retry: RetryPolicy,
    ) -> Result<SiteLog, LogError> {
        let info = stream.info().await.map_err(LogError::jetstream)?;
        let last_sequence = info.state.last_sequence;
        Ok(SiteLog {
            js,
            stream,
            subject: log_subject(site),
            last_sequence,
            retry,
        })
    }

    /// The last sequence this writer appended or found.
    pub fn last_sequence(&self) -> u64 {
        self.last_sequence
    }

    /// Appends `payload` as record `id`, fenced by the last sequence this writer knows. Done
    /// only once JetStream acked it; retried while JetStream does not answer.
    pub async fn append(&mut self, id: &RecordId, payload: Bytes) -> Result<Appended, LogError> {
        let started = Instant::now();
        let mut backoff = self.retry.first_backoff;
        loop {
            let publish = PublishMessage::build()
                .payload(payload.clone())
                .message_id(id.as_str())
                .expected_last_sequence(self.last_sequence);
            let attempt = async {
                match self.js.send_publish(self.subject.clone(), publish).await {
                    Ok(ack) => ack.await,
                    Err(e) => Err(e),
                }
            };
            // No try outlasts the deadline, however long the client would wait for an ack.
            let left = self.retry.deadline.saturating_sub(started.elapsed());
            let (kind, detail) = match tokio::time::timeout(left, attempt).await {
                Ok(Ok(ack)) => {
                    if ack.duplicate {
                        self.last_sequence = self.last_sequence.max(ack.sequence);
                        return Ok(Appended::Duplicate(ack.sequence));
                    }
                    self.last_sequence = ack.sequence;
                    return Ok(Appended::New(ack.sequence));
                }
                Ok(Err(e)) => (e.kind(), e.to_string()),
                Err(_) => (
                    PublishErrorKind::TimedOut,
                    "no ack before the deadline".to_owned(),
                ),
            };
            match classify(kind, &detail) {
                Failure::Fenced => {
                    return Err(LogError::Fenced {
                        expected: self.last_sequence,
                        detail,
                    });
                }
                Failure::Fatal => return Err(LogError::JetStream(detail)),
                Failure::Transient if started.elapsed() >= self.retry.deadline => {
                    return Err(LogError::Unavailable(self.retry.deadline, detail));
                }
                Failure::Transient => {
                    tokio::time::sleep(backoff).await;
                    backoff = (backoff * 2).min(self.retry.max_backoff);
                }
            }
        }
    }

    /// Every record from sequence `from` (1: the whole log) to the last, in order.
    pub async fn read_from(&self, from: u64) -> Result<Vec<Entry>, LogError> {
        self.read_some(from, usize::MAX).await
    }

    /// The records from sequence `from` on, in order, at most `max` of them: fewer than
    /// `max` when the log ends.
    pub async fn read_some(&self, from: u64, max: usize) -> Result<Vec<Entry>, LogError> {
        let (first, last) = self.bounds().await?;
        let mut entries = Vec::new();
        for sequence in (from.max(first)..=last).take(max) {
            entries.push(self.get(sequence).await?);
        }
        Ok(entries)
    }

    /// The stream's first and last sequence, as the server says now. An empty log's last
    /// is one before its first. A first sequence past the record after the last one a
    /// reader holds is a gap: the log was rebuilt ([`SiteLog::create_rebuilt`]).
    pub async fn bounds(&self) -> Result<(u64, u64), LogError> {
        let info = self
            .read_retrying(|| async { self.stream.get_info().await.map_err(|e| e.to_string()) })
            .await?;
        Ok((info.state.first_sequence, info.state.last_sequence))
    }

    /// The record at `sequence`.
    pub async fn get(&self, sequence: u64) -> Result<Entry, LogError> {
        let message = self
            .read_retrying(|| async {
                self.stream
                    .get_raw_message(sequence)
                    .await
                    .map_err(|e| format!("sequence {sequence}: {e}"))
            })
            .await?;
        Ok(Entry {
            sequence,
            id: message_id(&message.headers).unwrap_or_default(),
            payload: message.payload,
        })
    }

    /// `read`, tried again while it fails as reads do during a leader's election, up to the
    /// retry deadline.
    async fn read_retrying<T, F, Fut>(&self, read: F) -> Result<T, LogError>
    where
        F: Fn() -> Fut,
        Fut: std::future::Future<Output = Result<T, String>>,
    {
        let started = Instant::now();
        let mut backoff = self.retry.first_backoff;
        loop {
            let detail = match read().await {
                Ok(value) => return Ok(value),
                Err(detail) => detail,
            };
            if !read_may_pass(&detail) {
                return Err(LogError::JetStream(detail));
            }
            if started.elapsed() >= self.retry.deadline {
                return Err(LogError::Unavailable(self.retry.deadline, detail));
            }
            tokio::time::sleep(backoff).await;
            backoff = (backoff * 2).min(self.retry.max_backoff);
        }
    }
}

/// Whether a read failed only for the while a stream elects its leader: JetStream answers
/// 503 (error code 10008, "temporarily unavailable"), or nobody answers in time.
fn read_may_pass(detail: &str) -> bool {
    ["code 503", "timed out", "no responders", "unavailable"]
        .iter()
        .any(|words| detail.contains(words))
}

/// A site name the stream's name can hold: letters, digits, `-` and `_`.
fn check_site(site: &str) -> Result<(), LogError> {
    let ok = !site.is_empty()
        && site
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_');
    if !ok {
        return Err(LogError::BadSite(site.to_owned()));
    }
    Ok(())
}

/// The stream of site `site`'s log.
fn stream_name(site: &str) -> String {
    format!("LEVELMAP_SITE_{site}")
}

/// The subject site `site`'s records are appended on.
fn log_subject(site: &str) -> String {
    format!("levelmap.site.{site}.log")
}

/// Site `site`'s stream: `replicas` copies, file storage, starting at `first_sequence`
/// (1 when `None`).
fn log_config(site: &str, replicas: usize, first_sequence: Option<u64>) -> Config {
    Config {
        name: stream_name(site),
        subjects: vec![log_subject(site)],
        storage: StorageType::File,
        num_replicas: replicas,
        // Ids are remembered this long: a retry after a lost ack comes within seconds.
        duplicate_window: Duration::from_secs(120),
        first_sequence,
        ..Default::default()
    }
}

/// Deletes site `site`'s log, every record of it; whether there was one. Only a rebuild
/// does this (`levelmap site-log rebuild`: an empty log made again by a host, or with
/// `--replace` one that holds records).
pub async fn delete_log(js: &Context, site: &str) -> Result<bool, LogError> {
    check_site(site)?;
    if !log_exists(js, site).await? {
        return Ok(false);
    }
    js.delete_stream(stream_name(site))
        .await
        .map_err(LogError::jetstream)?;
    Ok(true)
}

/// Site `site`'s log's first and last sequence and its record count, if it has a log.
/// Reads, creates nothing.
pub async fn log_state(js: &Context, site: &str) -> Result<Option<(u64, u64, u64)>, LogError> {
    check_site(site)?;
    if !log_exists(js, site).await? {
        return Ok(None);
    }
    let mut stream = js
        .get_stream(stream_name(site))
        .await
        .map_err(LogError::jetstream)?;
    let state = stream
        .info()
        .await
        .map_err(LogError::jetstream)?
        .state
        .clone();
    Ok(Some((
        state.first_sequence,
        state.last_sequence,
        state.messages,
    )))
}

/// Whether site `site` has a log (a site some host ever took); reads, creates nothing.
pub async fn log_exists(js: &Context, site: &str) -> Result<bool, LogError> {
    use async_nats::jetstream::ErrorCode;
    use async_nats::jetstream::context::GetStreamErrorKind;
    match js.get_stream(stream_name(site)).await {
        Ok(_) => Ok(true),
        Err(e) => match e.kind() {
            GetStreamErrorKind::JetStream(error)
                if error.error_code() == ErrorCode::STREAM_NOT_FOUND =>
            {
                Ok(false)
            }
            _ => Err(LogError::JetStream(e.to_string())),
        },
    }
}

/// How many of site `site`'s log's copies are current (its leader and the followers that
/// are caught up and online), and how many it has: fewer current than copies means a
/// server is down, behind, or its JetStream disabled (a full disk), and one more loss may
/// stop the log. Reads, creates nothing.
pub async fn log_copies(js: &Context, site: &str) -> Result<(usize, usize), LogError> {
    let mut stream = js
        .get_stream(stream_name(site))
        .await
        .map_err(LogError::jetstream)?;
    let info = stream.info().await.map_err(LogError::jetstream)?;
    let Some(cluster) = &info.cluster else {
        return Ok((1, 1));
    };
    let followers = &cluster.replicas;
    let led = usize::from(cluster.leader.is_some());
    let current = followers.iter().filter(|p| p.current && !p.offline).count();
    Ok((led + current, 1 + followers.len()))
}

/// A publish's failure, by what the writer does about it.
#[derive(Debug, PartialEq, Eq)]
enum Failure {
    /// Someone else appended: drop the site.
    Fenced,
    /// No answer or a passing refusal: try again.
    Transient,
    /// Retrying will not help.
    Fatal,
}

/// 10071 ("wrong last sequence: N") is a fence; 10164 (the same words without a number)
/// comes back transiently even from one sequential writer, and is retried. A lost leader
/// shows as a timeout, a broken pipe or no responders.
fn classify(kind: PublishErrorKind, detail: &str) -> Failure {
    match kind {
        PublishErrorKind::WrongLastSequence if passing_refusal(detail) => Failure::Transient,
        PublishErrorKind::WrongLastSequence => Failure::Fenced,
        PublishErrorKind::TimedOut
        | PublishErrorKind::BrokenPipe
        | PublishErrorKind::StreamNotFound
        | PublishErrorKind::MaxAckPending => Failure::Transient,
        PublishErrorKind::Other if passing_refusal(detail) => Failure::Transient,
        PublishErrorKind::Other
            if detail.contains("no suitable peers") || detail.contains("unavailable") =>
        {
            Failure::Transient
        }
        _ => Failure::Fatal,
    }
}

/// JetStream's 10164 ("wrong last sequence" without a number): a write refused while others
/// to the same subject are in flight, not applied; the same write may be tried again.
pub(crate) fn passing_refusal(detail: &str) -> bool {
    detail.contains("error code 10164")
}

fn message_id(headers: &HeaderMap) -> Option<String> {
    headers
        .get(async_nats::header::NATS_MESSAGE_ID)
        .map(|v| v.as_str().to_owned())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_wrong_last_sequence_with_a_number_fences_and_without_one_is_retried() {
        // As async-nats shows them: the kind, then the server's error.
        let fenced = "wrong last sequence: wrong last sequence: 10164 (code 400, error code 10071)";
        let passing = "wrong last sequence: wrong last sequence (code 400, error code 10164)";
        assert_eq!(
            classify(PublishErrorKind::WrongLastSequence, fenced),
            Failure::Fenced
        );
        assert_eq!(
            classify(PublishErrorKind::WrongLastSequence, passing),
            Failure::Transient
        );
        assert_eq!(
            classify(PublishErrorKind::Other, passing),
            Failure::Transient
        );
        assert_eq!(
            classify(PublishErrorKind::TimedOut, "timed out"),
            Failure::Transient
        );
        assert_eq!(
            classify(PublishErrorKind::MaxPayloadExceeded, "too big"),
            Failure::Fatal
        );
    }

    #[test]
    fn a_lease_claim_refused_in_passing_is_told_from_a_fence() {
        // A KV update's error as the lease's claim got it in CI, and a fence's.
        let passing = "failed getting entry: publish failed: wrong last sequence (code 400, \
                       error code 10164)";
        let fenced = "wrong last sequence: 10164 (code 400, error code 10071)";
        assert!(passing_refusal(passing));
        assert!(!passing_refusal(fenced));
    }

    #[test]
    fn a_read_refused_during_an_election_is_retried_and_a_missing_record_is_not() {
        let electing = "sequence 74: JetStream error: JetStream system temporarily unavailable \
                        (code 503, error code 10008)";
        assert!(read_may_pass(electing));
        assert!(read_may_pass(
            "sequence 3: timed out: did not receive any response"
        ));
        assert!(!read_may_pass(
            "sequence 9: JetStream error: no message found (code 404, error code 10037)"
        ));
    }

    #[test]
    fn a_node_record_is_named_by_robot_chain_and_seq() {
        assert_eq!(RecordId::node("r1", 2, 17).as_str(), "node/r1/2/17");
    }
}

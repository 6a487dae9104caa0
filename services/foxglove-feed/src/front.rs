//! The token front: the Foxglove protocol has no access control, so a mapper with a read
//! token serves the SDK's server on a loopback port behind this front, which passes a
//! connection on only when its opening request carries the read or write token, as
//! `?token=…` in the URL (what Foxglove's connection dialog can give: a browser cannot set a
//! WebSocket's headers) or as `Authorization: Bearer …` (other clients). The token is taken
//! out of the request before it is passed on. Anything else gets a 401 and is closed.
//!
//! Bounded: the opening request within [`HEAD_MAX`] bytes and [`HEAD_WITHIN`], at most
//! [`CONNECTIONS_MAX`] connections at once (one more is closed at once).

use mapper::tokens::{Grant, Tokens};
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};

/// The largest opening request taken.
pub const HEAD_MAX: usize = 16 * 1024;
/// How long a connection has to send its opening request.
pub const HEAD_WITHIN: Duration = Duration::from_secs(10);
/// Connections at once.
pub const CONNECTIONS_MAX: usize = 64;

/// Accepts on `listener` and passes admitted connections to the server at `inner`.
pub(crate) fn serve(
    listener: TcpListener,
    inner: SocketAddr,
    tokens: Arc<Tokens>,
) -> tokio::task::JoinHandle<()> {
    tokio::spawn(async move {
        let open = Arc::new(tokio::sync::Semaphore::new(CONNECTIONS_MAX));
        loop {
            let (stream, peer) = match listener.accept().await {
                Ok(accepted) => accepted,
                Err(e) => {
                    // Out of descriptors, say: not a reason to spin.
                    tracing::warn!("foxglove front: accept: {e}");
                    tokio::time::sleep(Duration::from_millis(100)).await;
                    continue;
                }
            };
            let Ok(permit) = open.clone().try_acquire_owned() else {
                tracing::warn!(%peer, "foxglove front: {CONNECTIONS_MAX} connections open");
                continue;
            };
            let tokens = tokens.clone();
            tokio::spawn(async move {
                if let Err(e) = pass(stream, inner, &tokens).await {
                    tracing::debug!(%peer, "foxglove front: {e}");
                }
                drop(permit);
            });
        }
    })
}

/// One connection: its opening request read and judged, then passed on or refused.
async fn pass(mut client: TcpStream, inner: SocketAddr, tokens: &Tokens) -> std::io::Result<()> {
    let (head, rest) = tokio::time::timeout(HEAD_WITHIN, read_head(&mut client))
        .await
        .map_err(|_| std::io::Error::other("no opening request in time"))??;
    match admit(&head, tokens) {
        Ok(head) => {
            let mut server = TcpStream::connect(inner).await?;
            server.write_all(&head).await?;
            server.write_all(&rest).await?;
            tokio::io::copy_bidirectional(&mut client, &mut server).await?;
            Ok(())
        }
        Err(reason) => {
            let answer = format!(
                "HTTP/1.1 401 Unauthorized\r\nContent-Type: text/plain\r\nContent-Length: {}\r\n\
                 Connection: close\r\n\r\n{reason}",
                reason.len()
            );
            client.write_all(answer.as_bytes()).await?;
            client.shutdown().await
        }
    }
}

/// The opening request up to its blank line, and what came after it.
async fn read_head(client: &mut TcpStream) -> std::io::Result<(Vec<u8>, Vec<u8>)> {
    let mut buf = Vec::with_capacity(1024);
    let mut chunk = [0u8; 2048];
    loop {
        let n = client.read(&mut chunk).await?;
        if n == 0 {
            return Err(std::io::Error::other("closed before its opening request"));
        }
        buf.extend_from_slice(&chunk[..n]);
        if let Some(end) = buf.windows(4).position(|w| w == b"\r\n\r\n") {
            let rest = buf.split_off(end + 4);
            return Ok((buf, rest));
        }
        if buf.len() > HEAD_MAX {
            return Err(std::io::Error::other("opening request over 16 KiB"));
        }
    }
}

/// Why a connection is refused.
const NO_TOKEN: &str = "this mapper needs its read token on the Foxglove connection: \
     ws://HOST:PORT/?token=TOKEN, or Authorization: Bearer TOKEN\n";

/// The opening request to pass on, without its token, when it carries the read or write
/// token; else why not.
pub fn admit(head: &[u8], tokens: &Tokens) -> Result<Vec<u8>, &'static str> {
    let text = std::str::from_utf8(head).map_err(|_| "not an HTTP request\n")?;
    let (request_line, headers) = text.split_once("\r\n").ok_or("not an HTTP request\n")?;
    let mut parts = request_line.splitn(3, ' ');
    let (Some(method), Some(target), Some(version)) = (parts.next(), parts.next(), parts.next())
    else {
        return Err("not an HTTP request\n");
    };
    let (path, query) = target.split_once('?').unwrap_or((target, ""));
    let mut from_query = None;
    let kept: Vec<&str> = query
        .split('&')
        .filter(|pair| !pair.is_empty())
        .filter(|pair| match pair.strip_prefix("token=") {
            Some(value) => {
                from_query = Some(percent_decoded(value));
                false
            }
            None => true,
        })
        .collect();
    let mut from_header = None;
    let mut kept_headers = Vec::new();
    for line in headers.split("\r\n") {
        match line.split_once(':') {
            Some((name, value)) if name.trim().eq_ignore_ascii_case("authorization") => {
                from_header = bearer(value).map(str::to_owned);
            }
            _ => kept_headers.push(line),
        }
    }
    let token = from_query.or(from_header.map(String::into_bytes));
    if tokens.grant(token.as_deref()) == Grant::None {
        return Err(NO_TOKEN);
    }
    let target = match kept.is_empty() {
        true => path.to_owned(),
        false => format!("{path}?{}", kept.join("&")),
    };
    Ok(format!(
        "{method} {target} {version}\r\n{}",
        kept_headers.join("\r\n")
    )
    .into_bytes())
}

/// The token of an `Authorization` value `Bearer …` (the scheme in any case).
fn bearer(value: &str) -> Option<&str> {
    let (scheme, token) = value.trim().split_once(' ')?;
    let token = token.trim();
    (scheme.eq_ignore_ascii_case("bearer") && !token.is_empty()).then_some(token)
}

/// A URL query value with its `%XX` escapes (and `+`) decoded.
fn percent_decoded(value: &str) -> Vec<u8> {
    let bytes = value.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        let hex = |b: u8| (b as char).to_digit(16);
        match bytes[i] {
            b'%' if i + 2 < bytes.len() => match (hex(bytes[i + 1]), hex(bytes[i + 2])) {
                (Some(h), Some(l)) => {
                    out.push((h * 16 + l) as u8);
                    i += 3;
                    continue;
                }
                _ => out.push(b'%'),
            },
            b'+' => out.push(b' '),
            b => out.push(b),
        }
        i += 1;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn request(target: &str, extra: &str) -> Vec<u8> {
        format!(
            "GET {target} HTTP/1.1\r\nHost: h:8765\r\nUpgrade: websocket\r\n{extra}\
             Sec-WebSocket-Protocol: foxglove.sdk.v1\r\n\r\n"
        )
        .into_bytes()
    }

    #[test]
    fn the_read_or_write_token_in_the_url_or_a_header_passes_and_is_taken_out() {
        let tokens = Tokens::new("w s", "r-secret");
        let passed = admit(&request("/?token=r-secret", ""), &tokens).unwrap();
        let passed = String::from_utf8(passed).unwrap();
        assert!(
            passed.starts_with("GET / HTTP/1.1\r\nHost: h:8765\r\n"),
            "{passed}"
        );
        assert!(passed.ends_with("foxglove.sdk.v1\r\n\r\n") && !passed.contains("secret"));
        // Escaped, beside another parameter, which is kept.
        let passed = admit(&request("/x?a=1&token=w%20s", ""), &tokens).unwrap();
        assert!(
            String::from_utf8(passed)
                .unwrap()
                .starts_with("GET /x?a=1 HTTP/1.1\r\n")
        );
        let passed = admit(&request("/", "Authorization: bearer r-secret\r\n"), &tokens).unwrap();
        assert!(!String::from_utf8(passed).unwrap().contains("secret"));
    }

    #[test]
    fn no_token_a_wrong_one_or_garbage_is_refused() {
        let tokens = Tokens::new("", "r-secret");
        for head in [
            request("/", ""),
            request("/?token=r-secre", ""),
            request("/?token=", ""),
            request("/?tok=r-secret", ""),
            request("/", "Authorization: Basic r-secret\r\n"),
            b"\xff\xfe\r\n\r\n".to_vec(),
            b"GET\r\n\r\n".to_vec(),
        ] {
            assert!(
                admit(&head, &tokens).is_err(),
                "{}",
                String::from_utf8_lossy(&head)
            );
        }
    }

    #[test]
    fn escapes_decode_and_broken_ones_stay_as_they_are() {
        assert_eq!(percent_decoded("a%2Fb+c"), b"a/b c");
        assert_eq!(percent_decoded("50%"), b"50%");
        assert_eq!(percent_decoded("%zz%4"), b"%zz%4");
    }
}

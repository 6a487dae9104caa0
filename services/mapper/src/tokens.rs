//! The mapper's bearer tokens (read and write), compared in constant time: one check for the
//! HTTP API and for what serves beside it (the Foxglove feed's token front).

use sha3::{Digest, Sha3_256};
use subtle::ConstantTimeEq;

/// A token's SHA3-256 digest. Tokens are compared as digests: two 32-byte values whatever
/// their lengths, every byte looked at, so neither the time taken nor an early exit tells
/// how long the token is or how much of a guess was right.
type Digest32 = [u8; 32];

fn digest(token: &[u8]) -> Digest32 {
    Sha3_256::digest(token).into()
}

/// What a presented token is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Grant {
    /// No token, or one the mapper does not know.
    None,
    /// The read token.
    Read,
    /// The write token (which reads too).
    Write,
}

/// The configured tokens, as digests (none: not configured).
pub struct Tokens {
    write: Option<Digest32>,
    read: Option<Digest32>,
}

impl Tokens {
    /// The write token and the read token (`""`: not configured).
    pub fn new(write: &str, read: &str) -> Tokens {
        let secret = |t: &str| (!t.is_empty()).then(|| digest(t.as_bytes()));
        Tokens {
            write: secret(write),
            read: secret(read),
        }
    }

    /// A write token is configured: the write routes are on.
    pub fn write_routes(&self) -> bool {
        self.write.is_some()
    }

    /// A read token is configured: every guarded route needs a token.
    pub fn read_required(&self) -> bool {
        self.read.is_some()
    }

    /// What `token` is (`None`: none presented).
    pub fn grant(&self, token: Option<&[u8]>) -> Grant {
        let Some(given) = token.map(digest) else {
            return Grant::None;
        };
        let is = |secret: &Option<Digest32>| secret.is_some_and(|s| bool::from(s.ct_eq(&given)));
        // Both compared, so the time does not tell which one matched first.
        let (write, read) = (is(&self.write), is(&self.read));
        if write {
            Grant::Write
        } else if read {
            Grant::Read
        } else {
            Grant::None
        }
    }

    /// Whether `token` may read: no read token configured, or a known token.
    pub fn may_read(&self, token: Option<&[u8]>) -> bool {
        !self.read_required() || self.grant(token) != Grant::None
    }
}

//! The handshake's rules, without I/O: what a connection's first message
//! must be (a `Hello` with the magic, this protocol version and the cluster
//! token, at most [`MAX_HANDSHAKE_BYTES`](crate::MAX_HANDSHAKE_BYTES)), checked
//! by [`check_hello`], which can be fuzzed and tested alone. The exchange
//! over QUIC is `vtfarm_transport::handshake`.
//!
//! The master checks, in order: magic, version, token. Versions are read
//! even from a `Hello` that does not decode as this version's, because its
//! leading fields are frozen (see [`crate::message`]).

use std::time::Duration;

use sha2::{Digest, Sha256};
use subtle::ConstantTimeEq;

use crate::framing::decode_message;
use crate::message::{Hello, Message, Refusal, RefuseCode};

/// How long the master waits for a complete `Hello` (and a client for the answer).
pub const HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(10);

/// What the master accepts and how it introduces itself.
#[derive(Clone, PartialEq, Eq)]
pub struct HandshakePolicy {
    /// The cluster token every `Hello` must present.
    pub token: String,
    /// The protocol version to accept and to answer with.
    pub version: u32,
    /// The name in `Welcome`.
    pub master_name: String,
    /// How long a client may take to send its `Hello`.
    pub timeout: Duration,
    /// How long an accepted peer's message may stall once begun
    /// ([`crate::MESSAGE_STALL`]).
    pub message_stall: Duration,
}

impl HandshakePolicy {
    /// This build's version and the default timeout.
    pub fn new(token: impl Into<String>, master_name: impl Into<String>) -> Self {
        HandshakePolicy {
            token: token.into(),
            version: crate::PROTOCOL_VERSION,
            master_name: master_name.into(),
            timeout: HANDSHAKE_TIMEOUT,
            message_stall: crate::MESSAGE_STALL,
        }
    }
}

impl std::fmt::Debug for HandshakePolicy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // Logs must not leak the token.
        f.debug_struct("HandshakePolicy")
            .field("version", &self.version)
            .field("master_name", &self.master_name)
            .field("timeout", &self.timeout)
            .field("message_stall", &self.message_stall)
            .finish_non_exhaustive()
    }
}

/// Checks the body of a connection's first message (without its length
/// prefix): a `Hello` with the magic, the policy's version and token. No I/O,
/// so it can be fuzzed and tested alone.
pub fn check_hello(body: &[u8], policy: &HandshakePolicy) -> Result<Hello, Refusal> {
    let refuse = |code, message: String| Err(Refusal::new(code, message));
    let hello = match decode_message(body) {
        Ok(Message::Hello(hello)) => hello,
        Ok(other) => {
            let message = format!("expected Hello, got {}", other.name());
            return refuse(RefuseCode::BadMessage, message);
        }
        Err(e) => {
            // A Hello of another version need not decode as ours.
            return match frozen_hello_version(body) {
                Some(v) if v != policy.version => {
                    refuse(RefuseCode::BadVersion, unsupported(v, policy.version))
                }
                _ => refuse(RefuseCode::BadMessage, format!("not a vtfarm Hello: {e}")),
            };
        }
    };
    if hello.magic != crate::MAGIC {
        return refuse(
            RefuseCode::BadMessage,
            "not a vtfarm Hello: bad magic".to_owned(),
        );
    }
    if hello.version != policy.version {
        let message = unsupported(hello.version, policy.version);
        return refuse(RefuseCode::BadVersion, message);
    }
    if !token_matches(&policy.token, &hello.token) {
        return refuse(RefuseCode::BadToken, "wrong cluster token".to_owned());
    }
    Ok(hello)
}

fn unsupported(version: u32, ours: u32) -> String {
    format!("protocol version {version} is not supported (master speaks {ours})")
}

/// The version of a `Hello` body of any protocol version: variant 0, the
/// magic, then the version as a bincode varint. `None` if the body does not
/// start that way.
fn frozen_hello_version(body: &[u8]) -> Option<u32> {
    let rest = body.strip_prefix(&[0])?.strip_prefix(&crate::MAGIC[..])?;
    // bincode's varint: one byte below 251, else a marker and a little-endian integer.
    let v = match *rest.first()? {
        b @ 0..=250 => u64::from(b),
        251 => u16::from_le_bytes(rest.get(1..3)?.try_into().ok()?).into(),
        252 => u32::from_le_bytes(rest.get(1..5)?.try_into().ok()?).into(),
        _ => return None,
    };
    u32::try_from(v).ok()
}

/// Whether a presented token equals the expected one, in time independent
/// of where they differ: both are hashed first, so their lengths do not
/// leak either, and the equal-length digests are compared in constant time.
pub fn token_matches(expected: &str, presented: &str) -> bool {
    let expected = Sha256::digest(expected.as_bytes());
    let presented = Sha256::digest(presented.as_bytes());
    expected.ct_eq(&presented).into()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::framing::encode_message;
    use crate::message::Role;

    #[test]
    fn the_version_of_any_hello_can_be_read() {
        for version in [0, 1, 250, 251, 65535, 65536, u32::MAX] {
            let hello = Hello {
                version,
                ..Hello::new("t", Role::Submitter)
            };
            let frame = encode_message(&Message::Hello(hello)).expect("encodes");
            let mut body = frame[4..].to_vec();
            assert_eq!(frozen_hello_version(&body), Some(version));
            // A future Hello with more fields still shows its version.
            body.extend_from_slice(b"future fields");
            assert_eq!(frozen_hello_version(&body), Some(version));
        }
        assert_eq!(frozen_hello_version(&[1]), None);
        assert_eq!(frozen_hello_version(b"\0VTFARM\0\0"), None);
        assert_eq!(frozen_hello_version(b"\0VTFARX\0\0\x01"), None);
    }

    #[test]
    fn tokens_match_only_when_equal() {
        let token = "ab".repeat(32);
        assert!(token_matches(&token, &token.clone()));
        assert!(!token_matches(&token, &"ab".repeat(31)));
        assert!(!token_matches(&token, ""));
        assert!(!token_matches(&token, &format!("{token}x")));
        assert!(token_matches("", ""));
    }
}

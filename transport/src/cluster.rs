//! `cluster.toml`: where the master is, the shared token, and the master
//! certificate's fingerprint. The master writes it once
//! ([`ClusterConfig::generate`] then [`ClusterConfig::save`]); workers and
//! submitters read it. It holds a secret, so it is saved with mode 0600.
//!
//! ```toml
//! master = "farm.example:4433"
//! token = "3f0c…"        # 64 hex digits
//! fingerprint = "9a1b…"  # SHA-256 of the master certificate, 64 hex digits
//! ```

use std::fmt;
use std::io::Write;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::tls::{MasterIdentity, parse_fingerprint};

/// The conventional file name.
pub const CLUSTER_FILE: &str = "cluster.toml";
/// Random bytes in a generated token (hex-encoded: twice as many digits).
pub const TOKEN_BYTES: usize = 32;

/// How to reach and trust the master.
#[derive(Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClusterConfig {
    /// `host:port` of the master (`[v6-address]:port` for IPv6).
    pub master: String,
    /// The shared secret every `Hello` presents.
    pub token: String,
    /// SHA-256 of the master certificate, 64 hex digits.
    pub fingerprint: String,
}

impl fmt::Debug for ClusterConfig {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        // Logs must not leak the token.
        f.debug_struct("ClusterConfig")
            .field("master", &self.master)
            .field("token", &"…")
            .field("fingerprint", &self.fingerprint)
            .finish()
    }
}

/// A 1-based line and column in a file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Location {
    pub line: usize,
    pub column: usize,
}

impl Location {
    fn of(text: &str, offset: usize) -> Location {
        let before = crate::truncate_utf8(text, offset);
        let line_start = before.rfind('\n').map_or(0, |i| i + 1);
        Location {
            line: before.matches('\n').count() + 1,
            column: before[line_start..].chars().count() + 1,
        }
    }
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}", self.line, self.column)
    }
}

/// Why a cluster file could not be read, written or generated. Every
/// message starts with the file (and, for syntax errors, `line:column`).
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("{}: {source}", file.display())]
    Io {
        file: PathBuf,
        source: std::io::Error,
    },
    /// Not valid TOML, or keys missing, unknown or of the wrong type.
    #[error("{}{}: {message}", file.display(), location.map(|l| format!(":{l}")).unwrap_or_default())]
    Syntax {
        file: PathBuf,
        location: Option<Location>,
        message: String,
    },
    /// A key with an unusable value.
    #[error("{}: {key} = {value:?}: {problem}", file.display())]
    Invalid {
        file: PathBuf,
        key: &'static str,
        value: String,
        problem: &'static str,
    },
    #[error("cannot get random bytes from the operating system for the token")]
    Random,
}

impl ClusterConfig {
    /// A configuration for a master at `master_addr` (`host:port`) with
    /// `identity`, and a fresh random token (32 bytes from the OS RNG).
    pub fn generate(master_addr: &str, identity: &MasterIdentity) -> Result<Self, ConfigError> {
        let mut token = [0u8; TOKEN_BYTES];
        rustls::crypto::ring::default_provider()
            .secure_random
            .fill(&mut token)
            .map_err(|_| ConfigError::Random)?;
        let config = ClusterConfig {
            master: master_addr.to_owned(),
            token: hex::encode(token),
            fingerprint: identity.fingerprint(),
        };
        config.validate(Path::new("(generated)"))?;
        Ok(config)
    }

    /// Reads and validates `path`.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Io {
            file: path.to_owned(),
            source,
        })?;
        Self::from_toml(&text, path)
    }

    /// Parses and validates TOML; `file` names the source in errors.
    pub fn from_toml(text: &str, file: &Path) -> Result<Self, ConfigError> {
        let config: ClusterConfig = toml::from_str(text).map_err(|e| ConfigError::Syntax {
            file: file.to_owned(),
            location: e.span().map(|span| Location::of(text, span.start)),
            message: e.message().to_owned(),
        })?;
        config.validate(file)?;
        Ok(config)
    }

    /// The TOML text.
    pub fn to_toml(&self) -> String {
        toml::to_string(self).expect("three strings always serialize as TOML")
    }

    /// Writes the file (mode 0600 on unix: it holds the token), replacing
    /// any previous one.
    pub fn save(&self, path: &Path) -> Result<(), ConfigError> {
        let io = |source| ConfigError::Io {
            file: path.to_owned(),
            source,
        };
        let mut options = std::fs::OpenOptions::new();
        options.write(true).create(true).truncate(true);
        #[cfg(unix)]
        {
            use std::os::unix::fs::OpenOptionsExt;
            options.mode(0o600);
        }
        let mut file = options.open(path).map_err(io)?;
        file.write_all(self.to_toml().as_bytes()).map_err(io)?;
        file.sync_all().map_err(io)
    }

    /// The checks on values that TOML types cannot express.
    fn validate(&self, file: &Path) -> Result<(), ConfigError> {
        let invalid = |key, value: &str, problem| ConfigError::Invalid {
            file: file.to_owned(),
            key,
            value: value.to_owned(),
            problem,
        };
        let port_ok = self
            .master
            .rsplit_once(':')
            .is_some_and(|(host, port)| !host.is_empty() && port.parse::<u16>().is_ok());
        if !port_ok {
            return Err(invalid("master", &self.master, "must be host:port"));
        }
        if self.token.is_empty() {
            // Do not echo even a malformed secret.
            return Err(invalid("token", "", "must not be empty"));
        }
        if parse_fingerprint(&self.fingerprint).is_err() {
            return Err(invalid(
                "fingerprint",
                &self.fingerprint,
                "must be 64 hex digits (SHA-256 of the master certificate)",
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn config() -> ClusterConfig {
        ClusterConfig {
            master: "farm.example:4433".to_owned(),
            token: "ab".repeat(32),
            fingerprint: "0f".repeat(32),
        }
    }

    #[test]
    fn generated_configs_round_trip_through_a_file() {
        let identity = MasterIdentity::generate(&[]).expect("generates");
        let a = ClusterConfig::generate("10.0.0.1:4433", &identity).expect("generates");
        let b = ClusterConfig::generate("10.0.0.1:4433", &identity).expect("generates");
        assert_eq!(a.token.len(), 2 * TOKEN_BYTES);
        assert_ne!(a.token, b.token, "tokens are random");
        assert_eq!(a.fingerprint, identity.fingerprint());

        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join(CLUSTER_FILE);
        a.save(&path).expect("saves");
        assert_eq!(ClusterConfig::load(&path).expect("loads"), a);
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let mode = std::fs::metadata(&path).expect("file").permissions().mode();
            assert_eq!(mode & 0o777, 0o600);
        }
    }

    /// Parses `text` as `cluster.toml` and expects an error reading `expected`.
    fn check_error(text: &str, expected: &str) {
        let error = ClusterConfig::from_toml(text, Path::new("conf/cluster.toml"))
            .expect_err(expected)
            .to_string();
        assert_eq!(error, expected);
    }

    #[test]
    fn errors_name_the_file_and_line() {
        let good = config().to_toml();
        assert_eq!(
            ClusterConfig::from_toml(&good, Path::new("x")).expect("parses"),
            config()
        );
        let fp = "0f".repeat(32);
        check_error(
            &format!("master = \"a:1\"\ntoken = \"t\"\nfingerprint = \"{fp}\"\nextra = 1\n"),
            "conf/cluster.toml:4:1: unknown field `extra`, expected one of `master`, `token`, `fingerprint`",
        );
        check_error(
            "master = \"a:1\"\ntoken = \"t\n",
            "conf/cluster.toml:2:11: invalid basic string",
        );
        check_error(
            &format!("master = \"a:1\"\nfingerprint = \"{fp}\"\n"),
            "conf/cluster.toml:1:1: missing field `token`",
        );
        check_error(
            &format!("master = \"farm\"\ntoken = \"t\"\nfingerprint = \"{fp}\"\n"),
            "conf/cluster.toml: master = \"farm\": must be host:port",
        );
        check_error(
            "master = \"[::1]:4433\"\ntoken = \"t\"\nfingerprint = \"abc\"\n",
            "conf/cluster.toml: fingerprint = \"abc\": must be 64 hex digits (SHA-256 of the master certificate)",
        );
        check_error(
            &format!("master = \"a:1\"\ntoken = \"\"\nfingerprint = \"{fp}\"\n"),
            "conf/cluster.toml: token = \"\": must not be empty",
        );
        let missing = ClusterConfig::load(Path::new("/nonexistent/cluster.toml"))
            .expect_err("no such file")
            .to_string();
        assert!(
            missing.starts_with("/nonexistent/cluster.toml: "),
            "{missing}"
        );
    }

    #[test]
    fn debug_output_hides_the_token() {
        let shown = format!("{:?}", config());
        assert!(!shown.contains(&"ab".repeat(32)), "{shown}");
    }
}

//! TLS for the farm: the master's self-signed identity and the quinn
//! configurations.
//!
//! There is no certificate authority. The master creates a self-signed
//! certificate on first start and keeps it in its state directory; workers
//! and submitters pin the SHA-256 fingerprint of that certificate (from
//! `cluster.toml`). The client verifier accepts exactly the certificate with
//! that fingerprint, compared in constant time, and still checks the TLS 1.3
//! handshake signature with ring, so only the holder of the key gets in.
//! Host names, validity dates and chains play no part.
//!
//! Transport settings, the same on both ends: the client sends a keep-alive
//! every [`KEEP_ALIVE_INTERVAL`] (the master too), and a connection that
//! hears nothing for [`vtfarm_proto::PEER_TIMEOUT`] is dead; so a worker busy
//! tracing stays connected, and a vanished machine (master or worker) is
//! noticed when the master's scheduler gives up on it (the same timeout).

use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use rustls::DigitallySignedStruct;
use rustls::client::danger::{HandshakeSignatureValid, ServerCertVerified, ServerCertVerifier};
use rustls::crypto::CryptoProvider;
use rustls::pki_types::{CertificateDer, PrivateKeyDer, PrivatePkcs8KeyDer, ServerName, UnixTime};
use sha2::{Digest, Sha256};
use subtle::ConstantTimeEq;
use vtfarm_proto::PEER_TIMEOUT;

/// The ALPN protocol both ends require.
pub const ALPN: &[u8] = b"vtfarm/1";
/// The server name clients connect with; always in the certificate's SANs
/// (the pin, not the name, is what is checked).
pub const SERVER_NAME: &str = "vtfarm-master";
/// How often each end sends a QUIC PING when it has nothing else to send:
/// several times per idle timeout, so a lost PING or two closes nothing.
pub const KEEP_ALIVE_INTERVAL: Duration = Duration::from_secs(1);
const _: () = assert!(KEEP_ALIVE_INTERVAL.as_millis() * 5 <= PEER_TIMEOUT.as_millis());
/// The certificate's file name in the master's state directory.
pub const CERT_FILE: &str = "master.crt.der";
/// The private key's file name (PKCS #8 DER, mode 0600 on unix).
pub const KEY_FILE: &str = "master.key.der";

/// Why the master's identity could not be created or loaded.
#[derive(Debug, thiserror::Error)]
pub enum IdentityError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    /// Only one of the two files exists: refuse to overwrite a key or to
    /// invent a certificate that workers do not know.
    #[error(
        "{} exists but {} does not; restore it, or delete both to create a new identity (workers then need the new cluster.toml)",
        present.display(),
        missing.display()
    )]
    Incomplete { present: PathBuf, missing: PathBuf },
    /// The files do not hold a usable certificate and matching key.
    #[error("{} / {}: {message}", cert.display(), key.display())]
    Invalid {
        cert: PathBuf,
        key: PathBuf,
        message: String,
    },
    #[error("cannot generate the master certificate: {0}")]
    Generate(#[from] rcgen::Error),
}

/// Why a TLS configuration could not be built.
#[derive(Debug, thiserror::Error)]
pub enum TlsError {
    /// A pinned fingerprint that is not 64 hex digits.
    #[error("fingerprint {0:?} is not 64 hex digits (SHA-256 of the master certificate)")]
    BadFingerprint(String),
    #[error("TLS configuration: {0}")]
    Rustls(#[from] rustls::Error),
    #[error("QUIC TLS configuration: {0}")]
    Quic(String),
}

/// The master's certificate and private key.
pub struct MasterIdentity {
    cert: CertificateDer<'static>,
    key: PrivatePkcs8KeyDer<'static>,
}

impl std::fmt::Debug for MasterIdentity {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // Never print the key.
        f.debug_struct("MasterIdentity")
            .field("fingerprint", &self.fingerprint())
            .finish_non_exhaustive()
    }
}

impl MasterIdentity {
    /// A fresh self-signed identity (ECDSA P-256) whose certificate names
    /// [`SERVER_NAME`] and `hosts` (DNS names or IP addresses).
    pub fn generate(hosts: &[String]) -> Result<Self, IdentityError> {
        let mut names = vec![SERVER_NAME.to_owned()];
        names.extend(hosts.iter().filter(|h| *h != SERVER_NAME).cloned());
        let certified = rcgen::generate_simple_self_signed(names)?;
        Ok(MasterIdentity {
            cert: certified.cert.der().clone(),
            key: PrivatePkcs8KeyDer::from(certified.signing_key.serialize_der()),
        })
    }

    /// Loads the identity from `state_dir`, or creates and saves one there
    /// on first start (`hosts` only matter then). The directory is created
    /// if missing.
    pub fn load_or_create(state_dir: &Path, hosts: &[String]) -> Result<Self, IdentityError> {
        let cert_path = state_dir.join(CERT_FILE);
        let key_path = state_dir.join(KEY_FILE);
        match (exists(&cert_path)?, exists(&key_path)?) {
            (true, true) => Self::load(state_dir),
            (false, false) => {
                let identity = Self::generate(hosts)?;
                identity.save(state_dir)?;
                tracing::info!(
                    "created master identity in {}, fingerprint {}",
                    state_dir.display(),
                    identity.fingerprint()
                );
                Ok(identity)
            }
            (true, false) => Err(IdentityError::Incomplete {
                present: cert_path,
                missing: key_path,
            }),
            (false, true) => Err(IdentityError::Incomplete {
                present: key_path,
                missing: cert_path,
            }),
        }
    }

    /// Loads an identity saved by [`MasterIdentity::load_or_create`] and
    /// checks that the key belongs to the certificate.
    pub fn load(state_dir: &Path) -> Result<Self, IdentityError> {
        let cert_path = state_dir.join(CERT_FILE);
        let key_path = state_dir.join(KEY_FILE);
        let read = |path: &Path| {
            fs::read(path).map_err(|source| IdentityError::Io {
                path: path.to_owned(),
                source,
            })
        };
        let identity = MasterIdentity {
            cert: CertificateDer::from(read(&cert_path)?),
            key: PrivatePkcs8KeyDer::from(read(&key_path)?),
        };
        warn_if_readable_by_others(&key_path);
        rustls::sign::CertifiedKey::from_der(
            vec![identity.cert.clone()],
            identity.private_key(),
            &provider(),
        )
        .map_err(|e| IdentityError::Invalid {
            cert: cert_path,
            key: key_path,
            message: e.to_string(),
        })?;
        Ok(identity)
    }

    /// Writes both files; the key first, readable by the owner only.
    fn save(&self, state_dir: &Path) -> Result<(), IdentityError> {
        let io = |path: &Path| {
            let path = path.to_owned();
            move |source| IdentityError::Io { path, source }
        };
        fs::create_dir_all(state_dir).map_err(io(state_dir))?;
        let key_path = state_dir.join(KEY_FILE);
        write_new(&key_path, self.key.secret_pkcs8_der(), true).map_err(io(&key_path))?;
        let cert_path = state_dir.join(CERT_FILE);
        write_new(&cert_path, &self.cert, false).map_err(io(&cert_path))?;
        Ok(())
    }

    /// SHA-256 of the certificate DER as 64 lowercase hex digits: what
    /// `cluster.toml` pins.
    pub fn fingerprint(&self) -> String {
        fingerprint_of(&self.cert)
    }

    /// The certificate in DER.
    pub fn certificate_der(&self) -> &[u8] {
        &self.cert
    }

    fn private_key(&self) -> PrivateKeyDer<'static> {
        PrivateKeyDer::Pkcs8(self.key.clone_key())
    }
}

/// SHA-256 of a certificate's DER as 64 lowercase hex digits.
pub fn fingerprint_of(cert_der: &[u8]) -> String {
    hex::encode(Sha256::digest(cert_der))
}

/// Parses a fingerprint (64 hex digits, either case).
pub fn parse_fingerprint(text: &str) -> Result<[u8; 32], TlsError> {
    let bad = || TlsError::BadFingerprint(text.to_owned());
    let bytes = hex::decode(text.trim()).map_err(|_| bad())?;
    bytes.try_into().map_err(|_| bad())
}

fn exists(path: &Path) -> Result<bool, IdentityError> {
    path.try_exists().map_err(|source| IdentityError::Io {
        path: path.to_owned(),
        source,
    })
}

/// Creates `path` (failing if it exists, so two masters starting at once
/// cannot mix their files) and writes `bytes`; `private` files get mode 0600.
fn write_new(path: &Path, bytes: &[u8], private: bool) -> std::io::Result<()> {
    let mut options = fs::OpenOptions::new();
    options.write(true).create_new(true);
    #[cfg(unix)]
    if private {
        use std::os::unix::fs::OpenOptionsExt;
        options.mode(0o600);
    }
    #[cfg(not(unix))]
    let _ = private;
    let mut file = options.open(path)?;
    file.write_all(bytes)?;
    file.sync_all()
}

fn warn_if_readable_by_others(key_path: &Path) {
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        if let Ok(meta) = fs::metadata(key_path) {
            if meta.permissions().mode() & 0o077 != 0 {
                tracing::warn!(
                    "{} is readable by others; run chmod 600 on it",
                    key_path.display()
                );
            }
        }
    }
    #[cfg(not(unix))]
    let _ = key_path;
}

/// The ring crypto provider, passed explicitly so no process-wide default
/// provider is needed.
fn provider() -> CryptoProvider {
    rustls::crypto::ring::default_provider()
}

fn transport() -> Arc<quinn::TransportConfig> {
    let mut transport = quinn::TransportConfig::default();
    transport.keep_alive_interval(Some(KEEP_ALIVE_INTERVAL));
    transport.max_idle_timeout(Some(
        quinn::IdleTimeout::try_from(PEER_TIMEOUT).expect("10 s fits QUIC's idle timeout range"),
    ));
    Arc::new(transport)
}

/// The master's QUIC server configuration: TLS 1.3 with its certificate,
/// ALPN [`ALPN`], no client certificates (clients prove themselves with the
/// token in `Hello`).
pub fn server_config(identity: &MasterIdentity) -> Result<quinn::ServerConfig, TlsError> {
    let mut tls = rustls::ServerConfig::builder_with_provider(Arc::new(provider()))
        .with_protocol_versions(&[&rustls::version::TLS13])?
        .with_no_client_auth()
        .with_single_cert(vec![identity.cert.clone()], identity.private_key())?;
    tls.alpn_protocols = vec![ALPN.to_vec()];
    let crypto = quinn::crypto::rustls::QuicServerConfig::try_from(tls)
        .map_err(|e| TlsError::Quic(e.to_string()))?;
    let mut config = quinn::ServerConfig::with_crypto(Arc::new(crypto));
    config.transport_config(transport());
    Ok(config)
}

/// A worker's or submitter's QUIC client configuration that accepts only
/// the master certificate with SHA-256 `pinned_fingerprint` (hex). Connect
/// with [`SERVER_NAME`] as the server name.
pub fn client_config(pinned_fingerprint: &str) -> Result<quinn::ClientConfig, TlsError> {
    let provider = Arc::new(provider());
    let verifier = PinnedVerifier {
        fingerprint: parse_fingerprint(pinned_fingerprint)?,
        provider: provider.clone(),
    };
    let mut tls = rustls::ClientConfig::builder_with_provider(provider)
        .with_protocol_versions(&[&rustls::version::TLS13])?
        .dangerous()
        .with_custom_certificate_verifier(Arc::new(verifier))
        .with_no_client_auth();
    tls.alpn_protocols = vec![ALPN.to_vec()];
    let crypto = quinn::crypto::rustls::QuicClientConfig::try_from(tls)
        .map_err(|e| TlsError::Quic(e.to_string()))?;
    let mut config = quinn::ClientConfig::new(Arc::new(crypto));
    config.transport_config(transport());
    Ok(config)
}

/// Accepts exactly the end-entity certificate with the pinned SHA-256, and
/// verifies handshake signatures against it with the provider's algorithms.
#[derive(Debug)]
struct PinnedVerifier {
    fingerprint: [u8; 32],
    provider: Arc<CryptoProvider>,
}

impl ServerCertVerifier for PinnedVerifier {
    fn verify_server_cert(
        &self,
        end_entity: &CertificateDer<'_>,
        _intermediates: &[CertificateDer<'_>],
        _server_name: &ServerName<'_>,
        _ocsp_response: &[u8],
        _now: UnixTime,
    ) -> Result<ServerCertVerified, rustls::Error> {
        let presented: [u8; 32] = Sha256::digest(end_entity).into();
        if bool::from(presented.ct_eq(&self.fingerprint)) {
            Ok(ServerCertVerified::assertion())
        } else {
            Err(rustls::Error::InvalidCertificate(
                rustls::CertificateError::ApplicationVerificationFailure,
            ))
        }
    }

    fn verify_tls12_signature(
        &self,
        message: &[u8],
        cert: &CertificateDer<'_>,
        dss: &DigitallySignedStruct,
    ) -> Result<HandshakeSignatureValid, rustls::Error> {
        rustls::crypto::verify_tls12_signature(
            message,
            cert,
            dss,
            &self.provider.signature_verification_algorithms,
        )
    }

    fn verify_tls13_signature(
        &self,
        message: &[u8],
        cert: &CertificateDer<'_>,
        dss: &DigitallySignedStruct,
    ) -> Result<HandshakeSignatureValid, rustls::Error> {
        rustls::crypto::verify_tls13_signature(
            message,
            cert,
            dss,
            &self.provider.signature_verification_algorithms,
        )
    }

    fn supported_verify_schemes(&self) -> Vec<rustls::SignatureScheme> {
        self.provider
            .signature_verification_algorithms
            .supported_schemes()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn verifier_for(identity: &MasterIdentity) -> PinnedVerifier {
        PinnedVerifier {
            fingerprint: parse_fingerprint(&identity.fingerprint()).expect("own fingerprint"),
            provider: Arc::new(provider()),
        }
    }

    fn verify(verifier: &PinnedVerifier, identity: &MasterIdentity) -> bool {
        let name = ServerName::try_from(SERVER_NAME).expect("a valid DNS name");
        verifier
            .verify_server_cert(&identity.cert, &[], &name, &[], UnixTime::now())
            .is_ok()
    }

    #[test]
    fn the_verifier_accepts_exactly_the_pinned_certificate() {
        let a = MasterIdentity::generate(&[]).expect("generates");
        let b = MasterIdentity::generate(&[]).expect("generates");
        assert!(verify(&verifier_for(&a), &a));
        assert!(!verify(&verifier_for(&a), &b));
        assert!(!verify(&verifier_for(&b), &a));
    }

    #[test]
    fn identities_are_created_once_and_then_loaded() {
        let dir = tempfile::tempdir().expect("temp dir");
        let state = dir.path().join("state");
        let hosts = ["farm.example".to_owned(), "10.1.2.3".to_owned()];
        let created = MasterIdentity::load_or_create(&state, &hosts).expect("creates");
        let fingerprint = created.fingerprint();
        assert_eq!(fingerprint.len(), 64);
        assert!(
            fingerprint
                .chars()
                .all(|c| c.is_ascii_digit() || ('a'..='f').contains(&c))
        );
        assert_eq!(fingerprint, fingerprint_of(created.certificate_der()));
        let loaded = MasterIdentity::load_or_create(&state, &[]).expect("loads");
        assert_eq!(loaded.fingerprint(), fingerprint);
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let mode = fs::metadata(state.join(KEY_FILE))
                .expect("key file")
                .permissions()
                .mode();
            assert_eq!(mode & 0o777, 0o600);
        }
        assert!(server_config(&loaded).is_ok());
    }

    #[test]
    fn half_an_identity_or_a_bad_key_is_an_error_naming_the_files() {
        let dir = tempfile::tempdir().expect("temp dir");
        MasterIdentity::load_or_create(dir.path(), &[]).expect("creates");
        let key = fs::read(dir.path().join(KEY_FILE)).expect("key");

        fs::remove_file(dir.path().join(CERT_FILE)).expect("remove");
        let error = MasterIdentity::load_or_create(dir.path(), &[]).expect_err("half");
        assert!(matches!(error, IdentityError::Incomplete { .. }), "{error}");
        assert!(error.to_string().contains(CERT_FILE), "{error}");

        // A certificate of another key.
        let other = MasterIdentity::generate(&[]).expect("generates");
        fs::write(dir.path().join(CERT_FILE), other.certificate_der()).expect("write");
        let error = MasterIdentity::load(dir.path()).expect_err("mismatch");
        assert!(matches!(error, IdentityError::Invalid { .. }), "{error}");

        fs::write(dir.path().join(KEY_FILE), &key[..10]).expect("write");
        let error = MasterIdentity::load(dir.path()).expect_err("truncated key");
        assert!(error.to_string().contains(KEY_FILE), "{error}");
    }

    #[test]
    fn fingerprints_must_be_64_hex_digits() {
        let id = MasterIdentity::generate(&[]).expect("generates");
        assert!(client_config(&id.fingerprint()).is_ok());
        assert!(client_config(&id.fingerprint().to_uppercase()).is_ok());
        for bad in ["", "abc", &"g".repeat(64), &"ab".repeat(33)] {
            assert!(
                matches!(client_config(bad), Err(TlsError::BadFingerprint(_))),
                "{bad}"
            );
        }
    }

    #[test]
    fn debug_output_never_shows_the_key() {
        let id = MasterIdentity::generate(&[]).expect("generates");
        let shown = format!("{id:?}");
        assert!(shown.contains(&id.fingerprint()));
        assert!(!shown.contains(&hex::encode(id.key.secret_pkcs8_der())));
    }
}

//! Dialling the master over QUIC: pinned certificate, token handshake, and
//! one bidirectional stream for the session (workers and submitters alike).

use std::net::SocketAddr;
use std::time::Duration;

use tokio::net::lookup_host;

use vtfarm_proto::{Hello, Role};

use crate::{Link, ProtoError, ReadBounds, SERVER_NAME, client_config, client_handshake};

/// Where and who to connect as.
#[derive(Clone, Debug)]
pub struct ClientOptions {
    /// The master's `host:port`.
    pub master: String,
    pub token: String,
    /// The master certificate's SHA-256 fingerprint (hex).
    pub fingerprint: String,
}

/// Why connecting failed.
#[derive(Debug, thiserror::Error)]
pub enum ConnectError {
    #[error("cannot resolve {0}")]
    Resolve(String),
    #[error("{0}")]
    Setup(String),
    #[error("cannot connect to {master}: {source}")]
    Connect { master: String, source: ProtoError },
    /// The master's certificate is not the one pinned in `cluster.toml`.
    #[error(
        "the certificate of {master} does not match the fingerprint in cluster.toml ({source}); copy the master's current cluster.toml"
    )]
    WrongCertificate { master: String, source: ProtoError },
}

impl ConnectError {
    /// Whether trying again later could help (the master may be restarting);
    /// a refusal (wrong token or version), a certificate other than the
    /// pinned one or a bad set-up will not.
    pub fn is_transient(&self) -> bool {
        match self {
            ConnectError::Resolve(_) => true,
            ConnectError::Setup(_) | ConnectError::WrongCertificate { .. } => false,
            ConnectError::Connect { source, .. } => !matches!(source, ProtoError::Refused { .. }),
        }
    }
}

/// How long connecting (QUIC, TLS and the token handshake) may take: a
/// master that is not there is reported in seconds, not at the idle timeout.
pub const CONNECT_TIMEOUT: Duration = Duration::from_secs(3);

/// An open session: the endpoint must outlive the link.
pub struct Connection {
    pub endpoint: quinn::Endpoint,
    pub connection: quinn::Connection,
    pub link: Link,
}

/// Connects, completes the handshake as `role` and opens the session stream.
pub async fn connect(options: &ClientOptions, role: Role) -> Result<Connection, ConnectError> {
    let address: SocketAddr = lookup_host(&options.master)
        .await
        .ok()
        .and_then(|mut a| a.next())
        .ok_or_else(|| ConnectError::Resolve(options.master.clone()))?;
    let bind: SocketAddr = if address.is_ipv6() {
        "[::]:0"
    } else {
        "0.0.0.0:0"
    }
    .parse()
    .expect("literal address");
    let mut endpoint = quinn::Endpoint::client(bind)
        .map_err(|e| ConnectError::Setup(format!("cannot open a UDP socket: {e}")))?;
    endpoint.set_default_client_config(
        client_config(&options.fingerprint).map_err(|e| ConnectError::Setup(e.to_string()))?,
    );
    let failed = |source: ProtoError| ConnectError::Connect {
        master: options.master.clone(),
        source,
    };
    let connecting = endpoint
        .connect(address, SERVER_NAME)
        .map_err(|e| ConnectError::Setup(e.to_string()))?;
    let session = async {
        let connection = connecting.await?;
        client_handshake(&connection, &Hello::new(options.token.clone(), role)).await?;
        let (send, recv) = connection.open_bi().await?;
        Ok::<_, ProtoError>((connection, send, recv))
    };
    let (connection, send, recv) = tokio::time::timeout(CONNECT_TIMEOUT, session)
        .await
        .map_err(|_| failed(ProtoError::Timeout))?
        .map_err(|e| match e {
            // Our verifier refuses a certificate only when its fingerprint differs.
            ProtoError::Connection(quinn::ConnectionError::TransportError(t))
                if t.reason.contains("invalid peer certificate") =>
            {
                ConnectError::WrongCertificate {
                    master: options.master.clone(),
                    source: ProtoError::Connection(quinn::ConnectionError::TransportError(t)),
                }
            }
            e => failed(e),
        })?;
    let link = Link::over_connection(
        connection.clone(),
        recv,
        send,
        ReadBounds::SESSION,
        options.master.clone(),
    );
    Ok(Connection {
        endpoint,
        connection,
        link,
    })
}

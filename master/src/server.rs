//! The master's QUIC endpoint: every incoming connection must pass the
//! handshake (pinned certificate on the client side, token and version here)
//! before it reaches the core; a bad one is refused and logged with the
//! peer's address while the master keeps serving everyone else.

use std::net::SocketAddr;
use std::path::Path;

use tracing::{info, warn};
use vtfarm_master_core::Peer;
use vtfarm_proto::{HandshakePolicy, Role, SESSION_LIMIT};
use vtfarm_transport::{
    IdentityError, Link, MasterIdentity, ReadBounds, TlsError, server_config, server_handshake,
};

use crate::driver::MasterHandle;

/// Why the master's endpoint could not start.
#[derive(Debug, thiserror::Error)]
pub enum BindError {
    #[error(transparent)]
    Tls(#[from] TlsError),
    #[error("cannot listen on {address}: {source}")]
    Listen {
        address: SocketAddr,
        source: std::io::Error,
    },
}

/// A bound QUIC endpoint with the master's identity.
pub fn bind(listen: SocketAddr, identity: &MasterIdentity) -> Result<quinn::Endpoint, BindError> {
    let config = server_config(identity)?;
    quinn::Endpoint::server(config, listen).map_err(|source| BindError::Listen {
        address: listen,
        source,
    })
}

/// Loads (or creates on first start) the master's key and certificate in `state_dir`.
pub fn identity(state_dir: &Path, hosts: &[String]) -> Result<MasterIdentity, IdentityError> {
    MasterIdentity::load_or_create(state_dir, hosts)
}

/// Accepts connections until the endpoint closes.
pub async fn serve(endpoint: quinn::Endpoint, policy: HandshakePolicy, master: MasterHandle) {
    while let Some(incoming) = endpoint.accept().await {
        let (policy, master) = (policy.clone(), master.clone());
        tokio::spawn(async move {
            let address = incoming.remote_address();
            let conn = match incoming.await {
                Ok(c) => c,
                Err(e) => return warn!(peer = %address, "connection failed: {e}"),
            };
            let hello = match server_handshake(&conn, &policy).await {
                Ok(hello) => hello,
                Err(refusal) => {
                    return warn!(peer = %address, code = ?refusal.code, "refused: {}", refusal.message);
                }
            };
            let (send, recv) = match conn.accept_bi().await {
                Ok(s) => s,
                Err(e) => return warn!(peer = %address, "no session stream: {e}"),
            };
            let peer = match hello.role {
                Role::Worker { threads, name } => Peer::Worker {
                    name,
                    threads,
                    address: address.to_string(),
                },
                Role::Submitter => Peer::Submitter {
                    address: address.to_string(),
                },
            };
            info!(peer = %address, ?peer, "accepted");
            let closer = conn.clone();
            let bounds = ReadBounds {
                limit: SESSION_LIMIT,
                stall: policy.message_stall,
            };
            master.attach(
                peer,
                Link::over_connection(conn.clone(), recv, send, bounds, address.to_string()),
                Some(Box::new(move |reason: &str| {
                    closer.close(vtfarm_transport::CLOSE_NORMAL, reason.as_bytes())
                })),
            );
        });
    }
}

//! The worker's connection loop: connect (see `vtfarm_transport::client`),
//! serve, and reconnect with backoff when the master goes away.

use std::time::Duration;

use tracing::{info, warn};
use vtfarm_proto::Role;
use vtfarm_transport::client::{ClientOptions, ConnectError, connect};

use crate::engine::Engine;
use crate::serve::{DrainSignal, serve};
use crate::session::{SessionEnd, WorkerConfig};

/// Runs a worker until the master shuts it down or `drain` is raised:
/// connects, serves, and reconnects with exponential backoff (up to 10 s)
/// when the link drops.
pub async fn run_worker(
    options: ClientOptions,
    name: String,
    threads: u32,
    mut engine: Engine,
    config: WorkerConfig,
    mut drain: DrainSignal,
) -> Result<(), ConnectError> {
    let mut backoff = Duration::from_millis(200);
    while !drain.is_raised() {
        match connect(
            &options,
            Role::Worker {
                threads,
                name: name.clone(),
            },
        )
        .await
        {
            Ok(conn) => {
                info!(master = %options.master, "connected to the master");
                backoff = Duration::from_millis(200);
                let end = serve(conn.link, &mut engine, config, drain.clone()).await;
                conn.connection
                    .close(vtfarm_transport::CLOSE_NORMAL, b"bye");
                conn.endpoint.wait_idle().await;
                match end {
                    SessionEnd::Shutdown => {
                        info!("shut down by the master");
                        return Ok(());
                    }
                    SessionEnd::Drained => {
                        info!("drained, said goodbye");
                        return Ok(());
                    }
                    SessionEnd::Disconnected => {
                        warn!(master = %options.master, "connection lost, reconnecting")
                    }
                }
            }
            Err(e) if e.is_transient() => warn!("{e}; retrying in {backoff:?}"),
            Err(e) => return Err(e),
        }
        tokio::select! {
            () = tokio::time::sleep(backoff) => {}
            () = drain.raised() => {}
        }
        backoff = (backoff * 2).min(Duration::from_secs(10));
    }
    info!("stopped while not connected");
    Ok(())
}

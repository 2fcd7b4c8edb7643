//! Connections and peers: who is on each connection, the names logs and
//! statistics give them (workers that left during the running frame
//! included), and the frames each worker keeps as it counts them.

use std::collections::BTreeMap;
use vtfarm_proto::JobId;

use vtfarm_proto::{JobAction, KeptFrames, Message};
use vtfarm_scheduler::WorkerId;

/// A connection, numbered by the driver. A worker's connection is its
/// worker in the scheduler ([`ConnId::worker`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct ConnId(pub u64);

impl ConnId {
    /// The scheduler's worker on this connection.
    pub fn worker(self) -> WorkerId {
        WorkerId(self.0)
    }

    /// The connection of the scheduler's `worker`.
    pub fn of_worker(worker: WorkerId) -> ConnId {
        ConnId(worker.0)
    }
}

impl std::fmt::Display for ConnId {
    /// The bare number, as logs name a connection.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        self.0.fmt(f)
    }
}

/// Who is on a connection (from its handshake).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Peer {
    Worker {
        name: String,
        threads: u32,
        address: String,
    },
    Submitter {
        address: String,
    },
}

/// The connected peers: see the module's documentation.
#[derive(Default)]
pub(crate) struct Peers {
    peers: BTreeMap<ConnId, Peer>,
    /// Workers that left during the running frame, for its stats' names.
    departed: BTreeMap<ConnId, Peer>,
    /// The frames each worker keeps, as it counts them from the messages
    /// it got (`KeptFrames`, fed by [`Peers::saw`]): a split frame's
    /// `FrameStart` goes again only to a worker that let it go.
    worker_frames: BTreeMap<ConnId, KeptFrames>,
}

impl Peers {
    /// `peer` passed its handshake on `conn`.
    pub(crate) fn joined(&mut self, conn: ConnId, peer: Peer) {
        if matches!(peer, Peer::Worker { .. }) {
            self.worker_frames.insert(conn, KeptFrames::default());
        }
        self.peers.insert(conn, peer);
    }

    /// `conn` went away: who was on it. A worker keeps its name for the
    /// running frame's stats.
    pub(crate) fn left(&mut self, conn: ConnId) -> Option<Peer> {
        let peer = self.peers.remove(&conn)?;
        if matches!(peer, Peer::Worker { .. }) {
            self.worker_frames.remove(&conn);
            self.departed.insert(conn, peer.clone());
        }
        Some(peer)
    }

    /// A frame completed: the workers that left during it are named no more.
    pub(crate) fn frame_complete(&mut self) {
        self.departed.clear();
    }

    pub(crate) fn get(&self, conn: ConnId) -> Option<&Peer> {
        self.peers.get(&conn)
    }

    /// The workers connected now.
    pub(crate) fn workers(&self) -> Vec<ConnId> {
        (self.peers.iter())
            .filter(|(_, p)| matches!(p, Peer::Worker { .. }))
            .map(|(&c, _)| c)
            .collect()
    }

    /// How logs and statistics name `conn`'s peer (a worker that left
    /// during the running frame too).
    pub(crate) fn name(&self, conn: ConnId) -> String {
        match self.peers.get(&conn).or(self.departed.get(&conn)) {
            Some(Peer::Worker { name, address, .. }) => format!("{name} ({address})"),
            Some(Peer::Submitter { address }) => format!("submitter ({address})"),
            None => format!("connection {conn}"),
        }
    }

    /// Who asks for `action` over `conn`: the command and the host it ran
    /// on (`vtfarm cancel` on 10.0.0.7), for a job's reason and listing.
    pub(crate) fn controller(&self, conn: ConnId, action: &JobAction) -> String {
        let command = format!("`vtfarm {}`", action.command());
        match self.peers.get(&conn).or(self.departed.get(&conn)) {
            Some(Peer::Submitter { address }) => format!("{command} on {}", host_of(address)),
            _ => format!("{command} from {}", self.name(conn)),
        }
    }

    /// A worker's name (its connection number if it is gone).
    pub(crate) fn worker_name(&self, conn: ConnId) -> String {
        match self.peers.get(&conn) {
            Some(Peer::Worker { name, .. }) => name.clone(),
            _ => format!("connection {conn}"),
        }
    }

    /// A submitter's address (the host a job's listing names).
    pub(crate) fn submitter_host(&self, conn: ConnId) -> String {
        match self.peers.get(&conn) {
            Some(Peer::Submitter { address }) => address.clone(),
            _ => "unknown".into(),
        }
    }

    /// `message` goes to `conn`: a frame it names to a worker is among the
    /// frames that worker keeps now.
    pub(crate) fn saw(&mut self, conn: ConnId, message: &Message) {
        if let Some(kept) = self.worker_frames.get_mut(&conn) {
            kept.saw(message);
        }
    }

    /// Whether worker `conn` keeps frame `frame` of `job` (announced or
    /// set up), by the rule both ends count ([`KeptFrames`]).
    pub(crate) fn keeps(&self, conn: ConnId, job: JobId, frame: u32) -> bool {
        (self.worker_frames.get(&conn)).is_some_and(|kept| kept.contains((job, frame)))
    }
}

/// The host of a socket address (`127.0.0.1:5000`, `[::1]:5000`): the
/// port says only which connection it was.
fn host_of(address: &str) -> &str {
    address
        .rsplit_once(':')
        .map_or(address, |(host, _port)| host)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_connection_prints_as_its_number_and_is_its_workers_id() {
        let conn = ConnId(42);
        assert_eq!(conn.to_string(), "42");
        assert_eq!(format!("conn {conn}"), "conn 42");
        assert_eq!(conn.worker(), WorkerId(42));
        assert_eq!(ConnId::of_worker(conn.worker()), conn);
    }

    fn worker(name: &str) -> Peer {
        Peer::Worker {
            name: name.into(),
            threads: 4,
            address: "10.0.0.7:4000".into(),
        }
    }

    /// A worker that left keeps its name until the running frame
    /// completes; its kept frames go at once.
    #[test]
    fn a_worker_that_left_is_named_until_its_frame_completes() {
        let mut peers = Peers::default();
        peers.joined(ConnId(3), worker("w1"));
        peers.joined(
            ConnId(4),
            Peer::Submitter {
                address: "10.0.0.9:1".into(),
            },
        );
        assert_eq!(peers.workers(), vec![ConnId(3)]);
        assert_eq!(peers.submitter_host(ConnId(4)), "10.0.0.9:1");
        assert_eq!(peers.submitter_host(ConnId(3)), "unknown");
        assert_eq!(peers.left(ConnId(3)), Some(worker("w1")));
        assert!(peers.workers().is_empty());
        assert_eq!(peers.name(ConnId(3)), "w1 (10.0.0.7:4000)");
        assert_eq!(
            peers.worker_name(ConnId(3)),
            "connection 3",
            "gone: no worker now"
        );
        peers.frame_complete();
        assert_eq!(peers.name(ConnId(3)), "connection 3");
        assert_eq!(peers.left(ConnId(3)), None);
    }

    /// A worker keeps the frames its packages named; a submitter keeps none.
    #[test]
    fn a_worker_keeps_the_frames_its_messages_named() {
        let mut peers = Peers::default();
        peers.joined(ConnId(1), worker("w"));
        peers.joined(
            ConnId(2),
            Peer::Submitter {
                address: "s".into(),
            },
        );
        let package = Message::Package(vtfarm_proto::Package {
            id: 1,
            job: JobId(5),
            frame: 0,
            triangles: vec![0],
            whole: None,
        });
        peers.saw(ConnId(1), &package);
        peers.saw(ConnId(2), &package);
        assert!(peers.keeps(ConnId(1), JobId(5), 0));
        assert!(!peers.keeps(ConnId(1), JobId(5), 1), "another frame");
        assert!(
            !peers.keeps(ConnId(2), JobId(5), 0),
            "a submitter keeps no frames"
        );
        peers.left(ConnId(1));
        assert!(!peers.keeps(ConnId(1), JobId(5), 0), "gone with its worker");
    }

    /// A job's reason names the command and the host that asked, not the
    /// connection's ephemeral port.
    #[test]
    fn a_control_request_is_named_by_its_command_and_host() {
        let mut peers = Peers::default();
        let submitter = |address: &str| Peer::Submitter {
            address: address.into(),
        };
        peers.joined(ConnId(1), submitter("10.0.0.9:33292"));
        peers.joined(ConnId(2), submitter("[::1]:5000"));
        peers.joined(ConnId(3), worker("w1"));
        assert_eq!(
            peers.controller(ConnId(1), &JobAction::Cancel),
            "`vtfarm cancel` on 10.0.0.9"
        );
        assert_eq!(
            peers.controller(ConnId(2), &JobAction::Requeue { failed_only: true }),
            "`vtfarm requeue --failed` on [::1]"
        );
        assert_eq!(
            peers.controller(ConnId(3), &JobAction::Pause),
            "`vtfarm pause` from w1 (10.0.0.7:4000)"
        );
    }
}

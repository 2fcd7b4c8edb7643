//! The handshake over real QUIC on 127.0.0.1: one master endpoint whose
//! accept loop keeps serving, clients with the right and wrong fingerprint,
//! token, version and bytes. After every bad client a good one must still
//! get in on the same endpoint.

use std::net::SocketAddr;
use std::time::Duration;

use tokio::sync::mpsc;
use vtfarm_proto::{
    HandshakePolicy, Hello, MAX_HANDSHAKE_BYTES, Message, PROTOCOL_VERSION, Refusal, RefuseCode,
    Role, SESSION_LIMIT, encode_message,
};
use vtfarm_transport::{
    Link, MasterIdentity, ProtoError, ReadBounds, SERVER_NAME, client_config, client_handshake,
    read_message, server_config, server_handshake,
};

const TOKEN: &str = "0123456789abcdef0123456789abcdef";
const MASTER_NAME: &str = "test-master";
/// Short, so the silent client's test does not wait 10 s.
const TEST_HANDSHAKE_TIMEOUT: Duration = Duration::from_millis(400);
/// Short, so the stalled message's test does not wait 10 s.
const TEST_MESSAGE_STALL: Duration = Duration::from_millis(400);
/// Upper bound for anything a test waits on.
const PATIENCE: Duration = Duration::from_secs(10);

/// What the master's accept loop saw for one incoming connection.
#[derive(Debug)]
enum Outcome {
    /// The QUIC/TLS handshake failed.
    Tls,
    Handshake(Result<Hello, Refusal>),
}

struct Server {
    addr: SocketAddr,
    fingerprint: String,
    outcomes: mpsc::UnboundedReceiver<Outcome>,
    /// Kept so the endpoint lives as long as the test.
    _endpoint: quinn::Endpoint,
}

impl Server {
    fn start() -> Server {
        let identity =
            MasterIdentity::generate(&["127.0.0.1".to_owned()]).expect("identity generates");
        let config = server_config(&identity).expect("server config builds");
        let endpoint = quinn::Endpoint::server(config, "127.0.0.1:0".parse().expect("an address"))
            .expect("binds to a free port");
        let addr = endpoint.local_addr().expect("bound address");
        let (tx, outcomes) = mpsc::unbounded_channel();
        let policy = HandshakePolicy {
            timeout: TEST_HANDSHAKE_TIMEOUT,
            message_stall: TEST_MESSAGE_STALL,
            ..HandshakePolicy::new(TOKEN, MASTER_NAME)
        };
        let accepting = endpoint.clone();
        tokio::spawn(async move {
            while let Some(incoming) = accepting.accept().await {
                let (tx, policy) = (tx.clone(), policy.clone());
                tokio::spawn(async move {
                    let Ok(conn) = incoming.await else {
                        let _ = tx.send(Outcome::Tls);
                        return;
                    };
                    let result = server_handshake(&conn, &policy).await;
                    let accepted = result.is_ok();
                    let _ = tx.send(Outcome::Handshake(result));
                    if accepted {
                        // The session stream, served as the master serves it.
                        let _link = match conn.accept_bi().await {
                            Ok((send, recv)) => Some(Link::over_connection(
                                conn.clone(),
                                recv,
                                send,
                                ReadBounds {
                                    limit: SESSION_LIMIT,
                                    stall: policy.message_stall,
                                },
                                "test client".to_owned(),
                            )),
                            Err(_) => None,
                        };
                        // Dropping the last handle would close the connection.
                        conn.closed().await;
                    }
                });
            }
        });
        Server {
            addr,
            fingerprint: identity.fingerprint(),
            outcomes,
            _endpoint: endpoint,
        }
    }

    async fn next_outcome(&mut self) -> Outcome {
        tokio::time::timeout(PATIENCE, self.outcomes.recv())
            .await
            .expect("the server reports every connection in time")
            .expect("the accept loop is still running")
    }

    /// Connects with `fingerprint` pinned.
    async fn connect(
        &self,
        fingerprint: &str,
    ) -> (
        quinn::Endpoint,
        Result<quinn::Connection, quinn::ConnectionError>,
    ) {
        let mut endpoint = quinn::Endpoint::client("127.0.0.1:0".parse().expect("an address"))
            .expect("client binds");
        endpoint.set_default_client_config(client_config(fingerprint).expect("client config"));
        let connecting = endpoint
            .connect(self.addr, SERVER_NAME)
            .expect("connect starts");
        let conn = tokio::time::timeout(PATIENCE, connecting)
            .await
            .expect("TLS finishes in time");
        (endpoint, conn)
    }

    /// A good client connects, is welcomed, and the server reports its Hello.
    async fn check_good_client(&mut self) {
        let (_endpoint, conn) = self.connect(&self.fingerprint.clone()).await;
        let conn = conn.expect("the right fingerprint connects");
        let hello = Hello::new(
            TOKEN,
            Role::Worker {
                threads: 4,
                name: "w1".to_owned(),
            },
        );
        let welcome = client_handshake(&conn, &hello).await.expect("welcomed");
        assert_eq!(welcome.version, PROTOCOL_VERSION);
        assert_eq!(welcome.master_name, MASTER_NAME);
        match self.next_outcome().await {
            Outcome::Handshake(Ok(seen)) => assert_eq!(seen, hello),
            other => panic!("expected an accepted Hello, got {other:?}"),
        }
        conn.close(vtfarm_transport::CLOSE_NORMAL, b"done");
    }

    /// Expects the server to have refused the last connection with `code`.
    async fn check_server_refused(&mut self, code: RefuseCode) {
        match self.next_outcome().await {
            Outcome::Handshake(Err(refusal)) => assert_eq!(refusal.code, code, "{refusal}"),
            other => panic!("expected a {code:?} refusal, got {other:?}"),
        }
    }
}

/// Asserts that the master closed `conn` with `code`'s application close code.
/// Waits for the master to close with `code`; returns the close reason.
async fn check_closed_with(conn: &quinn::Connection, code: RefuseCode) -> String {
    let closed = tokio::time::timeout(PATIENCE, conn.closed())
        .await
        .expect("the master closes the connection");
    match closed {
        quinn::ConnectionError::ApplicationClosed(close) => {
            assert_eq!(close.error_code, code.close_code().into(), "{close:?}");
            String::from_utf8_lossy(&close.reason).into_owned()
        }
        other => panic!("expected an application close with {code:?}, got {other:?}"),
    }
}

/// The ways a client can get it wrong.
#[derive(Clone, Copy, Debug)]
enum BadClient {
    WrongFingerprint,
    WrongToken,
    WrongVersion,
    /// A small frame whose body is garbage.
    Garbage,
    /// A length prefix above the handshake limit.
    Oversized,
    BadMagic,
    /// A well-formed message that is not a Hello.
    NotHello,
    /// A Hello of a later version with fields this version does not know.
    FutureHello,
    /// The stream ends inside the first message.
    Truncated,
    /// Connects and never opens a stream.
    Silent,
}

const ALL_BAD_CLIENTS: [BadClient; 10] = [
    BadClient::WrongFingerprint,
    BadClient::WrongToken,
    BadClient::WrongVersion,
    BadClient::Garbage,
    BadClient::Oversized,
    BadClient::BadMagic,
    BadClient::NotHello,
    BadClient::FutureHello,
    BadClient::Truncated,
    BadClient::Silent,
];

fn frame(body: &[u8]) -> Vec<u8> {
    let mut f = (body.len() as u32).to_le_bytes().to_vec();
    f.extend_from_slice(body);
    f
}

fn hello_frame(hello: Hello) -> Vec<u8> {
    encode_message(&Message::Hello(hello)).expect("a Hello encodes")
}

impl BadClient {
    /// Runs the bad client against `server` and checks both ends' view.
    async fn check(self, server: &mut Server) {
        let fingerprint = match self {
            // Another master's certificate.
            BadClient::WrongFingerprint => MasterIdentity::generate(&[])
                .expect("identity generates")
                .fingerprint(),
            _ => server.fingerprint.clone(),
        };
        let (_endpoint, conn) = server.connect(&fingerprint).await;
        let conn = match (self, conn) {
            (BadClient::WrongFingerprint, Err(e)) => {
                assert!(
                    matches!(e, quinn::ConnectionError::TransportError(_)),
                    "{e:?}"
                );
                assert!(matches!(server.next_outcome().await, Outcome::Tls));
                return;
            }
            (BadClient::WrongFingerprint, Ok(_)) => panic!("a wrong fingerprint connected"),
            (_, conn) => conn.expect("the right fingerprint connects"),
        };
        let code = match self {
            BadClient::WrongToken | BadClient::WrongVersion => {
                let mut hello = Hello::new(TOKEN, Role::Submitter);
                if matches!(self, BadClient::WrongToken) {
                    hello.token = "0123456789abcdef0123456789abcdeX".to_owned();
                } else {
                    hello.version = PROTOCOL_VERSION + 1;
                }
                let refused = client_handshake(&conn, &hello).await.expect_err("refused");
                let ProtoError::Refused { code, message } = refused else {
                    panic!("expected a refusal, got {refused:?}");
                };
                assert!(!message.contains(TOKEN), "{message}");
                code
            }
            BadClient::Silent => RefuseCode::Timeout,
            _ => raw_first_message(&conn, self).await,
        };
        let expected = match self {
            BadClient::WrongToken => RefuseCode::BadToken,
            BadClient::WrongVersion | BadClient::FutureHello => RefuseCode::BadVersion,
            BadClient::Oversized => RefuseCode::TooLarge,
            BadClient::Silent => RefuseCode::Timeout,
            _ => RefuseCode::BadMessage,
        };
        assert_eq!(code, expected, "{self:?}");
        check_closed_with(&conn, expected).await;
        server.check_server_refused(expected).await;
    }
}

/// Sends raw bytes as the first message and returns the refusal code, from
/// the `Refused` message or, if it was lost, from the close code.
async fn raw_first_message(conn: &quinn::Connection, client: BadClient) -> RefuseCode {
    let mut valid = hello_frame(Hello::new(TOKEN, Role::Submitter));
    let bytes = match client {
        BadClient::Garbage => frame(&[0xff; 5]),
        BadClient::Oversized => (MAX_HANDSHAKE_BYTES + 1).to_le_bytes().to_vec(),
        BadClient::BadMagic => hello_frame(Hello {
            magic: *b"NOTVTFRM",
            ..Hello::new(TOKEN, Role::Submitter)
        }),
        BadClient::NotHello => encode_message(&Message::Heartbeat).expect("encodes"),
        BadClient::FutureHello => {
            let future = Hello {
                version: PROTOCOL_VERSION + 7,
                ..Hello::new(TOKEN, Role::Submitter)
            };
            let mut body = hello_frame(future)[4..].to_vec();
            body.extend_from_slice(b"fields of a later version");
            frame(&body)
        }
        BadClient::Truncated => {
            valid.truncate(valid.len() - 3);
            valid
        }
        other => unreachable!("{other:?} does not send raw bytes"),
    };
    let (mut send, mut recv) = conn.open_bi().await.expect("a stream opens");
    send.write_all(&bytes).await.expect("the bytes are sent");
    let _ = send.finish();
    match read_message(&mut recv, ReadBounds::HANDSHAKE).await {
        Ok(Message::Refused(refusal)) => refusal.code,
        Ok(other) => panic!("expected Refused, got {other:?}"),
        Err(e) => match conn.close_reason() {
            Some(quinn::ConnectionError::ApplicationClosed(close)) => {
                RefuseCode::from_close_code(close.error_code.into_inner())
                    .expect("a refusal close code")
            }
            other => panic!("no refusal: {e}, close reason {other:?}"),
        },
    }
}

/// Starts a server, runs `bad` against it, then a good client.
async fn check_bad_then_good(bad: BadClient) {
    let mut server = Server::start();
    bad.check(&mut server).await;
    server.check_good_client().await;
}

#[tokio::test]
async fn the_right_fingerprint_and_token_complete_the_handshake() {
    let mut server = Server::start();
    server.check_good_client().await;
    server.check_good_client().await;
}

#[tokio::test]
async fn a_wrong_fingerprint_fails_tls() {
    check_bad_then_good(BadClient::WrongFingerprint).await;
}

#[tokio::test]
async fn a_wrong_token_is_refused_and_closed_with_its_code() {
    check_bad_then_good(BadClient::WrongToken).await;
}

#[tokio::test]
async fn a_wrong_version_is_refused() {
    check_bad_then_good(BadClient::WrongVersion).await;
}

#[tokio::test]
async fn a_later_versions_hello_is_refused_as_bad_version() {
    check_bad_then_good(BadClient::FutureHello).await;
}

#[tokio::test]
async fn garbage_is_a_bad_message() {
    check_bad_then_good(BadClient::Garbage).await;
}

#[tokio::test]
async fn an_oversized_length_prefix_is_too_large() {
    check_bad_then_good(BadClient::Oversized).await;
}

#[tokio::test]
async fn bad_magic_another_message_or_a_cut_stream_are_bad_messages() {
    check_bad_then_good(BadClient::BadMagic).await;
    check_bad_then_good(BadClient::NotHello).await;
    check_bad_then_good(BadClient::Truncated).await;
}

#[tokio::test]
async fn a_silent_client_times_out() {
    check_bad_then_good(BadClient::Silent).await;
}

#[tokio::test]
async fn one_endpoint_survives_every_bad_client_in_turn() {
    let mut server = Server::start();
    for bad in ALL_BAD_CLIENTS {
        bad.check(&mut server).await;
        server.check_good_client().await;
    }
}

/// A pinned fingerprint that does not match is a configuration error:
/// retrying cannot help, so a worker stops instead of retrying forever.
#[tokio::test]
async fn a_wrong_fingerprint_is_not_worth_retrying() {
    let server = Server::start();
    let options = vtfarm_transport::client::ClientOptions {
        master: server.addr.to_string(),
        token: TOKEN.to_owned(),
        fingerprint: "ab".repeat(32),
    };
    let error = tokio::time::timeout(
        PATIENCE,
        vtfarm_transport::client::connect(&options, Role::Submitter),
    )
    .await
    .expect("TLS finishes in time")
    .err()
    .expect("the certificate does not match");
    assert!(!error.is_transient(), "{error}");
    assert!(error.to_string().contains("fingerprint"), "{error}");
}

/// After a valid handshake, an oversized length prefix or garbage on the
/// session stream closes the connection with its code and the cause as the
/// reason (they closed with code 0 and no reason).
#[tokio::test]
async fn bad_session_input_closes_with_its_code_and_reason() {
    let cases = [
        (
            vec![0xFF; 4],
            RefuseCode::TooLarge,
            "4294967295 bytes exceeds",
        ),
        (
            frame(b"\xff\xfe\xfd garbage"),
            RefuseCode::BadMessage,
            "cannot decode",
        ),
    ];
    for (bytes, code, reason) in cases {
        let server = Server::start();
        let (_endpoint, conn) = server.connect(&server.fingerprint).await;
        let conn = conn.expect("TLS with the right fingerprint");
        client_handshake(&conn, &Hello::new(TOKEN, Role::Submitter))
            .await
            .expect("welcomed");
        let (mut send, _recv) = conn.open_bi().await.expect("session stream");
        send.write_all(&bytes).await.expect("written");
        let text = check_closed_with(&conn, code).await;
        assert!(text.contains(reason), "{text:?}");
    }
}

/// An accepted peer that announces the largest message, sends a little of
/// it and goes silent (its connection kept alive by QUIC) is closed with
/// the timeout code once the message has stalled for the bound.
#[tokio::test]
async fn a_message_that_stalls_on_the_session_is_closed() {
    let server = Server::start();
    let (_endpoint, conn) = server.connect(&server.fingerprint).await;
    let conn = conn.expect("TLS with the right fingerprint");
    client_handshake(&conn, &Hello::new(TOKEN, Role::Submitter))
        .await
        .expect("welcomed");
    let (mut send, _recv) = conn.open_bi().await.expect("session stream");
    let mut begun = SESSION_LIMIT.to_le_bytes().to_vec();
    begun.extend_from_slice(&[0; 1000]);
    send.write_all(&begun).await.expect("written");
    let text = check_closed_with(&conn, RefuseCode::Timeout).await;
    assert!(text.contains("stalled: 1004 of"), "{text:?}");
}

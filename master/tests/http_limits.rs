//! The HTTP server under abuse, over real sockets on 127.0.0.1: a foreign
//! `Host` is refused (DNS rebinding), a forwarded loopback request needs
//! the token (compared exactly), idle connections are closed by the header
//! timeout while an authorised request still gets through, a trickled head
//! or body is closed at its deadline, slow bodies flooding from one
//! address leave room for others (127.0.0.2) and for the address itself
//! once they time out, event streams beyond the cap get 503, and a
//! thousand clients that never read leave the master's memory within a
//! stated bound. Every wait is bounded and ends on a socket event (a
//! response, an end of stream).

use std::net::SocketAddr;
use std::time::Duration;

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;
use vtfarm_master::FarmRules;
use vtfarm_master::http::{self, HttpAccess, HttpLimits};
use vtfarm_master::{MasterHandle, Peer, spawn_master};
use vtfarm_proto::Message;
use vtfarm_transport::Link;

/// Every wait on a socket is bounded by this.
const WAIT: Duration = Duration::from_secs(60);

/// Limits small enough to reach in a test.
const LIMITS: HttpLimits = HttpLimits {
    header_read_timeout: Duration::from_secs(1),
    body_read_timeout: Duration::from_secs(1),
    min_body_rate: 1024,
    max_body_bytes: 64 * 1024,
    max_connections: 64,
    max_connections_per_address: 64,
    reserved_connections: 0,
    max_event_streams: 8,
    write_buffer_bytes: 16 * 1024,
};

/// Raises this process's open-file limit to its hard limit: the tests
/// hold thousands of sockets, both ends in this process.
fn raise_fd_limit(needed: u64) {
    let mut limit = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: plain libc calls on a valid struct.
    unsafe {
        assert_eq!(libc::getrlimit(libc::RLIMIT_NOFILE, &mut limit), 0);
        limit.rlim_cur = limit.rlim_max;
        assert_eq!(libc::setrlimit(libc::RLIMIT_NOFILE, &limit), 0);
    }
    assert!(
        limit.rlim_cur >= needed,
        "the hard open-file limit {} is below the {needed} this test needs",
        limit.rlim_cur
    );
}

async fn start(access: HttpAccess, limits: HttpLimits) -> (MasterHandle, SocketAddr) {
    let (master, _task) = spawn_master(FarmRules::default());
    let listener = http::bind("127.0.0.1:0".parse().unwrap()).await.unwrap();
    let address = listener.local_addr().unwrap();
    tokio::spawn(http::serve(listener, master.clone(), access, limits));
    (master, address)
}

/// Sends `request` and reads the response to its end; returns the status
/// code and the text.
async fn exchange(address: SocketAddr, request: &str) -> (u16, String) {
    let mut stream = TcpStream::connect(address).await.unwrap();
    stream.write_all(request.as_bytes()).await.unwrap();
    let mut response = Vec::new();
    tokio::time::timeout(WAIT, stream.read_to_end(&mut response))
        .await
        .expect("the server answered and closed")
        .unwrap();
    let text = String::from_utf8_lossy(&response).into_owned();
    let code = (text.split(' ').nth(1)).and_then(|c| c.parse().ok());
    (
        code.unwrap_or_else(|| panic!("no status line: {text:?}")),
        text,
    )
}

fn get(path: &str, host: &str, extra: &str) -> String {
    format!("GET {path} HTTP/1.1\r\nHost: {host}\r\n{extra}Connection: close\r\n\r\n")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_foreign_host_is_refused_and_a_forwarded_loopback_request_needs_the_token() {
    let access = HttpAccess {
        allowed_hosts: vec!["dash.example".into()],
        ..HttpAccess::new("c0ffee")
    };
    let (_master, address) = start(access, LIMITS).await;
    let port = address.port();
    // DNS rebinding: the page's own name, now resolving to 127.0.0.1.
    let view = "{\"job\": 1, \"offset\": [0, 0, 0]}";
    let post = format!(
        "POST /api/view HTTP/1.1\r\nHost: rebind.evil.example:{port}\r\ncontent-type: application/json\r\ncontent-length: {}\r\nConnection: close\r\n\r\n{view}",
        view.len()
    );
    let (code, text) = exchange(address, &post).await;
    assert_eq!(code, 403, "{text}");
    assert!(text.contains("--http-allowed-host"), "{text}");
    let (code, _) = exchange(address, &get("/api/status", "evil.example", "")).await;
    assert_eq!(code, 403);
    for host in [
        format!("127.0.0.1:{port}"),
        format!("localhost:{port}"),
        "LOCALHOST".to_owned(),
        format!("[::1]:{port}"),
        "dash.example".to_owned(),
        format!("Dash.Example:{port}"),
    ] {
        let (code, text) = exchange(address, &get("/api/status", &host, "")).await;
        assert_eq!(code, 200, "Host: {host}: {text}");
    }
    // Through a proxy on this host: loopback, but not the peer's own request.
    let host = format!("127.0.0.1:{port}");
    for forwarded in [
        "X-Forwarded-For: 198.51.100.4\r\n",
        "Forwarded: for=198.51.100.4\r\n",
    ] {
        let (code, _) = exchange(address, &get("/api/status", &host, forwarded)).await;
        assert_eq!(code, 401, "{forwarded}");
        let with_token = format!("{forwarded}Authorization: Bearer c0ffee\r\n");
        let (code, _) = exchange(address, &get("/api/status", &host, &with_token)).await;
        assert_eq!(code, 200, "{forwarded} with the token");
    }

    let always = HttpAccess {
        require_token: true,
        ..HttpAccess::new("c0ffee")
    };
    let (_master, address) = start(always, LIMITS).await;
    let host = format!("127.0.0.1:{}", address.port());
    assert_eq!(
        exchange(address, &get("/api/status", &host, "")).await.0,
        401
    );
    let bearer = "Authorization: Bearer c0ffee\r\n";
    assert_eq!(
        exchange(address, &get("/api/status", &host, bearer))
            .await
            .0,
        200
    );
    // Tokens are compared exactly: nothing around them is ignored. (A
    // header's own surrounding whitespace is not part of its value in
    // HTTP: the parser drops it before anyone sees it.)
    for near in ["c0ffee%20", "c0ffee x", " c0ffee", "c0ffe", "C0FFEE"] {
        let bearer = format!("Authorization: Bearer {near}\r\n");
        let (code, _) = exchange(address, &get("/api/status", &host, &bearer)).await;
        assert_eq!(code, 401, "{bearer:?}");
    }
    for near in ["c0ffee%20", "c0ffee%09", "%20c0ffee", "c0ffee%0A", "c0ffe"] {
        let form = format!("token={near}");
        let login = format!(
            "POST /login HTTP/1.1\r\nHost: {host}\r\nContent-Type: application/x-www-form-urlencoded\r\n\
             Content-Length: {}\r\nConnection: close\r\n\r\n{form}",
            form.len()
        );
        let (code, text) = exchange(address, &login).await;
        assert_eq!(code, 401, "{form}: {text}");
    }
}

/// 2,000 connections that send nothing: those over the cap are answered
/// 503 or closed at once, the rest closed by the header timeout; then an
/// authorised request is served.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn idle_connections_are_closed_by_the_timeout_and_a_real_request_still_succeeds() {
    const IDLE: usize = 2000;
    raise_fd_limit(2 * IDLE as u64 + 256);
    let (_master, address) = start(HttpAccess::new("c0ffee"), LIMITS).await;
    let mut idle = Vec::with_capacity(IDLE);
    for _ in 0..IDLE {
        idle.push(TcpStream::connect(address).await.unwrap());
    }
    let mut answered_503 = 0;
    for mut stream in idle {
        let mut response = Vec::new();
        let read = tokio::time::timeout(WAIT, stream.read_to_end(&mut response))
            .await
            .expect("the server closed the idle connection");
        // A reset (closed unanswered with nothing read) is a close too.
        if read.is_ok() && response.starts_with(b"HTTP/1.1 503") {
            answered_503 += 1;
        }
    }
    assert!(answered_503 > 0, "connections over the cap are told 503");
    let host = format!("127.0.0.1:{}", address.port());
    let (code, text) = exchange(address, &get("/api/status", &host, "")).await;
    assert_eq!(code, 200, "{text}");
}

/// Opens an event stream and returns the connection with the response
/// head read (up to the first event's start, or a whole refusal).
async fn open_events(address: SocketAddr) -> (TcpStream, u16) {
    let mut stream = TcpStream::connect(address).await.unwrap();
    let host = format!("127.0.0.1:{}", address.port());
    let request = format!("GET /api/events HTTP/1.1\r\nHost: {host}\r\n\r\n");
    stream.write_all(request.as_bytes()).await.unwrap();
    let mut head = Vec::new();
    let mut byte = [0u8; 1];
    while !head.ends_with(b"\r\n\r\n") {
        let n = tokio::time::timeout(WAIT, stream.read(&mut byte))
            .await
            .expect("a response head")
            .unwrap();
        assert_eq!(n, 1, "the connection closed before the head: {head:?}");
        head.push(byte[0]);
    }
    let text = String::from_utf8_lossy(&head);
    let code = text.split(' ').nth(1).and_then(|c| c.parse().ok()).unwrap();
    (stream, code)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn event_streams_beyond_the_cap_get_503() {
    let (_master, address) = start(HttpAccess::new("c0ffee"), LIMITS).await;
    let mut streams = Vec::new();
    for _ in 0..LIMITS.max_event_streams {
        let (stream, code) = open_events(address).await;
        assert_eq!(code, 200);
        streams.push(stream);
    }
    let (_, code) = open_events(address).await;
    assert_eq!(code, 503, "one stream too many");
}

fn resident_bytes() -> u64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap();
    let line = status.lines().find(|l| l.starts_with("VmRSS:")).unwrap();
    let kib: u64 = line.split_whitespace().nth(1).unwrap().parse().unwrap();
    kib * 1024
}

/// The bound on what a thousand clients that never read may add to the
/// master's resident memory (the farm's own figure was 1.05 GB).
const SLOW_READERS_RSS_BOUND: u64 = 64 << 20;

/// A thousand dashboards that never read their event stream while the
/// master's state moves thousands of times: the master's memory stays
/// within [`SLOW_READERS_RSS_BOUND`] (the streams are capped, each holds
/// one coalesced view and a bounded buffer) and it keeps answering.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_thousand_slow_readers_leave_the_memory_bounded() {
    const READERS: usize = 1000;
    raise_fd_limit(2 * READERS as u64 + 256);
    let limits = HttpLimits {
        header_read_timeout: Duration::from_secs(30),
        ..HttpLimits::default()
    };
    let (master, address) = start(HttpAccess::new("c0ffee"), limits).await;
    // A submitter whose status requests move the master's state.
    let (master_end, mut submitter) = Link::pair();
    let peer = Peer::Submitter {
        address: "test".into(),
    };
    master.attach(peer, master_end, None);
    let before = resident_bytes();
    let host = format!("127.0.0.1:{}", address.port());
    let request = format!("GET /api/events HTTP/1.1\r\nHost: {host}\r\n\r\n");
    let mut readers = Vec::with_capacity(READERS);
    for _ in 0..READERS {
        let mut stream = TcpStream::connect(address).await.unwrap();
        // Some are refused at once (the caps); the rest never read.
        let _ = stream.write_all(request.as_bytes()).await;
        readers.push(stream);
    }
    for _ in 0..5000 {
        submitter.tx.send(Message::StatusRequest).unwrap();
        let reply = tokio::time::timeout(WAIT, submitter.rx.recv()).await;
        assert!(matches!(reply, Ok(Some(Message::StatusReply(_)))));
    }
    let during = resident_bytes();
    let grown = during.saturating_sub(before);
    println!(
        "resident memory {} MiB before, {} MiB with {READERS} slow readers (+{} MiB)",
        before >> 20,
        during >> 20,
        grown >> 20
    );
    assert!(
        grown < SLOW_READERS_RSS_BOUND,
        "{READERS} slow readers grew the master by {} MiB",
        grown >> 20
    );
    // The core still answers at once.
    let reply = tokio::time::timeout(WAIT, master.inspect(|c| c.status())).await;
    assert!(reply.expect("bounded").is_some());
    drop(readers);
}

/// A connection to `address` from the loopback address `from` (127.0.0.2
/// and so on: another client on the same host).
async fn connect_from(from: [u8; 4], address: SocketAddr) -> TcpStream {
    let socket = tokio::net::TcpSocket::new_v4().unwrap();
    socket
        .bind(SocketAddr::from((from, 0)))
        .expect("any 127.0.0.0/8 address binds on loopback");
    socket.connect(address).await.unwrap()
}

/// Sends `request` from `from` and reads the response to its end.
async fn exchange_from(from: [u8; 4], address: SocketAddr, request: &str) -> (u16, String) {
    let mut stream = connect_from(from, address).await;
    stream.write_all(request.as_bytes()).await.unwrap();
    let mut response = Vec::new();
    tokio::time::timeout(WAIT, stream.read_to_end(&mut response))
        .await
        .expect("the server answered and closed")
        .unwrap();
    let text = String::from_utf8_lossy(&response).into_owned();
    let code = (text.split(' ').nth(1)).and_then(|c| c.parse().ok());
    (code.unwrap_or(0), text)
}

/// What became of a slow client: the response the server sent before it
/// closed the connection (empty when it closed it unanswered).
async fn trickle(mut stream: TcpStream, head: String) -> Vec<u8> {
    let _ = stream.write_all(head.as_bytes()).await;
    let (mut read, mut write) = stream.into_split();
    let dribble = async {
        // One byte at a time, until the server stops taking them.
        loop {
            tokio::time::sleep(Duration::from_millis(200)).await;
            if write.write_all(b"x").await.is_err() {
                std::future::pending::<()>().await;
            }
        }
    };
    let mut response = Vec::new();
    tokio::select! {
        _ = read.read_to_end(&mut response) => {}
        () = dribble => {}
    }
    response
}

/// 260 clients on one address that send a request head for a body and
/// then trickle it a byte at a time: the address gets no more than its cap
/// (the rest are told 503), a dashboard on another address is served at
/// once, each trickler is answered 408 and closed at the body's deadline,
/// and a client on the flooding address itself, retrying on 503, is
/// served once they are.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn slow_bodies_from_one_address_hold_neither_the_server_nor_other_clients() {
    const SLOW: usize = 260;
    raise_fd_limit(2 * SLOW as u64 + 256);
    let limits = HttpLimits {
        header_read_timeout: Duration::from_secs(2),
        body_read_timeout: Duration::from_secs(3),
        max_connections: 256,
        max_connections_per_address: 128,
        reserved_connections: 32,
        ..HttpLimits::default()
    };
    let (_master, address) = start(HttpAccess::new("c0ffee"), limits).await;
    let host = format!("127.0.0.1:{}", address.port());
    let head = format!(
        "POST /login HTTP/1.1\r\nHost: {host}\r\nContent-Type: application/x-www-form-urlencoded\r\n\
         Content-Length: 60000\r\n\r\ntoken="
    );
    let (turned_away, turned_away_seen) = tokio::sync::mpsc::unbounded_channel();
    let mut slow = Vec::with_capacity(SLOW);
    for _ in 0..SLOW {
        let stream = connect_from([127, 0, 0, 1], address).await;
        let (head, turned_away) = (head.clone(), turned_away.clone());
        slow.push(tokio::spawn(async move {
            let response = trickle(stream, head).await;
            if response.starts_with(b"HTTP/1.1 503") {
                let _ = turned_away.send(());
            }
            response
        }));
    }
    let mut turned_away_seen = turned_away_seen;
    // The address's cap is reached once one of them is turned away.
    tokio::time::timeout(WAIT, turned_away_seen.recv())
        .await
        .expect("a client beyond the address's cap is told 503");
    let status = get("/api/status", &host, "");
    let (code, text) = exchange_from([127, 0, 0, 2], address, &status).await;
    assert_eq!(code, 200, "another address is served at once: {text}");

    // The flooding address itself, retrying on 503 as a browser's user would.
    let served = async {
        loop {
            let (code, text) = exchange_from([127, 0, 0, 1], address, &status).await;
            match code {
                200 => return,
                503 | 0 => tokio::time::sleep(Duration::from_millis(100)).await,
                _ => panic!("{text}"),
            }
        }
    };
    tokio::time::timeout(WAIT, served)
        .await
        .expect("the flooding address is served once its slow bodies time out");
    for client in slow {
        // Answered 408 (or reset: it closed with the trickled bytes unread).
        tokio::time::timeout(WAIT, client)
            .await
            .expect("every slow client is closed")
            .unwrap();
    }
}

/// A body that stops coming is answered 408 at its deadline and the
/// connection closed.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_body_that_stops_coming_is_answered_408() {
    let (_master, address) = start(HttpAccess::new("c0ffee"), LIMITS).await;
    let host = format!("127.0.0.1:{}", address.port());
    let part = format!(
        "POST /api/jobs/1/cancel HTTP/1.1\r\nHost: {host}\r\nContent-Type: application/json\r\n\
         Content-Length: 100\r\n\r\n{{\"failed\""
    );
    let (code, text) = exchange(address, &part).await;
    assert_eq!(code, 408, "{text}");
}

/// A request head trickled a byte at a time is closed at the header
/// deadline, not kept while bytes keep coming.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_trickled_request_head_is_closed_at_the_header_deadline() {
    let (_master, address) = start(HttpAccess::new("c0ffee"), LIMITS).await;
    let host = format!("127.0.0.1:{}", address.port());
    let endless_head = format!("GET /api/status HTTP/1.1\r\nHost: {host}\r\n");
    let client = trickle(TcpStream::connect(address).await.unwrap(), endless_head);
    tokio::time::timeout(WAIT, client)
        .await
        .expect("the server closed the trickling client");
}

/// A body announced over the limit is refused before it is read.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_body_over_the_limit_is_refused_at_its_head() {
    let (_master, address) = start(HttpAccess::new("c0ffee"), LIMITS).await;
    let host = format!("127.0.0.1:{}", address.port());
    let head = format!(
        "POST /login HTTP/1.1\r\nHost: {host}\r\nContent-Type: application/x-www-form-urlencoded\r\n\
         Content-Length: 1000000\r\n\r\n"
    );
    let (code, text) = exchange(address, &head).await;
    assert_eq!(code, 413, "{text}");
}

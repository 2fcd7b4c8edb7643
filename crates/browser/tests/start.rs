//! How a browser that does not start ends: stand-in `chromium` scripts
//! that fail in each way a real one can, each a typed error, and the
//! process killed once the caller's timeout is spent.

use std::path::PathBuf;
use std::sync::LazyLock;
use std::time::Duration;

use vtfarm_browser::{Browser, Error, Graphics, Options};

/// The stand-ins, written before any test starts a process (each test
/// asks for them first), so no child of another test holds one open for
/// writing while it is run.
static SCRIPTS: LazyLock<PathBuf> = LazyLock::new(|| {
    use std::os::unix::fs::PermissionsExt;
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("vtfarm-browser-stand-ins");
    std::fs::create_dir_all(&dir).unwrap();
    let scripts = [
        ("ends", "echo 'cannot open display' >&2\nexit 1"),
        // Says its pid beside itself, then waits in silence.
        ("silent", "echo $$ > \"$0.pid\"\nexec sleep 60"),
        // Starts a helper (as Chromium starts its renderer), says the
        // helper's pid, then waits in silence.
        (
            "family",
            "sleep 60 &\necho $! > \"$0.helper\"\nexec sleep 60",
        ),
        (
            "closed",
            "echo 'DevTools listening on ws://127.0.0.1:1/devtools/browser/x' >&2\nexec sleep 60",
        ),
    ];
    for (name, body) in scripts {
        let path = dir.join(name);
        std::fs::write(&path, format!("#!/bin/sh\n{body}\n")).unwrap();
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755)).unwrap();
    }
    dir
});

fn options(timeout: Duration) -> Options {
    Options {
        graphics: Graphics::SwiftShader,
        window: [320, 200],
        timeout,
        end_with_this_thread: false,
    }
}

async fn start(script: &str, timeout: Duration) -> Error {
    let path = SCRIPTS.join(script);
    match Browser::start(&path, &options(timeout)).await {
        Ok(_) => panic!("{script} started"),
        Err(e) => e,
    }
}

#[tokio::test]
async fn a_missing_binary_is_an_error_naming_it() {
    LazyLock::force(&SCRIPTS);
    let missing = SCRIPTS.join("no-such-chromium");
    let error = Browser::start(&missing, &options(Duration::from_secs(5))).await;
    let Err(Error::Spawn { path, .. }) = error else {
        panic!("{:?}", error.err());
    };
    assert_eq!(path, missing);
}

#[tokio::test]
async fn a_browser_that_ends_without_an_endpoint_is_an_error_with_what_it_said() {
    let error = start("ends", Duration::from_secs(30)).await;
    let Error::NoEndpoint { stderr } = &error else {
        panic!("{error:?}");
    };
    assert_eq!(stderr, "cannot open display");
}

#[tokio::test]
async fn a_browser_that_never_says_its_endpoint_is_killed_after_the_timeout() {
    let pid_file = SCRIPTS.join("silent.pid");
    let _ = std::fs::remove_file(&pid_file);
    // Long enough for the stand-in to say its pid on a busy machine.
    let timeout = Duration::from_secs(5);
    let error = start("silent", timeout).await;
    let Error::Timeout { what, after } = &error else {
        panic!("{error:?}");
    };
    assert_eq!(what, "Chromium's DevTools endpoint");
    assert_eq!(*after, timeout);
    let pid: libc::pid_t = std::fs::read_to_string(&pid_file)
        .expect("the stand-in ran")
        .trim()
        .parse()
        .unwrap();
    // Killed and reaped: no such process.
    // SAFETY: signal 0 only checks whether the process exists.
    assert_eq!(unsafe { libc::kill(pid, 0) }, -1);
}

/// Whether process `pid` ends within `bound`: waits on its pidfd, which
/// becomes readable when it exits (true too when it is gone already).
fn ends_within(pid: libc::pid_t, bound: Duration) -> bool {
    // SAFETY: pidfd_open takes a pid and flags and returns a new fd or -1.
    let fd = unsafe { libc::syscall(libc::SYS_pidfd_open, pid, 0) };
    if fd < 0 {
        return std::io::Error::last_os_error().raw_os_error() == Some(libc::ESRCH);
    }
    let fd = fd as libc::c_int;
    let mut poll = libc::pollfd {
        fd,
        events: libc::POLLIN,
        revents: 0,
    };
    let millis = libc::c_int::try_from(bound.as_millis()).unwrap_or(libc::c_int::MAX);
    // SAFETY: one valid pollfd; the fd is ours and closed once.
    let ready = unsafe { libc::poll(&mut poll, 1, millis) };
    unsafe { libc::close(fd) };
    ready == 1
}

#[tokio::test]
async fn a_browser_ends_with_its_helper_processes() {
    let helper_file = SCRIPTS.join("family.helper");
    let _ = std::fs::remove_file(&helper_file);
    let error = start("family", Duration::from_secs(5)).await;
    assert!(matches!(error, Error::Timeout { .. }), "{error:?}");
    let helper: libc::pid_t = std::fs::read_to_string(&helper_file)
        .expect("the stand-in ran")
        .trim()
        .parse()
        .unwrap();
    assert!(
        ends_within(helper, Duration::from_secs(10)),
        "the helper {helper} outlived its browser"
    );
}

#[tokio::test]
async fn an_endpoint_that_refuses_the_connection_is_an_error_naming_it() {
    let error = start("closed", Duration::from_secs(30)).await;
    let Error::Connect { url, .. } = &error else {
        panic!("{error:?}");
    };
    assert_eq!(url, "ws://127.0.0.1:1/devtools/browser/x");
}

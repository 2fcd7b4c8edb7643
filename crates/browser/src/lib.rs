//! Headless Chromium driven over the DevTools protocol, with a fresh
//! profile: the dashboard's browser tests and `vtfarm bench view --browser`
//! drive the page through it.
//!
//! [`Browser::start`] runs Chromium (`--remote-debugging-port=0`), reads
//! the DevTools endpoint it prints on stderr and connects to the page
//! target of its first tab; [`Browser::call`], [`Browser::event`] and
//! [`Browser::eval`] speak the protocol on that page, and
//! [`Browser::send`] with [`Browser::reply`] send commands without waiting
//! for each reply (input at its own pace, as a user gives it). Every wait is bounded
//! by the caller's [`Options::timeout`], and Chromium is killed when the
//! [`Browser`] is dropped, whichever way its owner ends.

use std::collections::{HashMap, HashSet, VecDeque};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use futures_util::{SinkExt, StreamExt};
use serde_json::{Value, json};
use tokio::net::TcpStream;
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::{MaybeTlsStream, WebSocketStream};

/// What went wrong with Chromium or its DevTools connection.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("no `chromium` on PATH (apt-get install chromium)")]
    NotFound,
    #[error("creating Chromium's profile directory: {0}")]
    Profile(#[source] std::io::Error),
    #[error("starting {}: {source}", path.display())]
    Spawn {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("Chromium ended without a DevTools endpoint; its stderr ends:\n{stderr}")]
    NoEndpoint { stderr: String },
    #[error("{what}: nothing within {} s", after.as_secs_f64())]
    Timeout { what: String, after: Duration },
    #[error("the DevTools connection at {url}: {source}")]
    Connect {
        url: String,
        #[source]
        source: Box<tokio_tungstenite::tungstenite::Error>,
    },
    #[error("the DevTools connection: {0}")]
    Socket(#[source] Box<tokio_tungstenite::tungstenite::Error>),
    #[error("the DevTools connection closed")]
    Closed,
    #[error("DevTools sent a message that is not JSON: {0}")]
    NotJson(#[source] serde_json::Error),
    #[error("Chromium lists no page target")]
    NoPage,
    #[error("{method} failed: {error}")]
    Command { method: String, error: Value },
    #[error("the page threw: {0}")]
    Exception(Value),
}

/// How the page may draw.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Graphics {
    /// No GPU and no WebGL: pages fall back to what they draw without it.
    NoWebGl,
    /// WebGL2 on SwiftShader, the software rasterizer (the machine's GPU,
    /// if any, is not asked for).
    SwiftShader,
}

impl Graphics {
    fn flags(self) -> &'static [&'static str] {
        match self {
            Graphics::NoWebGl => &["--disable-gpu", "--disable-webgl"],
            Graphics::SwiftShader => &["--use-angle=swiftshader", "--enable-unsafe-swiftshader"],
        }
    }
}

/// How Chromium runs.
#[derive(Clone, Debug)]
pub struct Options {
    pub graphics: Graphics,
    /// The window's width and height in CSS pixels.
    pub window: [u32; 2],
    /// The bound of every wait: Chromium's start, each DevTools reply and
    /// each awaited event (an [`Browser::eval`] awaits its promise within it).
    pub timeout: Duration,
    /// Linux: the kernel kills Chromium when the thread that started it
    /// ends (the parent-death signal), so a process killed by a signal
    /// leaves no browser behind. Only for a thread that lives as long as
    /// the browser (a program's main thread), never a pool's.
    pub end_with_this_thread: bool,
}

/// The flags of every run: headless, quiet, no sandbox (containers), no
/// network but the pages asked for.
const FLAGS: &[&str] = &[
    "--headless",
    "--no-sandbox",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--remote-debugging-port=0",
];

/// The most DevTools events kept while waiting for something else (the
/// oldest go first), so a chatty page holds bounded memory.
const EVENTS_KEPT: usize = 4096;

/// The stderr lines kept to explain a Chromium that did not start.
const STDERR_KEPT: usize = 20;

/// `chromium` on `PATH`.
pub fn which_chromium() -> Result<PathBuf, Error> {
    let path = std::env::var_os("PATH").ok_or(Error::NotFound)?;
    std::env::split_paths(&path)
        .map(|dir| dir.join("chromium"))
        .find(|p| p.is_file())
        .ok_or(Error::NotFound)
}

/// Headless Chromium with a connection to its first tab.
pub struct Browser {
    page: Connection,
    // Dropped after the connection: Chromium ends, then its profile goes.
    _child: KillOnDrop,
    _profile: tempfile::TempDir,
}

impl Browser {
    /// Starts `chromium` with a fresh profile on `about:blank` and connects
    /// to that page.
    pub async fn start(chromium: &Path, options: &Options) -> Result<Browser, Error> {
        let profile = tempfile::Builder::new()
            .prefix("vtfarm-chromium-")
            .tempdir()
            .map_err(Error::Profile)?;
        let [width, height] = options.window;
        let mut command = Command::new(chromium);
        command
            .args(FLAGS)
            .arg(format!("--window-size={width},{height}"))
            .args(options.graphics.flags())
            .arg(format!("--user-data-dir={}", profile.path().display()))
            .arg("about:blank")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped());
        if options.end_with_this_thread {
            end_with_this_thread(&mut command, libc::SIGKILL);
        }
        // Its own process group, so that its helpers (renderer, GPU) end
        // with it at once, before its profile is removed.
        in_own_group(&mut command);
        let mut child = command.spawn().map_err(|source| Error::Spawn {
            path: chromium.to_owned(),
            source,
        })?;
        let stderr = child.stderr.take().expect("stderr is piped");
        let child = KillOnDrop(child);
        // Chromium says where its DevTools endpoint is on stderr; a thread
        // passes the lines on and keeps draining, so Chromium never blocks.
        let (lines_tx, mut lines) = tokio::sync::mpsc::unbounded_channel();
        std::thread::spawn(move || {
            use std::io::BufRead;
            for line in std::io::BufReader::new(stderr)
                .lines()
                .map_while(Result::ok)
            {
                let _ = lines_tx.send(line);
            }
        });
        let endpoint = async {
            let mut said = VecDeque::new();
            while let Some(line) = lines.recv().await {
                if let Some(url) = line.strip_prefix("DevTools listening on ") {
                    return Ok(url.to_owned());
                }
                if said.len() == STDERR_KEPT {
                    said.pop_front();
                }
                said.push_back(line);
            }
            let stderr = Vec::from(said).join("\n");
            Err(Error::NoEndpoint { stderr })
        };
        let timeout = options.timeout;
        let browser_url = within(timeout, "Chromium's DevTools endpoint", endpoint).await??;
        let page_url = page_target(&browser_url, timeout).await?;
        Ok(Browser {
            page: Connection::open(&page_url, timeout).await?,
            _child: child,
            _profile: profile,
        })
    }

    /// Sends a DevTools command to the page and returns its result.
    pub async fn call(&mut self, method: &str, params: Value) -> Result<Value, Error> {
        self.page.call(method, params).await
    }

    /// Sends a DevTools command to the page without waiting for its reply;
    /// [`Browser::reply`] waits for it.
    pub async fn send(&mut self, method: &str, params: Value) -> Result<Sent, Error> {
        self.page.send(method, params).await
    }

    /// The result of a command [`Browser::send`] sent.
    pub async fn reply(&mut self, sent: Sent) -> Result<Value, Error> {
        self.page.reply(sent).await
    }

    /// Waits for the DevTools event `method` (one that came while waiting
    /// for something else counts) and returns its parameters.
    pub async fn event(&mut self, method: &str) -> Result<Value, Error> {
        self.page.event(method).await
    }

    /// Evaluates a JavaScript expression on the page, awaiting it if it is
    /// a promise, and returns its value as JSON.
    pub async fn eval(&mut self, expression: &str) -> Result<Value, Error> {
        let params = json!({
            "expression": expression, "awaitPromise": true, "returnByValue": true
        });
        let result = self.call("Runtime.evaluate", params).await?;
        if let Some(details) = result.get("exceptionDetails") {
            return Err(Error::Exception(details.clone()));
        }
        Ok(result["result"]["value"].clone())
    }

    /// Presses and releases `key` (a DOM key name, `code` its Windows
    /// virtual key code) on the page, as a keyboard does.
    pub async fn press(&mut self, key: &str, code: u32) -> Result<(), Error> {
        for kind in ["keyDown", "keyUp"] {
            let event = json!({
                "type": kind, "key": key, "code": key, "windowsVirtualKeyCode": code
            });
            self.call("Input.dispatchKeyEvent", event).await?;
        }
        Ok(())
    }

    /// What the page logged and threw (the parameters of the
    /// `Runtime.consoleAPICalled` and `Runtime.exceptionThrown` events
    /// kept so far; `Runtime.enable` asks for them).
    pub fn page_log(&self) -> Vec<String> {
        (self.page.events.iter())
            .filter(|e| {
                let m = e["method"].as_str().unwrap_or_default();
                m == "Runtime.consoleAPICalled" || m == "Runtime.exceptionThrown"
            })
            .map(|e| e["params"].to_string())
            .collect()
    }
}

/// The DevTools URL of the first tab's page, asked of the browser's
/// endpoint (the tab may be listed a moment after the endpoint).
async fn page_target(browser_url: &str, timeout: Duration) -> Result<String, Error> {
    let mut browser = Connection::open(browser_url, timeout).await?;
    let base = browser_url
        .split("/devtools/")
        .next()
        .unwrap_or(browser_url);
    let find = async {
        loop {
            let targets = browser.call("Target.getTargets", json!({})).await?;
            let infos = targets["targetInfos"].as_array().map_or(&[][..], |t| t);
            let page = infos.iter().find(|t| t["type"] == "page");
            if let Some(id) = page.and_then(|t| t["targetId"].as_str()) {
                return Ok(format!("{base}/devtools/page/{id}"));
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    };
    match tokio::time::timeout(timeout, find).await {
        Ok(found) => found,
        Err(_) => Err(Error::NoPage),
    }
}

/// A command sent and not yet answered (see [`Browser::send`]).
#[derive(Debug)]
#[must_use = "the reply is waited for with Browser::reply"]
pub struct Sent {
    id: u64,
    method: String,
}

/// One DevTools WebSocket: numbered commands, the replies to commands sent
/// and not yet waited for, and the events that came while waiting for
/// something else.
struct Connection {
    socket: WebSocketStream<MaybeTlsStream<TcpStream>>,
    next_id: u64,
    /// Commands sent whose replies are kept until asked for.
    unanswered: HashSet<u64>,
    replies: HashMap<u64, Value>,
    events: VecDeque<Value>,
    timeout: Duration,
}

impl Connection {
    async fn open(url: &str, timeout: Duration) -> Result<Connection, Error> {
        let connect = tokio_tungstenite::connect_async(url);
        let connected = within(timeout, "the DevTools connection", connect).await?;
        let (socket, _) = connected.map_err(|source| Error::Connect {
            url: url.to_owned(),
            source: Box::new(source),
        })?;
        Ok(Connection {
            socket,
            next_id: 1,
            unanswered: HashSet::new(),
            replies: HashMap::new(),
            events: VecDeque::new(),
            timeout,
        })
    }

    async fn call(&mut self, method: &str, params: Value) -> Result<Value, Error> {
        let sent = self.send(method, params).await?;
        self.reply(sent).await
    }

    async fn send(&mut self, method: &str, params: Value) -> Result<Sent, Error> {
        let id = self.next_id;
        self.next_id += 1;
        let command = json!({ "id": id, "method": method, "params": params });
        let send = self.socket.send(Message::text(command.to_string()));
        let what = format!("sending {method}");
        within(self.timeout, &what, send)
            .await?
            .map_err(|e| Error::Socket(Box::new(e)))?;
        self.unanswered.insert(id);
        Ok(Sent {
            id,
            method: method.to_owned(),
        })
    }

    async fn reply(&mut self, sent: Sent) -> Result<Value, Error> {
        let Sent { id, method } = sent;
        let reply = match self.replies.remove(&id) {
            Some(reply) => Ok(reply),
            None => {
                let timeout = self.timeout;
                let reply = self.next_message(|v| v["id"] == id);
                let what = format!("the reply to {method}");
                within(timeout, &what, reply).await.and_then(|r| r)
            }
        };
        // Answered or given up: a late reply is not kept.
        self.unanswered.remove(&id);
        let mut reply = reply?;
        if let Some(error) = reply.get("error") {
            return Err(Error::Command {
                method,
                error: error.clone(),
            });
        }
        Ok(reply["result"].take())
    }

    async fn event(&mut self, method: &str) -> Result<Value, Error> {
        if let Some(at) = self.events.iter().position(|e| e["method"] == method) {
            let mut event = self.events.remove(at).expect("found");
            return Ok(event["params"].take());
        }
        let timeout = self.timeout;
        let event = self.next_message(|v| v["method"] == method);
        let mut event = within(timeout, &format!("the event {method}"), event).await??;
        Ok(event["params"].take())
    }

    /// The next message that is `wanted`; events and the replies to
    /// commands sent on the way are kept.
    async fn next_message(&mut self, wanted: impl Fn(&Value) -> bool) -> Result<Value, Error> {
        while let Some(message) = self.socket.next().await {
            let Message::Text(text) = message.map_err(|e| Error::Socket(Box::new(e)))? else {
                continue;
            };
            let value: Value = serde_json::from_str(&text).map_err(Error::NotJson)?;
            if wanted(&value) {
                return Ok(value);
            }
            if let Some(id) = value["id"]
                .as_u64()
                .filter(|id| self.unanswered.contains(id))
            {
                self.replies.insert(id, value);
            } else if value.get("method").is_some() {
                if self.events.len() == EVENTS_KEPT {
                    self.events.pop_front();
                }
                self.events.push_back(value);
            }
        }
        Err(Error::Closed)
    }
}

/// `future`'s output, or [`Error::Timeout`] naming `what`.
async fn within<T>(
    timeout: Duration,
    what: &str,
    future: impl Future<Output = T>,
) -> Result<T, Error> {
    tokio::time::timeout(timeout, future)
        .await
        .map_err(|_| Error::Timeout {
            what: what.to_owned(),
            after: timeout,
        })
}

/// The parameters of `Input.dispatchMouseEvent` for a left-button event
/// of `kind` (`mousePressed`, `mouseMoved` with the button held,
/// `mouseReleased`) at (`x`, `y`) in CSS pixels.
pub fn left_button(kind: &str, x: f64, y: f64) -> Value {
    json!({ "type": kind, "x": x, "y": y, "button": "left", "buttons": 1, "clickCount": 1 })
}

/// Chromium ends with its [`Browser`], whichever way its owner ends: its
/// whole process group, so that no helper process still writes to the
/// profile when it is removed.
struct KillOnDrop(Child);

impl Drop for KillOnDrop {
    fn drop(&mut self) {
        kill_group(&self.0);
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

#[cfg(unix)]
fn in_own_group(command: &mut Command) {
    use std::os::unix::process::CommandExt;
    command.process_group(0);
}

#[cfg(not(unix))]
fn in_own_group(_: &mut Command) {}

/// Kills the process group `child` leads ([`in_own_group`]).
#[cfg(unix)]
fn kill_group(child: &Child) {
    if let Ok(pid) = libc::pid_t::try_from(child.id()) {
        // SAFETY: kill(2) with a negative pid signals that process group;
        // it touches no memory of this process.
        unsafe {
            libc::kill(-pid, libc::SIGKILL);
        }
    }
}

#[cfg(not(unix))]
fn kill_group(_: &Child) {}

/// Asks the kernel to send the child `signal` when the thread that started
/// it ends, so that a process killed outright leaves no child behind.
#[cfg(target_os = "linux")]
pub fn end_with_this_thread(command: &mut Command, signal: libc::c_int) {
    use std::os::unix::process::CommandExt;
    // SAFETY: the closure runs in the child between fork and exec and only
    // calls `prctl`, which is async-signal-safe.
    unsafe {
        command.pre_exec(move || {
            libc::prctl(libc::PR_SET_PDEATHSIG, signal);
            Ok(())
        });
    }
}

/// Elsewhere the children end with their owners' drops only.
#[cfg(not(target_os = "linux"))]
pub fn end_with_this_thread(_: &mut Command, _signal: i32) {}

//! The DevTools client against a stand-in DevTools server on 127.0.0.1 (a
//! stand-in `chromium` script says its address): the first tab's page is
//! found when the browser lists it, replies are matched to their commands
//! whatever their order, events that come on the way are kept, and a
//! command's error, a page's exception and a reply that never comes are
//! each a typed error.

use std::path::PathBuf;
use std::time::Duration;

use futures_util::{SinkExt, StreamExt};
use serde_json::{Value, json};
use tokio::net::{TcpListener, TcpStream};
use tokio_tungstenite::WebSocketStream;
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::tungstenite::handshake::server::{Request, Response};
use vtfarm_browser::{Browser, Error, Graphics, Options};

/// Accepts one WebSocket connection and answers it with the path asked for.
async fn accept(listener: &TcpListener) -> (WebSocketStream<TcpStream>, String) {
    let (stream, _) = listener.accept().await.unwrap();
    let mut path = String::new();
    // The error type is tungstenite's callback's.
    #[allow(clippy::result_large_err)]
    let callback = |request: &Request, response: Response| {
        path = request.uri().path().to_owned();
        Ok(response)
    };
    let socket = tokio_tungstenite::accept_hdr_async(stream, callback)
        .await
        .unwrap();
    (socket, path)
}

async fn receive(socket: &mut WebSocketStream<TcpStream>) -> Value {
    loop {
        match socket.next().await.unwrap().unwrap() {
            Message::Text(text) => return serde_json::from_str(&text).unwrap(),
            _ => continue,
        }
    }
}

async fn answer(socket: &mut WebSocketStream<TcpStream>, message: Value) {
    socket
        .send(Message::text(message.to_string()))
        .await
        .unwrap();
}

/// The stand-in DevTools server: the browser's endpoint lists no page at
/// first, then the page `p1`; the page answers as the test expects.
async fn serve(listener: TcpListener) {
    let (mut browser, path) = accept(&listener).await;
    assert_eq!(path, "/devtools/browser/b1");
    for targets in [json!([]), json!([{ "type": "page", "targetId": "p1" }])] {
        let command = receive(&mut browser).await;
        assert_eq!(command["method"], "Target.getTargets");
        let result = json!({ "targetInfos": targets });
        answer(
            &mut browser,
            json!({ "id": command["id"], "result": result }),
        )
        .await;
    }
    let (mut page, path) = accept(&listener).await;
    assert_eq!(path, "/devtools/page/p1");
    // Two commands sent before either is answered: the second is
    // answered first, with an event between the answers.
    let first = receive(&mut page).await;
    let second = receive(&mut page).await;
    assert_eq!(
        (&first["method"], &second["method"]),
        (&json!("Page.enable"), &json!("Input.dispatchMouseEvent"))
    );
    answer(
        &mut page,
        json!({ "id": second["id"], "result": { "n": 2 } }),
    )
    .await;
    answer(
        &mut page,
        json!({ "method": "Page.loadEventFired", "params": { "timestamp": 7 } }),
    )
    .await;
    answer(
        &mut page,
        json!({ "id": first["id"], "result": { "n": 1 } }),
    )
    .await;
    loop {
        let command = receive(&mut page).await;
        let id = &command["id"];
        let reply = match command["method"].as_str().unwrap() {
            "No.such" => {
                json!({ "id": id, "error": { "code": -32601, "message": "'No.such' wasn't found" } })
            }
            "Runtime.evaluate" if command["params"]["expression"] == "throw 1" => json!({
                "id": id, "result": { "result": { "type": "number" }, "exceptionDetails": { "text": "Uncaught" } }
            }),
            "Runtime.evaluate" => {
                json!({ "id": id, "result": { "result": { "type": "number", "value": 42 } } })
            }
            // Never answered.
            _ => continue,
        };
        answer(&mut page, reply).await;
    }
}

#[tokio::test]
async fn the_client_finds_the_page_matches_replies_keeps_events_and_types_errors() {
    use std::os::unix::fs::PermissionsExt;
    let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let port = listener.local_addr().unwrap().port();
    let server = tokio::spawn(serve(listener));
    // This binary's only stand-in, written before any process starts.
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("vtfarm-browser-devtools");
    std::fs::create_dir_all(&dir).unwrap();
    let chromium = dir.join("chromium");
    let said = format!("DevTools listening on ws://127.0.0.1:{port}/devtools/browser/b1");
    let script = format!("#!/bin/sh\necho 'starting' >&2\necho '{said}' >&2\nexec sleep 60\n");
    std::fs::write(&chromium, script).unwrap();
    std::fs::set_permissions(&chromium, std::fs::Permissions::from_mode(0o755)).unwrap();

    // Long enough for the stand-in to start on a busy machine; the
    // unanswered command waits for all of it.
    let timeout = Duration::from_secs(5);
    let options = Options {
        graphics: Graphics::NoWebGl,
        window: [320, 200],
        timeout,
        end_with_this_thread: false,
    };
    let mut browser = Browser::start(&chromium, &options).await.unwrap();
    let first = browser.send("Page.enable", json!({})).await.unwrap();
    let second = browser
        .send("Input.dispatchMouseEvent", json!({}))
        .await
        .unwrap();
    assert_eq!(browser.reply(first).await.unwrap(), json!({ "n": 1 }));
    assert_eq!(browser.reply(second).await.unwrap(), json!({ "n": 2 }));
    let event = browser.event("Page.loadEventFired").await.unwrap();
    assert_eq!(event, json!({ "timestamp": 7 }));

    let error = browser.call("No.such", json!({})).await.unwrap_err();
    let Error::Command { method, error } = &error else {
        panic!("{error:?}");
    };
    assert_eq!(method, "No.such");
    assert_eq!(error["code"], -32601);
    let thrown = browser.eval("throw 1").await.unwrap_err();
    assert!(
        matches!(&thrown, Error::Exception(details) if details["text"] == "Uncaught"),
        "{thrown:?}"
    );
    assert_eq!(browser.eval("6 * 7").await.unwrap(), 42);

    let error = browser.call("Never.answered", json!({})).await.unwrap_err();
    let Error::Timeout { what, after } = &error else {
        panic!("{error:?}");
    };
    assert_eq!(
        (what.as_str(), *after),
        ("the reply to Never.answered", timeout)
    );
    drop(browser);
    server.abort();
}

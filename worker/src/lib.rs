//! The farm worker: dials the master, holds the whole scene (cached on disk by
//! content hash), rebuilds each frame's ID buffers locally and runs task
//! packages with the vertex tracer, returning sparse bitmaps.
//!
//! - [`engine`]: computing, no network: scene cache, renderer, packages.
//! - [`session`]: the worker's side of the protocol, a sans-IO state machine.
//! - [`serve()`]: the async driver of a session over any `Link`.
//! - `priority`: the later stages of the view's frames at a lower priority.
//! - [`client`]: QUIC: connect, handshake, reconnect with backoff.

#[cfg(feature = "cli")]
pub mod cli;
pub mod client;
pub mod engine;
mod priority;
pub mod serve;
pub mod session;

pub use client::run_worker;
pub use engine::Engine;
pub use serve::{DrainSignal, serve};
pub use session::{SceneStore, SessionEnd, Task, WorkerConfig, WorkerSession};
pub use vtfarm_transport::client::ClientOptions;

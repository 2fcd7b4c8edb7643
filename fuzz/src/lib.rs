//! The fuzz targets' bodies, one function per target: each feeds hostile
//! bytes to the code a peer or a file reaches and may only return (errors
//! are fine; a panic, a hang or an unbounded allocation is a finding).

use std::path::Path;

use sha2::{Digest, Sha256};
use vtfarm_method::FrameSetup;
use vtfarm_proto::{
    HandshakePolicy, JobScene, MAX_HANDSHAKE_BYTES, Message, SESSION_LIMIT, SceneData, check_hello,
    decode_message, split_frame,
};

/// One framed message (length prefix and body) under the session's limit,
/// as the session reader takes it apart, then every wire conversion the
/// master or a worker applies to it.
pub fn frame(data: &[u8]) {
    let Ok(message) = first_message(data, SESSION_LIMIT) else {
        return;
    };
    convert(message);
}

/// The body of a connection's first message, as the master checks it.
pub fn handshake(data: &[u8]) {
    let policy = HandshakePolicy::new("fuzz-token", "fuzz");
    if let Ok(message) = first_message(data, MAX_HANDSHAKE_BYTES) {
        let _ = message.name();
    }
    let _ = check_hello(data, &policy);
}

/// An OBJ file and its MTL library: the input is the OBJ text, a line
/// `#MTL`, then the MTL text (written as `scene.mtl`).
pub fn obj(data: &[u8]) {
    let (obj, mtl) = match data.windows(5).position(|w| w == b"\n#MTL") {
        Some(i) => (&data[..i], &data[i + 5..]),
        None => (data, &b""[..]),
    };
    let Ok(dir) = tempfile::tempdir() else {
        return;
    };
    let path = dir.path().join("scene.obj");
    if std::fs::write(&path, obj).is_err()
        || std::fs::write(dir.path().join("scene.mtl"), mtl).is_err()
    {
        return;
    }
    if let Ok(scene) = vtfarm_scene::obj::load_obj(&path, &Default::default()) {
        // What the loader accepts, the wire and the BVH accept too.
        assert_eq!(scene.validate(), Ok(()));
    }
}

/// A job file's text.
pub fn job(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(job) = vtfarm_job::parse_job(text, Path::new("fuzz/job.toml")) {
        // Whatever parses has settings within their bounds.
        assert_eq!(job.vertex.validate(), Ok(()));
        assert_eq!(job.trace.validate(), Ok(()));
    }
}

/// The conversions to domain types that the master and the workers apply.
fn convert(message: Message) {
    match message {
        Message::SubmitJob { job } => submitted(job),
        Message::SubmitStudy { study } => study.variants.into_iter().for_each(submitted),
        Message::SceneData(data) => scene(data.bytes),
        Message::FrameStart(start) => {
            let _ = FrameSetup::try_from(start.setup);
        }
        Message::PackageResult(result) => match result.pixels {
            vtfarm_proto::ResultPixels::Bitmap(bitmap) => {
                let _ = bitmap.into_bitmap_within(640, 360);
            }
            vtfarm_proto::ResultPixels::Frame { image, .. } => {
                let _ = image.into_pixels();
            }
        },
        Message::FrameDone(done) => {
            let _ = done.image.into_pixels();
        }
        _ => {}
    }
}

/// A submitted job's conversions: its frames and an inline scene.
fn submitted(job: vtfarm_proto::WireJob) {
    for frame in job.frames {
        let _ = FrameSetup::try_from(frame);
    }
    if let JobScene::Data(data) = job.scene {
        scene(data.bytes);
    }
}

/// Scene bytes under their own hash (the fuzzer cannot forge SHA-256).
fn scene(bytes: Vec<u8>) {
    let data = SceneData {
        hash: Sha256::digest(&bytes).into(),
        bytes,
    };
    if let Ok(scene) = data.to_scene() {
        assert_eq!(scene.validate(), Ok(()));
    }
}

/// The first message of a frame whose body may be at most `limit` bytes.
fn first_message(data: &[u8], limit: u32) -> Result<Message, vtfarm_proto::FrameError> {
    decode_message(split_frame(data, limit)?.0)
}

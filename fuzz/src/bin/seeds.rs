//! Writes the starting corpora into `fuzz/corpus/<target>/` from real
//! messages and files: `cargo run --bin seeds` (from `fuzz/`).

use std::fs;
use std::path::Path;

use glam::Vec3;
use vtfarm_method::FrameSetup;
use vtfarm_proto::{
    FrameStart, Hello, JobScene, Message, Package, PackageResult, Role, SceneData, WireBitmap,
    WireFrameSetup, WireImageFormat, WireJob, WireMethod, WirePackageStats, encode_message,
};
use vtfarm_scene::{Camera, Lighting, Material, MaterialId, Object, ObjectId, Scene, Triangle};
use vtfarm_trace::TraceSettings;
use vtfarm_vertex::{SparseBitmap, VertexSettings};

fn main() -> std::io::Result<()> {
    let corpus = Path::new(env!("CARGO_MANIFEST_DIR")).join("corpus");
    let write = |target: &str, name: &str, bytes: &[u8]| {
        let dir = corpus.join(target);
        fs::create_dir_all(&dir)?;
        fs::write(dir.join(name), bytes)
    };
    let scene = Scene {
        positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y],
        normals: vec![Vec3::Z; 3],
        triangles: vec![Triangle {
            vertices: [0, 1, 2],
            object: ObjectId(0),
            material: MaterialId(0),
        }],
        objects: vec![Object {
            name: "glass".into(),
        }],
        materials: vec![Material::default()],
        ..Default::default()
    };
    let camera = Camera {
        eye: Vec3::new(0.2, 0.2, 2.0),
        target: Vec3::new(0.2, 0.2, 0.0),
        up: Vec3::Y,
        fov_y_deg: 40.0,
        width: 8,
        height: 6,
    };
    let setup = WireFrameSetup::from(&FrameSetup {
        camera,
        lighting: Lighting::default(),
        trace: TraceSettings::default(),
        vertex: VertexSettings::default(),
    });
    let data = SceneData::from_scene(&scene);
    let hello = Message::Hello(Hello::new("fuzz-token", Role::Submitter));
    let messages = [
        ("hello", hello.clone()),
        ("heartbeat", Message::Heartbeat),
        (
            "submit",
            Message::SubmitJob {
                job: WireJob {
                    name: "seed".into(),
                    scene: JobScene::Data(data.clone()),
                    frames: vec![setup.clone()],
                    reflectors: vec![0],
                    aux: false,
                    method: WireMethod::VertexTracing,
                    image: WireImageFormat::Srgb8,
                    priority: 0,
                    kind: vtfarm_proto::WireJobKind::Render,
                },
            },
        ),
        ("scene", Message::SceneData(data.clone())),
        (
            "frame_start",
            Message::FrameStart(FrameStart {
                job: vtfarm_proto::JobId(1),
                frame: 0,
                scene: data.hash,
                setup,
                reflectors: vec![0],
                method: WireMethod::VertexTracing,
                aux: false,
                image: vtfarm_proto::WireImageFormat::LinearF32,
                stages: Vec::new(),
            }),
        ),
        (
            "package",
            Message::Package(Package {
                id: 3,
                job: vtfarm_proto::JobId(1),
                frame: 0,
                triangles: vec![0],
                whole: None,
            }),
        ),
        (
            "result",
            Message::PackageResult(PackageResult {
                id: 3,
                pixels: vtfarm_proto::ResultPixels::Bitmap(WireBitmap::from(&SparseBitmap {
                    x0: 1,
                    y0: 1,
                    width: 2,
                    height: 1,
                    mask: vec![true, false],
                    color: vec![Vec3::ONE],
                    reflected: vec![Vec3::ZERO],
                    transmitted: vec![Vec3::ZERO],
                    reflected_object: vec![0],
                })),
                stats: WirePackageStats::default(),
                busy_micros: 7,
                setup_micros: 3,
                triangle_samples: vec![3],
                stage: None,
                mesh: None,
            }),
        ),
    ];
    for (name, message) in &messages {
        let frame = encode_message(message).expect("seed messages encode");
        write("frame", name, &frame)?;
    }
    let hello_frame = encode_message(&hello).expect("encodes");
    write("handshake", "hello", &hello_frame[4..])?;
    let worker = Message::Hello(Hello::new(
        "fuzz-token",
        Role::Worker {
            threads: 4,
            name: "w".into(),
        },
    ));
    write(
        "handshake",
        "worker",
        &encode_message(&worker).expect("encodes")[4..],
    )?;

    write(
        "obj",
        "quad",
        b"mtllib scene.mtl\no glass\nusemtl mirror\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//1 4//1\ng dash\nusemtl paint\nv 0 0 -1\nv 1 0 -1\nv 0 1 -1\nf 5 6 7\n#MTL\nnewmtl mirror\nKd 0.1 0.1 0.1\nKs 0.9 0.9 0.9\nNs 64\nillum 3\nKr 0.8 0.8 0.8\nd 0.7\nNi 1.5\nnewmtl paint\nKa 0.1 0.1 0.1\nKd 0.5 0.2 0.2\nKe 0 0 0\n",
    )?;
    let configs = Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs");
    write("job", "cockpit", &fs::read(configs.join("cockpit.toml"))?)?;
    write(
        "job",
        "obj",
        b"[scene]\nobj = \"missing.obj\"\n[camera]\neye = [0, 0, 2]\ntarget = [0, 0, 0]\nfov_y = 40\nwidth = 64\nheight = 48\n[reflectors]\nobjects = [\"glass\"]\n",
    )?;
    write(
        "job",
        "quality",
        b"[scene]\nbuiltin = \"cockpit\"\nglass = \"flat-tilted\"\nglass_tilt = 15\n[camera]\nwidth = 320\nheight = 180\n[[lighting.lights]]\nkind = \"directional\"\ndirection = [0, -1, 0]\n[quality]\nlevel = \"refine\"\nepsilon = 0\npixel_floor = 0.5\nmax_refine_depth = 20\n[frames]\neyes = [[-0.5, 1.4, 0.1]]\n",
    )?;
    Ok(())
}

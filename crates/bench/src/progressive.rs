//! `vtfarm bench progressive`: one eye's preview, refine and full on the
//! built-in cockpit, rendered as three separate frames (each set up from
//! nothing, as `vtfarm render --quality` does) against one progressive frame
//! (`Renderer::progressive`: set up once, each stage continuing the last's
//! vertices), side by side in one run; the least wall time of a few rounds.
//! It checks that each stage's image is the separate render's, bit for bit.

use std::time::{Duration, Instant};

use anyhow::{Result, ensure};
use vtfarm_render::{FrameSetup, RenderOptions, Renderer};
use vtfarm_vertex::{FrameImage, PixelValue, Quality, VertexSettings};

use super::CockpitFrameArgs;

#[derive(clap::Args)]
pub struct ProgressiveArgs {
    #[command(flatten)]
    frame: CockpitFrameArgs,
    /// Rounds; the least time of each figure is kept.
    #[arg(long, default_value_t = 5)]
    rounds: u32,
}

const STAGES: [Quality; 3] = [Quality::Preview, Quality::Refine, Quality::Full];

/// One round's figures, per stage.
#[derive(Clone, Copy, Default)]
struct Round {
    /// A separate render of the stage's quality (set-up included).
    separate: [Duration; 3],
    /// The separate renders' samples (vertices, pixels).
    separate_samples: [(u64, u64); 3],
    /// The progressive frame: its set-up, then each stage's own time.
    set_up: Duration,
    stage: [Duration; 3],
    stage_samples: [(u64, u64); 3],
}

pub(crate) fn run(args: ProgressiveArgs) -> Result<()> {
    let job = args.frame.set_up(Quality::Full)?;
    let renderer = Renderer::new(job.scene.clone(), job.reflectors.clone());
    let options = RenderOptions::default();
    let at = |quality| FrameSetup {
        vertex: VertexSettings {
            quality,
            ..job.setup.vertex
        },
        ..job.setup.clone()
    };
    // Warms the shadow-map cache, as a renderer's second frame finds it.
    renderer.render(&at(Quality::Preview), &options, &mut |_, _| {});
    let mut best: Option<Round> = None;
    for _ in 0..args.rounds.max(1) {
        let mut round = Round::default();
        let mut images = Vec::new();
        for (k, &quality) in STAGES.iter().enumerate() {
            let start = Instant::now();
            let frame = renderer.render(&at(quality), &options, &mut |_, _| {});
            round.separate[k] = start.elapsed();
            round.separate_samples[k] = (frame.stats.vertex_samples, frame.stats.filled_pixels);
            // Only what the check needs: the frames themselves are dropped,
            // so both ways allocate their buffers alike.
            images.push(fingerprint(&frame.image));
        }
        let start = Instant::now();
        let mut progressive = renderer.progressive(&job.setup, &options);
        round.set_up = start.elapsed();
        for (k, &quality) in STAGES.iter().enumerate() {
            let start = Instant::now();
            let stage = progressive.advance(quality)?;
            round.stage[k] = start.elapsed();
            round.stage_samples[k] = (stage.stats.vertex_samples, stage.stats.filled_pixels);
            ensure!(
                fingerprint(progressive.image()) == images[k],
                "the progressive {} differs from the separate render",
                quality.name()
            );
        }
        best = Some(match best {
            None => round,
            Some(b) => least(b, round),
        });
    }
    let best = best.expect("at least one round");
    print(&args, &renderer, job.setup.camera, &best);
    Ok(())
}

/// A frame's PNG bytes and its reflector pixels' values: what must agree.
fn fingerprint(image: &FrameImage) -> (Vec<u8>, Vec<PixelValue>) {
    let pixels = image.glass().map(|i| image.pixel(i)).collect();
    (image.color.to_srgb8(), pixels)
}

/// Each figure's least over two rounds (the samples are the same).
fn least(a: Round, b: Round) -> Round {
    let min3 = |x: [Duration; 3], y: [Duration; 3]| std::array::from_fn(|k| x[k].min(y[k]));
    Round {
        separate: min3(a.separate, b.separate),
        set_up: a.set_up.min(b.set_up),
        stage: min3(a.stage, b.stage),
        ..a
    }
}

fn print(args: &ProgressiveArgs, renderer: &Renderer, camera: vtfarm_scene::Camera, r: &Round) {
    println!(
        "cockpit {} triangles, {}x{}, {} threads, least of {} rounds; load average {}",
        renderer.scene().triangles.len(),
        camera.width,
        camera.height,
        rayon::current_num_threads(),
        args.rounds.max(1),
        crate::support::load_average()
    );
    println!(
        "{:<8} {:>12} {:>12} {:>12} {:>12} {:>16} {:>16}",
        "stage",
        "separate ms",
        "separate Σ",
        "stage ms",
        "progr. Σ",
        "samples sep.",
        "samples progr."
    );
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    let (mut separate_sum, mut progressive_sum) = (Duration::ZERO, r.set_up);
    println!(
        "{:<8} {:>12} {:>12} {:>12.1} {:>12.1}",
        "set-up",
        "",
        "",
        ms(r.set_up),
        ms(r.set_up)
    );
    for (k, quality) in STAGES.iter().enumerate() {
        separate_sum += r.separate[k];
        progressive_sum += r.stage[k];
        let samples = |(v, p): (u64, u64)| format!("{v} + {p} px");
        println!(
            "{:<8} {:>12.1} {:>12.1} {:>12.1} {:>12.1} {:>16} {:>16}",
            quality.name(),
            ms(r.separate[k]),
            ms(separate_sum),
            ms(r.stage[k]),
            ms(progressive_sum),
            samples(r.separate_samples[k]),
            samples(r.stage_samples[k]),
        );
    }
    println!(
        "separate: each quality rendered from nothing (raster pass included), Σ the three in a row;\n\
         progressive: one set-up, then each stage continuing the last (vertex samples: new ones only);\n\
         every stage's image checked equal to the separate render's"
    );
}

//! The master's memory over long jobs, measured with a counting allocator:
//! the master's core and real worker sessions in the `Pair` harness render
//! job after job, and the heap the process holds between jobs must not grow
//! with the frames rendered (the soak run's question, without its noise).

#[path = "support/frame.rs"]
mod frame;

mod support;

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicI64, Ordering};
use std::time::Duration;

use frame::small_frame;
use glam::Vec3;
use support::pair::Pair;
use vtfarm_cockpit::{CockpitConfig, cockpit};
use vtfarm_master::FarmRules;
use vtfarm_master::{JobOptions, wire_job};
use vtfarm_method::MethodKind;
use vtfarm_proto::SceneData;

/// Bytes allocated and not yet freed, by every thread.
static LIVE: AtomicI64 = AtomicI64::new(0);

struct Counting;

// SAFETY: every call goes to `System` unchanged; only the count is added.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        LIVE.fetch_add(layout.size() as i64, Ordering::Relaxed);
        unsafe { System.alloc(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        LIVE.fetch_sub(layout.size() as i64, Ordering::Relaxed);
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        LIVE.fetch_add(layout.size() as i64, Ordering::Relaxed);
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        LIVE.fetch_add(new_size as i64 - layout.size() as i64, Ordering::Relaxed);
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

#[test]
fn the_heap_between_jobs_does_not_grow_with_the_frames_rendered() {
    let c = cockpit(&CockpitConfig {
        detail: 0.2,
        glass_segments: 24,
        ..CockpitConfig::default()
    });
    let data = SceneData::from_scene(&c.scene);
    let reflectors = c.cover_glass_triangles();
    // One view repeated: memory, not images, is the question here.
    let view = small_frame(&c, Vec3::ZERO);
    let mut pair = Pair::new(FarmRules::default());
    pair.add_worker("w1", 1.0);
    pair.add_worker("w2", 1.0);
    let run_job = |pair: &mut Pair, frames: usize| {
        let setups = vec![view.clone(); frames];
        let options = JobOptions {
            method: MethodKind::VertexTracing,
            aux: false,
        };
        let job = wire_job("memory", &data, &setups, &reflectors, options);
        pair.to_submitter.clear();
        pair.submit(job, data.clone());
        pair.drive(Duration::from_secs(3600), |p| {
            p.frames_done().len() == frames || p.job_failed().is_some()
        });
        assert_eq!(pair.job_failed(), None);
        // The harness's copy of what the submitter got is not the master's.
        pair.forget_records();
        LIVE.load(Ordering::Relaxed)
    };
    // Warm-up: the scene, BVHs, thread pools, the telemetry's kept frames,
    // and a finished job as large as the next ones (the master keeps the
    // last job's set-ups, 4 KB a frame, until the next one).
    const FRAMES: usize = 40;
    run_job(&mut pair, FRAMES);
    let before = run_job(&mut pair, FRAMES);
    let after = run_job(&mut pair, FRAMES);
    let growth = after - before;
    println!("live heap {before} B after two jobs, {after} B after three");
    // 1.3 KB a frame (the soak run's master RSS growth) would be 52 KB; a
    // job leaves about 2 KB (not per frame).
    assert!(
        growth.abs() < 8 * 1024,
        "the heap grew {growth} bytes over {FRAMES} frames"
    );
}

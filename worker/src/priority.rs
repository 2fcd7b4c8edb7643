//! The later stages of a progressive frame (the view's `refine` and
//! `full`) run on threads of a lower scheduling priority than the rest of
//! the farm's work: on a machine whose cores the master and the workers
//! share, the master's base frame and every worker's set-up and preview,
//! which the view's first image waits for, go first, and the refinement
//! takes the cores they leave. The same work is done in the same order per
//! package, so every stage's pixels are the same; only who waits changes.
//!
//! The pool has as many threads as the worker's own (the global rayon
//! pool, `--threads`), made once: lowering a thread's priority needs no
//! privilege but raising it again would, so the later stages keep threads
//! of their own instead of lowering and raising the pool's.

use std::sync::OnceLock;

/// How much lower than the rest the later stages' threads run (a `nice`
/// increment: at 10 a busy thread of normal priority gets about ten times
/// the CPU of one of these when both want a core).
pub(crate) const LATER_STAGE_NICENESS: i32 = 10;

/// The pool that runs the later stages of progressive packages.
pub(crate) fn later_stages() -> &'static rayon::ThreadPool {
    static POOL: OnceLock<rayon::ThreadPool> = OnceLock::new();
    POOL.get_or_init(|| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(rayon::current_num_threads())
            .thread_name(|k| format!("later-stages-{k}"))
            .start_handler(|_| vtfarm_transport::lower_this_thread(LATER_STAGE_NICENESS))
            .build()
            .expect("a thread pool of the worker's size starts")
    })
}

#[cfg(test)]
mod tests {
    /// The pool's threads run at the lower priority, the caller's not.
    #[cfg(target_os = "linux")]
    #[test]
    fn later_stages_run_at_a_lower_priority_than_the_caller() {
        let niceness = || {
            // SAFETY: reads the calling thread's nice value.
            unsafe { libc::getpriority(libc::PRIO_PROCESS, 0) }
        };
        let caller = niceness();
        let pooled = super::later_stages().install(niceness);
        assert_eq!(
            pooled,
            (caller + super::LATER_STAGE_NICENESS).min(19),
            "caller {caller}"
        );
        assert_eq!(niceness(), caller);
    }
}

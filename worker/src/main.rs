//! `vtfarm-worker`: the standalone worker binary, a thin wrapper over
//! `vtfarm worker` (same options).

fn main() -> std::process::ExitCode {
    vtfarm_worker::cli::main()
}

//! `vtfarm-master`: the standalone master binary, a thin wrapper over
//! `vtfarm master` (same options).

fn main() -> std::process::ExitCode {
    vtfarm_master::cli::main()
}

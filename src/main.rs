//! The `aarbf` command: logging to stderr (`AARBF_LOG`), then [`aarbf::cli`]. Under an MPI
//! launcher, ranks other than 0 log only warnings unless `AARBF_LOG` says otherwise: every
//! process resolves the same scene and would say the same lines once each.

use tracing_subscriber::EnvFilter;

fn main() -> std::process::ExitCode {
    tracing_subscriber::fmt()
        .with_env_filter(EnvFilter::try_from_env("AARBF_LOG").unwrap_or_else(|_| {
            let rank = aarbf::dist::launched_rank().unwrap_or(0);
            EnvFilter::new(if rank == 0 { "info" } else { "warn" })
        }))
        .with_writer(std::io::stderr)
        .with_target(false)
        .without_time()
        .init();
    let cli = aarbf::cli::Cli::parse_args();
    match aarbf::cli::run(cli) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

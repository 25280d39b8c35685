//! `worker`: the render farm's worker process. It joins the farm with the coordinator service
//! (issue 5); until then it only builds, so that the workspace has its final shape.

use std::process::ExitCode;

fn main() -> ExitCode {
    eprintln!(
        "worker: the render farm is not available yet; render on one machine with `coordinator render`"
    );
    ExitCode::FAILURE
}

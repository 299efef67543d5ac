//! Helpers shared by the CLI tests: running this build's `ground-sim`, and the job scripts in
//! `tools/`.

use std::path::Path;
use std::process::{Command, Output};

/// Run this build's `ground-sim` with `args`.
pub fn exec(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_ground-sim"))
        .args(args)
        .output()
        .expect("ground-sim runs")
}

/// Run `args` expecting success; what it printed, stdout then stderr (some commands log their
/// progress on stderr).
pub fn run(args: &[&str]) -> String {
    let out = exec(args);
    let (o, e) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    assert!(
        out.status.success(),
        "ground-sim {args:?} failed:\n{o}\n{e}"
    );
    format!("{o}{e}")
}

/// Run `args` expecting failure; its stderr.
pub fn refused(args: &[&str]) -> String {
    let out = exec(args);
    assert!(!out.status.success(), "ground-sim {args:?} should fail");
    String::from_utf8_lossy(&out.stderr).to_string()
}

/// A stand-in for Slurm's `sbatch`: runs the job script at once (array tasks in turn, with
/// `SLURM_ARRAY_TASK_ID` set) in its `--chdir`, and prints a job id as `--parsable` does. A
/// failing task fails the submission, which is what `afterok` makes of the merge.
#[allow(dead_code)] // only the tests that run the job scripts use it
pub const FAKE_SBATCH: &str = r#"#!/usr/bin/env bash
set -euo pipefail
script=""
for a in "$@"; do
    case $a in -*) ;; *) script=$a ;; esac
done
cd "$(sed -n 's/^#SBATCH --chdir=//p' "$script")"
range=$(sed -n 's/^#SBATCH --array=//p' "$script")
if [[ -n $range ]]; then
    for ((i = ${range%-*}; i <= ${range#*-}; i++)); do
        SLURM_ARRAY_TASK_ID=$i SLURM_CPUS_PER_TASK=1 bash "$script" >&2
    done
else
    bash "$script" >&2
fi
echo "$RANDOM"
"#;

/// Write [`FAKE_SBATCH`] as `bin_dir/sbatch` (executable); put `bin_dir` first on `PATH` to use it.
#[allow(dead_code)] // only the tests that run the job scripts use it
pub fn install_fake_sbatch(bin_dir: &Path) {
    std::fs::create_dir_all(bin_dir).unwrap();
    let sbatch = bin_dir.join("sbatch");
    std::fs::write(&sbatch, FAKE_SBATCH).unwrap();
    std::fs::set_permissions(&sbatch, std::os::unix::fs::PermissionsExt::from_mode(0o755)).unwrap();
}

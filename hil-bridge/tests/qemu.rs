//! The firmware under QEMU on a few frames (one terrain frame and the five stress frames, with
//! link faults): every result bit-exact with the host, the instruction bound, static RAM.
//!
//! Needs `qemu-system-arm`, `gcc`, `mkfifo` and the `thumbv7em-none-eabihf` target; without them
//! the test says so and passes (`.ci/run` installs them, so CI always runs it).

use hil_bridge::host::runner::{INSTRUCTION_BUDGET, RunOptions, STATIC_RAM_BUDGET, run};
use std::path::PathBuf;
use std::process::Command;

fn have(cmd: &str, arg: &str) -> bool {
    Command::new(cmd)
        .arg(arg)
        .output()
        .is_ok_and(|o| o.status.success())
}

fn missing_tools() -> Vec<&'static str> {
    let mut missing = Vec::new();
    if !have("qemu-system-arm", "--version") {
        missing.push("qemu-system-arm");
    }
    if !have("gcc", "--version") {
        missing.push("gcc");
    }
    if !have("mkfifo", "--version") {
        missing.push("mkfifo");
    }
    let targets = Command::new("rustup")
        .args(["target", "list", "--installed"])
        .output()
        .map(|o| String::from_utf8_lossy(&o.stdout).into_owned())
        .unwrap_or_default();
    if !targets.contains("thumbv7em-none-eabihf") {
        missing.push("rustup target thumbv7em-none-eabihf");
    }
    missing
}

#[test]
fn firmware_is_bit_exact_and_within_the_instruction_budget() {
    let missing = missing_tools();
    if !missing.is_empty() {
        eprintln!(
            "SKIPPED firmware_is_bit_exact_and_within_the_instruction_budget: missing {} \
             (bash .ci/run installs them)",
            missing.join(", ")
        );
        return;
    }
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut opts = RunOptions::new(root);
    opts.frames = Some(6);
    opts.progress = true;
    let report = run(&opts).expect("HIL run");
    // Six TRN stress frames, then the final phase's chain, whole.
    let final_phase: Vec<_> = report
        .per_frame
        .iter()
        .filter(|f| f.job != "locate")
        .collect();
    assert_eq!(report.frames, 6 + final_phase.len());
    assert!(
        final_phase.len() >= 8,
        "{} final-phase frames",
        final_phase.len()
    );
    // Keyframes captured, odometry fixes within a metre of the truth with an honest σ, and the
    // hazard maps made with a site chosen.
    let keyframes = final_phase.iter().filter(|f| f.outcome == "keyframe");
    assert_eq!(keyframes.count(), 3);
    let offsets: Vec<_> = final_phase
        .iter()
        .filter_map(|f| Some((f.offset_error_m?, f.offset_sigma_m?)))
        .collect();
    assert_eq!(offsets.len(), 3, "{final_phase:?}");
    for (err, sigma) in offsets {
        assert!(
            err < 1.0 && err < 3.5 * sigma.max(0.01),
            "offset error {err} m, σ {sigma}"
        );
    }
    let maps: Vec<_> = final_phase
        .iter()
        .filter(|f| f.hazard_sites.is_some())
        .collect();
    // Two maps of whole 0.4 m frames and two confirmations around the aim on 0.25 m frames,
    // each with a site (kept or moved).
    assert_eq!(maps.len(), 4);
    assert_eq!(final_phase.iter().filter(|f| f.job == "confirm").count(), 2);
    assert!(maps.iter().all(|m| m.site_from_target_m.is_some()));
    assert_eq!(
        report.bit_exact_frames, report.frames,
        "target and host results differ"
    );
    assert!(
        report.max_instructions_per_frame <= INSTRUCTION_BUDGET,
        "worst frame {} instructions > {INSTRUCTION_BUDGET}",
        report.max_instructions_per_frame
    );
    // Counts are deterministic: every frame was measured and none is implausibly small.
    assert!(report.per_frame.iter().all(|f| f.instructions > 1_000_000));
    assert!(report.static_ram_bytes <= STATIC_RAM_BUDGET);
    assert!(report.link_errors_injected >= 3);
    assert_eq!(report.link_errors_recovered, report.link_errors_injected);
    let s = report.target_status;
    assert_eq!(s.frames_done as usize, report.frames, "{s:?}");
    assert!(
        s.crc_errors + s.cobs_errors + s.seq_gaps + s.duplicates > 0,
        "{s:?}"
    );
}

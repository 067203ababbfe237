//! The demo's figures do not mislead: its world figures (the twin after the
//! mission, on the case study's site and on the mapped one; Table 1; Section
//! 6) are written through the plot crate's check, which refuses a legend
//! entry hidden under what is drawn after it or with nothing drawn, so the
//! demo finishing is the check passing; and each legend names what the run
//! produced.

use std::path::Path;

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn handbacks(report: &Path) -> usize {
    let r: serde_json::Value = serde_json::from_str(&read(report)).unwrap();
    r["handbacks"].as_array().unwrap().len()
}

#[test]
fn demo_world_figures_hide_no_legend_entry() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let mut stdout = Vec::new();
    twindrive_experiment::demo::run(&out, &mut stdout)
        .unwrap_or_else(|e| panic!("the demo (and with it the figure check) failed: {e:#}"));

    // The case study's site: a hand-back at the box, a block learnt, the
    // plan and its continuation drawn as references.
    let twin = read(&out.join("decoupled/twin.svg"));
    assert!(handbacks(&out.join("decoupled/report.json")) > 0);
    for entry in [
        "plan",
        "continuation 1",
        "robot (true path)",
        "hand-back",
        "block the twin learnt",
    ] {
        assert!(twin.contains(entry), "twin.svg lacks {entry}");
    }
    // The mapped site: the legend lists a hand-back only if there was one.
    let mapped = read(&out.join("mapped_site/decoupled/twin.svg"));
    assert_eq!(
        mapped.contains("hand-back"),
        handbacks(&out.join("mapped_site/decoupled/report.json")) > 0
    );
    for (file, reference) in [
        ("evidence/table1_circle.svg", "tracker"),
        ("evidence/section6_wheelbase.svg", "true path"),
    ] {
        assert!(read(&out.join(file)).contains(reference), "{file}");
    }
    // Runs that did not complete are in the strip, not on the time axis.
    let completion = read(&out.join("experiment/completion_time.svg"));
    assert!(completion.contains("not completed (strip above the times)"));
}

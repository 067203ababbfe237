//! The demo's figures do not mislead: every world and time figure is
//! written through the plot crate's check, which refuses a legend over
//! anything drawn and a legend entry hidden under what is drawn after it or
//! with nothing drawn, so the demo finishing is the check passing; and each
//! legend names what the run produced.

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
    // Runs that did not complete are in the strip, not on the axis: in the
    // completion times and in the contacts, for each method with such a run.
    let rows = read(&out.join("experiment/results.csv"));
    let mut not_completed: Vec<&str> = rows
        .lines()
        .skip(1)
        .filter(|l| l.split(',').nth(4) == Some("false"))
        .filter_map(|l| l.split(',').next())
        .collect();
    not_completed.dedup();
    // Direct operation at 2 s one way does not finish: without such a run
    // this part would check nothing.
    assert!(!not_completed.is_empty(), "every run completed: {rows}");
    for file in ["completion_time.svg", "collisions.svg"] {
        let svg = read(&out.join("experiment").join(file));
        for method in &not_completed {
            let entry = format!("{method}: not completed (strip above the axis)");
            assert!(svg.contains(&entry), "{file} lacks {entry}");
        }
    }
    assert!(read(&out.join("experiment/collisions.svg")).contains("contacts per completed run"));
}

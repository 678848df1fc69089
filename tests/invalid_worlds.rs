//! Every file under tests/invalid_worlds/ is a world a person could plausibly write wrong. Each
//! must be rejected with an error that names the file and says what is wrong: its first line
//! `# expect-error: TEXT` gives a substring the message must contain.

use std::path::PathBuf;

use ftcbf_sim::world::World;

#[test]
fn every_invalid_world_is_rejected_with_a_helpful_message() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/invalid_worlds");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .expect("tests/invalid_worlds exists")
        .map(|e| e.expect("readable entry").path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    files.sort();
    assert!(
        files.len() >= 25,
        "the catalogue has {} worlds, expected at least 25",
        files.len()
    );
    let mut problems = Vec::new();
    for f in &files {
        let text = std::fs::read_to_string(f).expect("readable");
        let expect = text
            .lines()
            .next()
            .and_then(|l| l.strip_prefix("# expect-error: "))
            .unwrap_or_else(|| panic!("{}: first line must be `# expect-error: TEXT`", f.display()))
            .to_string();
        match World::load(f, &[]) {
            Ok(_) => problems.push(format!(
                "{}: accepted, expected an error containing {expect:?}",
                f.display()
            )),
            Err(e) => {
                let msg = e.to_string();
                let name = f.file_name().and_then(|n| n.to_str()).unwrap_or_default();
                if !msg.contains(&expect) {
                    problems.push(format!(
                        "{name}: message {msg:?} does not contain {expect:?}"
                    ));
                }
                if !msg.contains(name) {
                    problems.push(format!("{name}: message {msg:?} does not name the file"));
                }
            }
        }
    }
    assert!(
        problems.is_empty(),
        "{} problem(s):\n{}",
        problems.len(),
        problems.join("\n")
    );
}

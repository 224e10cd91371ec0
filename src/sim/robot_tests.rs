//! Unit tests of a robot's code: what it may reach, and what it reports and widens.

#[test]
fn robot_code_cannot_reach_the_field_truth() {
    // The boundary is structural: a tick gets `Percepts` and its own clock, never the
    // simulator's world. This keeps a future change from quietly reaching for it.
    let code: String = include_str!("robot.rs")
        .lines()
        .filter(|l| !l.trim_start().starts_with("//"))
        .collect::<Vec<_>>()
        .join("\n");
    let words: Vec<&str> = code
        .split(|c: char| !(c.is_alphanumeric() || c == '_'))
        .collect();
    let world = concat!("Wor", "ld");
    assert!(
        !words.contains(&world),
        "robot.rs names `{world}` outside its docs: robot code must not see the truth"
    );
    let w = concat!("wor", "ld");
    for reach in [" {w}.", "({w}.", "&{w}.", "mut {w}"].map(|p| p.replace("{w}", w)) {
        assert!(
            !code.contains(reach.as_str()),
            "robot.rs reaches into a world value: `{reach}`"
        );
    }
}

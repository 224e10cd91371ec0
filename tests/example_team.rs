//! `examples/team.rs` runs as a test: two sessions on a scratch group on loopback, the
//! value replicated, its change streamed, robot 2 seen joining and leaving.

#[path = "../examples/team.rs"]
mod team;

#[test]
fn the_team_example_runs_on_a_multi_threaded_runtime() {
    if let Err(e) = team::main() {
        panic!("examples/team.rs failed: {e}");
    }
}

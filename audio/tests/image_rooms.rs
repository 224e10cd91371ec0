//! Rooms nobody on the decoder tuned on: pyroomacoustics image-source rooms (a lab and a
//! hall, T60 0.5 s measured on their own impulse responses) and espeak-ng talkers reading
//! with the pauses between sentences kept as digital silence, built by
//! `audio/rooms/make_rooms.py` (seed 7; the decoder's mix floor was chosen on this set and
//! on seed 1, so these are regression stories, not the report: `huddle audio rooms` on
//! seed 2 is, see audio/rooms/README.md). Skipped with a message where python3, pyroomacoustics or espeak-ng are missing
//! (scripts/install-rooms.sh installs them; `.ci/run` calls it).

use std::path::PathBuf;
use std::process::Command;
use std::sync::OnceLock;

use audio::evaluation::{load_room_set, run_scene_false_alarm_trial, run_scene_trial};
use audio::evaluation::{RoomSet, SceneTrial};

/// The room set, built once per test binary; `None` (and why, printed) where the tools
/// are missing.
fn room_set() -> Option<&'static RoomSet> {
    static SET: OnceLock<Option<RoomSet>> = OnceLock::new();
    SET.get_or_init(|| {
        let have = |cmd: &str, args: &[&str]| {
            Command::new(cmd)
                .args(args)
                .output()
                .is_ok_and(|o| o.status.success())
        };
        if !have("espeak-ng", &["--version"])
            || !have("python3", &["-c", "import numpy, scipy, pyroomacoustics"])
        {
            eprintln!(
                "SKIPPED: needs espeak-ng and python3 with numpy, scipy, pyroomacoustics \
                 (bash scripts/install-rooms.sh)"
            );
            return None;
        }
        let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("image-rooms-seed7");
        if load_room_set(&dir).is_err() {
            let script = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("rooms/make_rooms.py");
            let status = Command::new("python3")
                .arg(script)
                .args(["--out", dir.to_str().expect("utf-8 path")])
                .args(["--seed", "7", "--t60", "0,0.5", "--senders", "3"])
                .args(["--talkers", "4", "--babble-tracks", "4"])
                .args(["--babble-seconds", "40"])
                .status()
                .expect("python3 runs");
            assert!(status.success(), "make_rooms.py failed: {status}");
        }
        Some(load_room_set(&dir).expect("the room set just built reads back"))
    })
    .as_ref()
}

fn trial(seed: u64, snr_db: Option<f64>, talkers: usize, messages: usize) -> SceneTrial {
    SceneTrial {
        seed,
        snr_db,
        talkers,
        messages,
        long_share: 0.0,
        two_senders: false,
        max_clock_error: 0.005,
        team: audio::TeamPlan::Three,
    }
}

#[test]
fn short_messages_hold_over_talkers_who_pause_into_digital_silence() {
    // Before the floor was held to the mix, two talkers 20 dB under the message in a free
    // field lost about 3 messages in 10 (the floor dropped to nothing in every pause).
    let Some(set) = room_set() else { return };
    for room in &set.rooms {
        for (snr, talkers) in [(20.0, 2), (10.0, 3)] {
            let out = run_scene_trial(room, &set.babble, &trial(71, Some(snr), talkers, 60))
                .expect("trial runs");
            assert_eq!(
                out.wrong, 0,
                "{} at {snr} dB: {:?}",
                room.name, out.wrong_reports
            );
            assert!(
                out.correct_share() >= 0.95,
                "{} at {snr} dB, {talkers} talkers: {}/{} decoded, missed {:?}",
                room.name,
                out.correct,
                out.sent,
                out.missed
            );
        }
    }
}

/// Long messages in the image-source rooms, quiet and at 0 dB of talking babble: under the
/// checked plan (`audio::TeamPlan::Checked`, the format #33 asked for: a long message's
/// frames use other data basics than a short message) nothing comes out wrong, whatever
/// frame the room or the babble takes. Under the seed's plan every frame of a long message
/// is also a valid short one, and a long message whose first frame is lost outright reads
/// as a short: at the babble's true 0 dB (since the rooms' SNR calibration was mended in
/// round 14) room set 7's lab-0.5, seed 72, has one, long (RightAttacker, 257) heard as
/// short 5 at its second frame, with the first frame's sender basic one tone of three
/// under the babble. No end test can rule that out, which is why the checked plan exists;
/// the seed's plan is held to it where the room alone (no babble) is the channel.
#[test]
fn long_messages_in_image_source_rooms_are_never_cut_to_a_short() {
    let Some(set) = room_set() else { return };
    let rows = [
        (audio::TeamPlan::Checked, None),
        (audio::TeamPlan::Checked, Some(0.0)),
        (audio::TeamPlan::Three, None),
    ];
    for room in &set.rooms {
        for (team, snr) in rows {
            let mut t = trial(72, snr, 3, 40);
            t.long_share = 1.0;
            t.team = team;
            let out = run_scene_trial(room, &set.babble, &t).expect("trial runs");
            assert_eq!(
                out.wrong, 0,
                "{} ({snr:?} dB, plan {team}): a long message read as something else: {:?}",
                room.name, out.wrong_reports
            );
            // 0 dB of talking babble is the hardest row (77–95% of long messages when the
            // floor was chosen; the room alone 97–100%); what must hold everywhere is
            // that nothing comes out wrong.
            let floor = if snr.is_none() { 0.95 } else { 0.7 };
            assert!(
                out.long_correct as f64 >= floor * out.long_sent as f64,
                "{} ({snr:?} dB, plan {team}): {}/{} long messages",
                room.name,
                out.long_correct,
                out.long_sent
            );
        }
    }
}

#[test]
fn two_robots_sounding_at_once_say_nothing_wrong() {
    let Some(set) = room_set() else { return };
    for room in &set.rooms {
        let mut t = trial(73, Some(10.0), 3, 60);
        t.long_share = 0.5;
        t.two_senders = true;
        let out = run_scene_trial(room, &set.babble, &t).expect("trial runs");
        assert!(out.overlapped_sent > 10, "the row must overlap messages");
        assert_eq!(
            out.wrong, 0,
            "{}: overlapping robots decoded wrongly: {:?}",
            room.name, out.wrong_reports
        );
        assert_eq!(out.spurious, 0, "{}: reports over nothing", room.name);
    }
}

#[test]
fn a_crowd_of_eight_talkers_says_nothing() {
    let Some(set) = room_set() else { return };
    for (i, room) in set.rooms.iter().enumerate() {
        let heard = run_scene_false_alarm_trial(
            room,
            &set.babble,
            8,
            300.0,
            740 + i as u64,
            audio::TeamPlan::Checked,
        );
        assert!(heard.is_empty(), "{}: false messages {heard:?}", room.name);
    }
}

mod manifest {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        /// A room set's manifest is a file from elsewhere: whatever it holds, reading it
        /// gives a room set or an error, never a panic, and never a path outside the set.
        #[test]
        fn any_manifest_reads_or_is_refused(lines in proptest::collection::vec(
            prop_oneof![
                "[a-z ]{0,20}",
                Just("room r 1.2 1.3".to_string()),
                Just("room r nan 1".to_string()),
                Just("sender r ../../etc/passwd".to_string()),
                Just("talker r /etc/passwd".to_string()),
                Just("babble missing.wav".to_string()),
                Just("sender nowhere a.wav".to_string()),
            ],
            0..8,
        ), case in 0u64..1_000_000) {
            let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("manifest-{case}"));
            std::fs::create_dir_all(&dir).unwrap();
            std::fs::write(dir.join("manifest.txt"), lines.join("\n")).unwrap();
            let read = load_room_set(&dir);
            prop_assert!(read.is_err(), "no manifest here names readable audio: {read:?}");
            std::fs::remove_dir_all(&dir).ok();
        }
    }
}

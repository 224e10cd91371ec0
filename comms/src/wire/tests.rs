use super::*;
use proptest::prelude::*;

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

fn sample() -> Frame {
    Frame {
        team: 7,
        sender: 3,
        incarnation: 0x0102_0304_0506_0708,
        seq: 300,
        clock: FrameClock {
            stamp_us: 0x1234_5678,
            echo: Some(Echo {
                target: 5,
                seq16: 0x0102,
                hold_10us: 0x0304,
            }),
        },
        items: vec![
            Item::Update {
                path: "ball.dist".into(),
                value: Value::Float(1.5),
                version: 2,
                age_us: 1000,
            },
            Item::Update {
                path: "mode".into(),
                value: Value::Int(-2),
                version: 1,
                age_us: 0,
            },
            Item::Talk {
                queue: "plan".into(),
                seq: 1,
                value: Value::String("go".into()),
            },
            Item::TalkHead {
                queue: "plan".into(),
                first: 1,
                last: 1,
            },
            Item::Nack {
                target: 5,
                queue: "q".into(),
                first: 4,
                last: 6,
            },
            Item::Update {
                path: "v".into(),
                value: Value::Floats(vec![1.0, -2.0]),
                version: 1,
                age_us: 0,
            },
            Item::Update {
                path: "b".into(),
                value: Value::Bytes(vec![0xab]),
                version: 1,
                age_us: 0,
            },
            Item::Update {
                path: "t".into(),
                value: Value::Bool(true),
                version: 1,
                age_us: 0,
            },
        ],
    }
}

// Frozen bytes: if this test fails, the wire format changed. Bump VERSION instead of
// editing the fixture, or robots running different builds stop understanding each other.
const GOLDEN: &str = concat!(
    "4844",
    "03", // format version 3: send stamps and echoes
    "02", // flags: an echo follows the header
    "07",
    "03",
    "0807060504030201",
    "78563412", // header: send stamp 0x12345678 µs
    "05",
    "0201",
    "0403", // echo: robot 5's frame ...0x0102, held 0x0304 × 10 µs
    "fb2c01",
    "08", // seq 300, 8 items
    "00",
    "09",
    "62616c6c2e64697374",
    "01",
    "000000000000f83f",
    "02",
    "fbe803",
    "00",
    "04",
    "6d6f6465",
    "00",
    "03",
    "01",
    "00",
    "01",
    "04",
    "706c616e",
    "01",
    "03",
    "02",
    "676f",
    "02",
    "04",
    "706c616e",
    "01",
    "01",
    "03",
    "05",
    "0171",
    "04",
    "06",
    "00",
    "0176",
    "04",
    "02",
    "000000000000f03f", // Floats are f64 since format version 2
    "00000000000000c0",
    "01",
    "00",
    "00",
    "0162",
    "05",
    "01",
    "ab",
    "01",
    "00",
    "00",
    "0174",
    "02",
    "01",
    "01",
    "00",
);

#[test]
fn golden_bytes_freeze_the_format() {
    let bytes = encode_frame(&sample(), None);
    assert_eq!(hex(&bytes), GOLDEN);
    assert_eq!(decode_frame(&bytes, 7, None), Ok(sample()));
}

#[test]
fn floats_that_do_not_fit_f32_cross_the_wire_exactly() {
    let wide = vec![123_456_789.123, 1e-50, -1e300, f64::MIN_POSITIVE, 0.1];
    assert!(
        wide.iter().all(|&x| f64::from(x as f32) != x),
        "none fits f32"
    );
    let frame = Frame {
        items: vec![Item::Update {
            path: "f".into(),
            value: Value::Floats(wide.clone()),
            version: 1,
            age_us: 0,
        }],
        ..sample()
    };
    let bytes = encode_frame(&frame, None);
    assert_eq!(
        value_len(&Value::Floats(wide)),
        1 + 1 + 8 * 5,
        "tag, count, 8 bytes each"
    );
    let back = decode_frame(&bytes, 7, None).unwrap();
    assert_eq!(back.items[0], frame.items[0]);
}

#[test]
fn a_version_1_frame_is_refused_not_misread() {
    let mut bytes = encode_frame(&sample(), None);
    bytes[2] = 1;
    assert_eq!(
        decode_frame(&bytes, 7, None),
        Err(DecodeError::UnknownVersion(1))
    );
}

#[test]
fn golden_tag_is_truncated_hmac_sha256_over_everything_before_it() {
    let key = TeamKey::new(b"team key");
    let frame = Frame {
        items: vec![],
        clock: FrameClock {
            stamp_us: 0x1234_5678,
            echo: None,
        },
        ..sample()
    };
    let bytes = encode_frame(&frame, Some(&key));
    assert_eq!(
        hex(&bytes),
        "484403010703080706050403020178563412fb2c010099560cde6deefcc7399a0c168688ff92",
        "header with flag 1 (no echo), stamp, seq, 0 items, 16-byte tag (checked against \
         Python's hmac)"
    );
    assert_eq!(decode_frame(&bytes, 7, Some(&key)), Ok(frame));
}

// Frozen bytes for every varint width (1, 3, 5 and 9 bytes) and the zigzag of a signed
// integer: the part of the format a replacement encoder is most likely to get wrong.
const GOLDEN_VARINTS: &str = concat!(
    "4844030007030807060504030201ffffffff", // header, stamp u32::MAX, no echo
    "fdffffffffffffffff",                   // seq u64::MAX
    "04",                                   // 4 items
    "00",
    "0176",
    "00",
    "fdffffffffffffffff", // Int(i64::MIN), zigzag u64::MAX
    "fbfb00",             // version 251
    "fc00000100",         // age 65536
    "00",
    "0177",
    "00",
    "01",         // Int(-1), zigzag 1
    "fcffffffff", // version u32::MAX
    "fbffff",     // age 65535
    "01",
    "0171",
    "fd0000000000000040", // seq 2^62
    "0200",               // Bool(false)
    "02",
    "0171",
    "fd0000000001000000", // first 2^32
    "fd0000000001000000", // last 2^32
);

#[test]
fn golden_bytes_freeze_every_varint_width() {
    let frame = Frame {
        seq: u64::MAX,
        clock: FrameClock {
            stamp_us: u32::MAX,
            echo: None,
        },
        items: vec![
            Item::Update {
                path: "v".into(),
                value: Value::Int(i64::MIN),
                version: 251,
                age_us: 65_536,
            },
            Item::Update {
                path: "w".into(),
                value: Value::Int(-1),
                version: u64::from(u32::MAX),
                age_us: 65_535,
            },
            Item::Talk {
                queue: "q".into(),
                seq: MAX_TALK_SEQ,
                value: Value::Bool(false),
            },
            Item::TalkHead {
                queue: "q".into(),
                first: 1 << 32,
                last: 1 << 32,
            },
        ],
        ..sample()
    };
    let bytes = encode_frame(&frame, None);
    assert_eq!(hex(&bytes), GOLDEN_VARINTS);
    assert_eq!(decode_frame(&bytes, 7, None), Ok(frame));
}

/// A league's frame: the claim, the pass receiver and the world model under item 4
/// (known paths as one byte), frozen like [`GOLDEN`].
#[test]
fn golden_bytes_freeze_known_paths() {
    let update = |path: &str, value: Value| Item::Update {
        path: path.into(),
        value,
        version: 300,
        age_us: 7,
    };
    let frame = Frame {
        clock: FrameClock::default(),
        items: vec![
            update("machine.heuristic", Value::Floats(vec![1.0, 0.0])),
            update("machine.pass_to", Value::Int(2)),
            update("world.local", Value::Bytes(vec![0xab, 0xcd])),
            update("machine.heuristic.x", Value::Bool(true)),
        ],
        ..sample()
    };
    let mut w =
        FrameWriter::new(7, 3, frame.incarnation, frame.seq, 1200, None).with_known_paths(true);
    for item in &frame.items {
        assert!(w.push(item.as_ref()));
    }
    let bytes = w.finish();
    let body = concat!(
        "fb2c01",
        "04", // seq 300, 4 items
        "04",
        "00",
        "04",
        "02",
        "000000000000f03f",
        "0000000000000000",
        "fb2c01",
        "07",
        "04",
        "02",
        "00",
        "04",
        "fb2c01",
        "07", // Int 2, zigzag 4
        "04",
        "01",
        "05",
        "02",
        "abcd",
        "fb2c01",
        "07",
        // Not a known path (only whole paths are): as item 0.
        "00",
        "13",
        "6d616368696e652e6865757269737469632e78",
        "02",
        "01",
        "fb2c01",
        "07",
    );
    assert_eq!(hex(&bytes[HEADER_LEN..]), body);
    assert_eq!(decode_frame(&bytes, 7, None), Ok(frame.clone()));
    // The same items without known paths: item 0 throughout, each path's length and
    // text (18, 16 and 12 bytes) instead of one byte.
    let plain = encode_frame(&frame, None);
    assert_eq!(plain.len(), bytes.len() + 17 + 15 + 11);
    assert_eq!(decode_frame(&plain, 7, None), Ok(frame));
}

#[test]
fn an_unknown_known_path_index_is_malformed() {
    let mut w = FrameWriter::new(7, 3, 1, 1, 1200, None).with_known_paths(true);
    assert!(w.push(ItemRef::Update {
        path: "world.local",
        value: &Value::Int(1),
        version: 1,
        age_us: 0,
    }));
    let mut bytes = w.finish();
    // seq, count, item 4, then the index: point it past the table.
    let at = HEADER_LEN + 3;
    assert_eq!(bytes[at], 1, "world.local is index 1");
    for index in [KNOWN_PATHS.len() as u8, 250] {
        bytes[at] = index;
        assert!(
            matches!(
                decode_frame(&bytes, 7, None),
                Err(DecodeError::Malformed(_))
            ),
            "index {index} names no path"
        );
    }
}

#[test]
fn bad_frames_are_told_apart() {
    let key = TeamKey::new(b"k");
    let plain = encode_frame(&sample(), None);
    let tagged = encode_frame(&sample(), Some(&key));
    assert_eq!(
        decode_frame(&plain[..1], 7, None),
        Err(DecodeError::TooShort)
    );
    assert_eq!(
        decode_frame(&plain[..10], 7, None),
        Err(DecodeError::TooShort)
    );
    assert_eq!(
        decode_frame(b"XX0123456789abcdef", 7, None),
        Err(DecodeError::BadMagic)
    );
    let mut v2 = plain.clone();
    v2[2] = 2;
    assert_eq!(
        decode_frame(&v2, 7, None),
        Err(DecodeError::UnknownVersion(2)),
        "a version 2 frame has no send stamp: refused, not misread"
    );
    assert_eq!(
        decode_frame(&plain, 8, None),
        Err(DecodeError::OtherTeam(7))
    );
    assert_eq!(
        decode_frame(&plain, 7, Some(&key)),
        Err(DecodeError::MissingTag)
    );
    assert_eq!(
        decode_frame(&tagged, 7, None),
        Err(DecodeError::UnexpectedTag)
    );
    assert_eq!(
        decode_frame(&tagged, 7, Some(&TeamKey::new(b"other"))),
        Err(DecodeError::BadTag)
    );
    let mut flipped = tagged.clone();
    flipped[20] ^= 1;
    assert_eq!(
        decode_frame(&flipped, 7, Some(&key)),
        Err(DecodeError::BadTag)
    );
    let truncated = &plain[..plain.len() - 1];
    assert!(matches!(
        decode_frame(truncated, 7, None),
        Err(DecodeError::Malformed(_))
    ));
    let mut trailing = plain.clone();
    trailing.push(0);
    assert!(matches!(
        decode_frame(&trailing, 7, None),
        Err(DecodeError::Malformed(_))
    ));
    let mut sender0 = plain.clone();
    sender0[5] = 0;
    assert!(matches!(
        decode_frame(&sender0, 7, None),
        Err(DecodeError::Malformed(_))
    ));
    let huge = vec![0u8; MAX_FRAME_LEN + 1];
    assert_eq!(decode_frame(&huge, 7, None), Err(DecodeError::Oversized));
}

#[test]
fn a_bad_path_or_a_huge_claimed_length_is_malformed_not_a_panic_or_an_allocation() {
    let mut w = FrameWriter::new(7, 3, 1, 1, 1200, None);
    w.push(ItemRef::Update {
        path: "a..b",
        value: &Value::Int(1),
        version: 1,
        age_us: 0,
    });
    assert!(matches!(
        decode_frame(&w.finish(), 7, None),
        Err(DecodeError::Malformed(_))
    ));
    // seq 1, then a claimed item count of 2^62.
    let mut bytes = encode_frame(
        &Frame {
            items: vec![],
            clock: FrameClock::default(),
            ..sample()
        },
        None,
    );
    bytes.truncate(HEADER_LEN);
    bytes.extend_from_slice(&[1, 0xfd, 0, 0, 0, 0, 0, 0, 0, 0x40]);
    assert!(matches!(
        decode_frame(&bytes, 7, None),
        Err(DecodeError::Malformed(_))
    ));
}

#[test]
fn the_writer_never_exceeds_its_budget() {
    let value = Value::Bytes(vec![1; 100]);
    let mut w = FrameWriter::new(7, 3, 1, 1, 400, None);
    let mut pushed = 0;
    while w.push(ItemRef::Update {
        path: "x",
        value: &value,
        version: 1,
        age_us: 1,
    }) {
        pushed += 1;
    }
    let len = w.len();
    let bytes = w.finish();
    assert_eq!(bytes.len(), len, "len() predicts the finished size");
    assert!(
        bytes.len() <= 400 && bytes.len() > 400 - 110,
        "{} bytes",
        bytes.len()
    );
    assert_eq!(pushed, 3);
}

fn any_value() -> impl Strategy<Value = Value> {
    prop_oneof![
        any::<i64>().prop_map(Value::Int),
        any::<f64>()
            .prop_filter("NaN is never equal", |x| !x.is_nan())
            .prop_map(Value::Float),
        any::<bool>().prop_map(Value::Bool),
        ".{0,12}".prop_map(Value::String),
        proptest::collection::vec(-1e6f64..1e6, 0..6).prop_map(Value::Floats),
        proptest::collection::vec(any::<u8>(), 0..48).prop_map(Value::Bytes),
    ]
}

fn any_path() -> impl Strategy<Value = String> {
    prop_oneof![
        3 => "[a-z0-9_-]{1,8}(\\.[a-z0-9_-]{1,8}){0,2}".boxed(),
        1 => proptest::sample::select(&KNOWN_PATHS[..]).prop_map(str::to_owned).boxed(),
    ]
}

pub(crate) fn any_item() -> impl Strategy<Value = Item> {
    prop_oneof![
        (any_path(), any_value(), any::<u64>(), any::<u64>()).prop_map(
            |(path, value, version, age_us)| Item::Update {
                path,
                value,
                version,
                age_us
            }
        ),
        (any_path(), 1..=MAX_TALK_SEQ, any_value()).prop_map(|(queue, seq, value)| Item::Talk {
            queue,
            seq,
            value
        }),
        (any_path(), 1..MAX_TALK_SEQ / 2, 0..1000u64).prop_map(|(queue, first, n)| {
            Item::TalkHead {
                queue,
                first,
                last: first - 1 + n,
            }
        }),
        (1..=254u8, any_path(), 1..MAX_TALK_SEQ / 2, 0..1000u64).prop_map(
            |(target, queue, first, n)| Item::Nack {
                target,
                queue,
                first,
                last: first + n
            }
        ),
    ]
}

pub(crate) fn any_frame() -> impl Strategy<Value = Frame> {
    (
        any::<u8>(),
        1..=254u8,
        any::<u64>(),
        any::<u64>(),
        any_clock(),
        proptest::collection::vec(any_item(), 0..8),
    )
        .prop_map(|(team, sender, incarnation, seq, clock, items)| Frame {
            team,
            sender,
            incarnation,
            seq,
            clock,
            items,
        })
}

fn any_clock() -> impl Strategy<Value = FrameClock> {
    let echo =
        (1..=254u8, any::<u16>(), any::<u16>()).prop_map(|(target, seq16, hold_10us)| Echo {
            target,
            seq16,
            hold_10us,
        });
    (any::<u32>(), proptest::option::of(echo))
        .prop_map(|(stamp_us, echo)| FrameClock { stamp_us, echo })
}

proptest! {
    #[test]
    fn decode_inverts_encode_for_any_frame(frame in any_frame(), keyed in any::<bool>(), known in any::<bool>()) {
        let key = TeamKey::new(b"secret");
        let key = keyed.then_some(&key);
        let mut w = FrameWriter::new(frame.team, frame.sender, frame.incarnation, frame.seq, usize::MAX, key)
            .with_known_paths(known);
        w.set_clock(frame.clock);
        for item in &frame.items {
            prop_assert!(w.push(item.as_ref()));
        }
        let len = w.len();
        let bytes = w.finish();
        prop_assert_eq!(bytes.len(), len);
        if !known {
            prop_assert_eq!(&bytes, &encode_frame(&frame, key));
        }
        prop_assert_eq!(decode_frame(&bytes, frame.team, key), Ok(frame));
    }

    #[test]
    fn computed_item_sizes_match_the_encoder(item in any_item(), known in any::<bool>()) {
        let mut sink = Vec::new();
        prop_assert!(super::codec::encode_item(item.as_ref(), known, &mut sink));
        prop_assert_eq!(item_len_coded(item.as_ref(), known), sink.len());
        if !known {
            prop_assert_eq!(item_len(item.as_ref()), sink.len());
        }
    }

    #[test]
    fn an_echo_names_a_robot_and_fits_before_the_body(frame in any_frame(), target in prop_oneof![Just(0u8), Just(255u8)], cut in 0..ECHO_LEN) {
        let with_echo = Frame {
            clock: FrameClock {
                echo: Some(Echo { target: 1, seq16: 2, hold_10us: 3 }),
                ..frame.clock
            },
            ..frame
        };
        let mut bytes = encode_frame(&with_echo, None);
        bytes[HEADER_LEN] = target;
        prop_assert!(matches!(
            decode_frame(&bytes, with_echo.team, None),
            Err(DecodeError::Malformed(_))
        ), "echo target {} is no robot", target);
        bytes.truncate(HEADER_LEN + cut);
        prop_assert_eq!(decode_frame(&bytes, with_echo.team, None), Err(DecodeError::TooShort));
    }

    #[test]
    fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..200)) {
        let _ = decode_frame(&bytes, 7, None);
        let _ = decode_frame(&bytes, 7, Some(&TeamKey::new(b"k")));
    }

    #[test]
    fn corrupted_frames_never_panic(frame in any_frame(), at in any::<usize>(), byte in any::<u8>(), cut in any::<usize>()) {
        let mut bytes = encode_frame(&frame, None);
        let i = at % bytes.len();
        bytes[i] = byte;
        bytes.truncate(cut % (bytes.len() + 1));
        let _ = decode_frame(&bytes, frame.team, None);
    }
}

//! The wire format's unit tests: a fixture, typed errors, and properties over arbitrary
//! bytes and covariances.

use super::*;
use nalgebra::{Matrix2, Matrix3, Matrix4, SMatrix};
use proptest::prelude::*;

fn covers<const N: usize>(decoded: &SMatrix<f64, N, N>, original: &SMatrix<f64, N, N>) -> bool {
    let diff = decoded - original;
    let scale = original.abs().max().max(1e-12);
    nalgebra::DMatrix::from_iterator(N, N, diff.iter().copied())
        .symmetric_eigenvalues()
        .min()
        >= -1e-9 * scale
}

fn sample() -> LocalWorldModel {
    LocalWorldModel {
        t_s: 10.0,
        seq: 513,
        pose: PoseEstimate {
            mean: Vector3::new(1.234, -2.5, 3.0),
            cov: Matrix3::new(
                0.01, 0.002, 0.001, 0.002, 0.02, -0.001, 0.001, -0.001, 0.005,
            ),
        },
        ball: Some(BallEstimate {
            t_s: 10.0,
            mean: Vector4::new(0.5, 0.25, -1.5, 2.0),
            cov: Matrix4::new(
                0.004, 0.001, 0.002, 0.0, 0.001, 0.003, 0.0, 0.001, 0.002, 0.0, 0.05, 0.01, 0.0,
                0.001, 0.01, 0.04,
            ),
        }),
        ball_seen_age_s: 0.033,
        slc: 0.8,
        lbc: 0.9,
        observation: Some(FieldObservation {
            t_s: 9.95,
            position: Vector2::new(0.49, 0.2),
            cov: Matrix2::new(0.002, 0.0005, 0.0005, 0.001),
        }),
        earlier: [
            None,
            Some(FieldObservation {
                t_s: 9.87,
                position: Vector2::new(0.47, 0.21),
                cov: Matrix2::new(0.003, 0.0, 0.0, 0.002),
            }),
        ],
        kick: Some(KickReport {
            number: 2,
            kick: Kick {
                t_s: 9.96,
                speed_mps: 4.0,
                direction_rad: -2.5,
                speed_sigma_mps: 0.2,
                direction_sigma_rad: 0.08,
                contact_prob: 1.0,
            },
        }),
    }
}

#[test]
fn fixture_round_trips_within_one_quantum_and_never_shrinks_a_covariance() {
    let lwm = sample();
    let bytes = lwm.to_bytes().unwrap();
    assert_eq!(bytes.len(), 75);
    assert_eq!(
        bytes[0], 0x4b,
        "version 4, ball, observation and the seq−2 batch present"
    );
    assert_eq!(
        bytes[47] >> 4,
        15,
        "a kick the kicker is sure of: contact code 15, p = 16/16"
    );
    assert_eq!(
        &bytes[70..73],
        &[0x80 | (2 << 5) | 8, 80, 154],
        "kick: present, number 2, 40 ms old; 4.0 m/s; −2.5 rad = 154 × 2π/256"
    );
    assert_eq!(&bytes[1..3], &[0x01, 0x02], "seq 513 little-endian");
    assert_eq!(&bytes[3..5], &1234i16.to_le_bytes(), "pose x in mm");
    let back = LocalWorldModel::from_bytes(&bytes, 20.0).unwrap();
    assert_eq!(back.seq, 513);
    assert!((back.pose.mean - lwm.pose.mean).abs().max() < 1e-3);
    assert!(
        covers(&back.pose.cov, &lwm.pose.cov),
        "pose {}",
        back.pose.cov
    );
    let (b0, b1) = (lwm.ball.unwrap(), back.ball.unwrap());
    assert_eq!(b1.t_s, 20.0, "times move to the receiver's clock");
    assert!((b1.mean - b0.mean).abs().max() <= 0.0005 + 1e-12);
    assert!(covers(&b1.cov, &b0.cov), "ball {}", b1.cov);
    let (o0, o1) = (lwm.observation.unwrap(), back.observation.unwrap());
    assert!(
        (o1.t_s - 19.95).abs() < 1e-9,
        "observation age kept: {}",
        o1.t_s
    );
    assert!(covers(&o1.cov, &o0.cov));
    assert!(
        o1.cov[(0, 0)] < o0.cov[(0, 0)] * 1.01,
        "the observation σ scale is fine"
    );
    assert!((back.ball_seen_age_s - 0.033).abs() < 1e-9);
    assert_eq!(back.earlier[0], None, "an empty batch stays empty");
    let (e0, e1) = (lwm.earlier[1].unwrap(), back.earlier[1].unwrap());
    assert!((e1.t_s - 19.87).abs() < 1e-9, "repeat keeps its age");
    assert!((e1.position - e0.position).abs().max() < 1e-9);
    assert!(covers(&e1.cov, &e0.cov));
    let (k0, k1) = (lwm.kick.unwrap(), back.kick.unwrap());
    assert_eq!(k1.number, 2);
    assert!(
        (k1.kick.t_s - 19.96).abs() < 1e-9,
        "kick time {}",
        k1.kick.t_s
    );
    assert!((k1.kick.speed_mps - 4.0).abs() < 1e-9);
    assert!(
        crate::geometry::wrap_angle(k1.kick.direction_rad - k0.kick.direction_rad).abs()
            <= PI / 256.0
    );
    assert!(
        k1.kick.speed_sigma_mps >= k0.kick.speed_sigma_mps
            && k1.kick.direction_sigma_rad >= k0.kick.direction_sigma_rad,
        "a kick's σ's never shrink on the wire: {:?}",
        k1.kick
    );
}

#[test]
fn a_kick_that_cannot_be_carried_is_an_error_not_a_wrong_message() {
    let mut lwm = sample();
    let kick = |t_s: f64, speed_mps: f64| {
        Some(KickReport {
            number: 0,
            kick: Kick {
                t_s,
                speed_mps,
                direction_rad: 0.0,
                speed_sigma_mps: 0.1,
                direction_sigma_rad: 0.1,
                contact_prob: 1.0,
            },
        })
    };
    lwm.kick = kick(9.7, 4.0);
    assert_eq!(
        lwm.to_bytes(),
        Err(EncodeError::OutOfRange { field: "kick age" }),
        "300 ms is older than a report lasts"
    );
    lwm.kick = kick(9.99, 20.0);
    assert_eq!(
        lwm.to_bytes(),
        Err(EncodeError::OutOfRange {
            field: "kick speed"
        })
    );
    lwm.kick = kick(9.99, 4.0).map(|mut r| {
        r.kick.speed_sigma_mps = 500.0;
        r
    });
    assert_eq!(
        lwm.to_bytes(),
        Err(EncodeError::OutOfRange {
            field: "kick speed σ"
        }),
        "past the σ scale's top the receiver would be told less than was sent"
    );
    lwm.kick = kick(f64::NAN, 4.0);
    assert_eq!(
        lwm.to_bytes(),
        Err(EncodeError::OutOfRange { field: "kick" })
    );
    lwm.kick = None;
    let bytes = lwm.to_bytes().unwrap();
    assert_eq!(&bytes[70..], &[0; 5], "no kick: five zero bytes");
    assert_eq!(bytes[47] >> 4, 0, "and no contact bits");
    assert_eq!(LocalWorldModel::from_bytes(&bytes, 0.0).unwrap().kick, None);
}

#[test]
fn bad_length_version_and_correlations_are_typed_errors() {
    let bytes = sample().to_bytes().unwrap();
    assert_eq!(
        LocalWorldModel::from_bytes(&bytes[..74], 0.0),
        Err(DecodeError::Length {
            expected: 75,
            got: 74
        })
    );
    let mut v = bytes;
    v[0] = 0x3b;
    assert_eq!(
        LocalWorldModel::from_bytes(&v, 0.0),
        Err(DecodeError::Version { got: 3 }),
        "a version-3 sender's 75 bytes padded: refused, not misread"
    );
    let mut v = bytes;
    v[0] = 0x5b;
    assert_eq!(
        LocalWorldModel::from_bytes(&v, 0.0),
        Err(DecodeError::Version { got: 5 })
    );
    let mut v = bytes;
    v[12..15].copy_from_slice(&[127, 127, 0x81]); // ρxy = 1, ρxθ = 1, ρyθ = −1
    assert_eq!(
        LocalWorldModel::from_bytes(&v, 0.0),
        Err(DecodeError::NotPositiveDefinite { field: "pose" })
    );
}

fn spd<const N: usize>(entries: &[f64], scale: f64) -> SMatrix<f64, N, N> {
    let a = SMatrix::<f64, N, N>::from_fn(|i, j| entries[(i * N + j) % entries.len()]);
    (a * a.transpose()) * scale + SMatrix::<f64, N, N>::identity() * 1e-8
}

proptest! {
    #[test]
    fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..96)) {
        let _ = LocalWorldModel::from_bytes(&bytes, 1.0);
    }

    #[test]
    fn any_75_bytes_decode_to_finite_pd_covariances_or_an_error(mut bytes in proptest::array::uniform32(any::<u8>()), tail in proptest::array::uniform32(any::<u8>()), end in proptest::array::uniform16(any::<u8>()), flags in 0u8..16) {
        let mut all = [0u8; LWM_WIRE_LEN];
        bytes[0] = 0x40 | flags;
        all[..32].copy_from_slice(&bytes);
        all[32..64].copy_from_slice(&tail);
        all[64..].copy_from_slice(&end[..11]);
        if let Ok(lwm) = LocalWorldModel::from_bytes(&all, 1.0) {
            if let Some(k) = lwm.kick {
                prop_assert!(k.kick.is_valid() && k.kick.t_s <= 1.0 && k.number < 4, "{:?}", k);
            }
            prop_assert!(lwm.pose.cov.cholesky().is_some());
            if let Some(b) = lwm.ball { prop_assert!(b.cov.cholesky().is_some() && b.mean.iter().all(|v| v.is_finite())); }
            for o in lwm.observation.iter().chain(lwm.earlier.iter().flatten()) { prop_assert!(o.cov.cholesky().is_some()); }
        }
    }

    #[test]
    fn encoding_never_makes_the_receiver_more_confident(
        e in proptest::collection::vec(-1.0f64..1.0, 16),
        scale in 1e-6f64..10.0,
        x in -30.0f64..30.0, y in -30.0f64..30.0, th in -10.0f64..10.0,
        v in -20.0f64..20.0, age in 0.0f64..1.0,
    ) {
        let lwm = LocalWorldModel {
            t_s: 5.0,
            seq: 7,
            pose: PoseEstimate { mean: Vector3::new(x, y, th), cov: spd::<3>(&e, scale) },
            ball: Some(BallEstimate { t_s: 5.0, mean: Vector4::new(y, x, v, -v), cov: spd::<4>(&e[3..], scale) }),
            ball_seen_age_s: age,
            slc: 0.5,
            lbc: 0.5,
            observation: Some(FieldObservation { t_s: 5.0 - age, position: Vector2::new(x, y), cov: spd::<2>(&e[7..], scale) }),
            earlier: [Some(FieldObservation { t_s: 4.9 - age, position: Vector2::new(y, x), cov: spd::<2>(&e[9..], scale) }), None],
            kick: Some(KickReport { number: 1, kick: Kick { t_s: 5.0 - age * 0.15, speed_mps: v.abs() / 2.0, direction_rad: th, speed_sigma_mps: scale.sqrt(), direction_sigma_rad: scale.sqrt(), contact_prob: 1.0 } }),
        };
        let back = LocalWorldModel::from_bytes(&lwm.to_bytes().unwrap(), 5.0).unwrap();
        prop_assert!(covers(&back.pose.cov, &lwm.pose.cov));
        prop_assert!(covers(&back.ball.unwrap().cov, &lwm.ball.unwrap().cov));
        prop_assert!(covers(&back.observation.unwrap().cov, &lwm.observation.unwrap().cov));
        prop_assert!(covers(&back.earlier[0].unwrap().cov, &lwm.earlier[0].unwrap().cov));
        prop_assert!((crate::geometry::wrap_angle(back.pose.mean.z - th)).abs() < 1e-4);
        let (k0, k1) = (lwm.kick.unwrap().kick, back.kick.unwrap().kick);
        prop_assert!(k1.speed_sigma_mps >= k0.speed_sigma_mps.min(100.0) && k1.direction_sigma_rad >= k0.direction_sigma_rad.min(100.0));
        prop_assert!((k1.t_s - k0.t_s).abs() <= 0.0025 + 1e-9);
    }
}

#[test]
fn the_compact_form_is_the_snapshot_and_the_kick_without_batches() {
    let lwm = sample();
    let full = lwm.to_bytes().unwrap();
    let compact = lwm.to_compact_bytes().unwrap();
    assert_eq!(compact.len(), 43);
    assert_eq!(compact[0], 0x51, "version 5, ball present, no batch flags");
    assert_eq!(&compact[1..37], &full[1..37], "the snapshot, byte for byte");
    assert_eq!(&compact[37..42], &full[70..75], "the kick block");
    assert_eq!(compact[42], 0xf0, "contact code 15 in the high nibble");
    let back = LocalWorldModel::from_bytes(&compact, 20.0).unwrap();
    let expected = LocalWorldModel::from_bytes(&full, 20.0).unwrap();
    assert_eq!(
        back,
        LocalWorldModel {
            observation: None,
            earlier: [None; 2],
            ..expected
        },
        "decodes to the full form less its batches"
    );
    assert_eq!(back.kick.unwrap().kick.contact_prob, 1.0);
}

#[test]
fn a_compact_message_with_bits_its_form_does_not_have_is_refused() {
    let compact = sample().to_compact_bytes().unwrap();
    let mut v = compact;
    v[0] |= 0x02;
    assert_eq!(
        LocalWorldModel::from_bytes(&v, 0.0),
        Err(DecodeError::Compact),
        "a batch flag with no batch to read"
    );
    let mut v = compact;
    v[42] |= 0x01;
    assert_eq!(
        LocalWorldModel::from_bytes(&v, 0.0),
        Err(DecodeError::Compact)
    );
    let mut v = compact;
    v[0] = 0x41;
    assert_eq!(
        LocalWorldModel::from_bytes(&v, 0.0),
        Err(DecodeError::Version { got: 4 }),
        "43 bytes are version 5 or nothing"
    );
}

proptest! {
    #[test]
    fn any_43_bytes_decode_to_finite_pd_covariances_or_an_error(head in proptest::array::uniform32(any::<u8>()), tail in proptest::array::uniform11(any::<u8>())) {
        let mut all = [0u8; LWM_COMPACT_LEN];
        all[..32].copy_from_slice(&head);
        all[32..].copy_from_slice(&tail);
        all[0] = 0x50 | (head[0] & 1);
        all[42] &= 0xf0;
        if let Ok(lwm) = LocalWorldModel::from_bytes(&all, 1.0) {
            prop_assert!(lwm.observation.is_none() && lwm.earlier == [None; 2]);
            prop_assert!(lwm.pose.cov.cholesky().is_some());
            if let Some(b) = lwm.ball { prop_assert!(b.cov.cholesky().is_some() && b.mean.iter().all(|v| v.is_finite())); }
        }
    }
}

/// Every float of an LWM, bit for bit (`Debug` prints the shortest form that reads back
/// as the same bits, and tells −0 from 0).
fn bits(lwm: &LocalWorldModel) -> String {
    format!("{lwm:?}")
}

#[test]
fn a_retimed_lwm_is_its_bytes_decoded_at_the_other_time_bit_for_bit() {
    // The simulator's delivery reference places a teammate's message at its true send
    // time, which the robot's GWM (decoding it first) does not know: it takes the GWM's
    // decoded LWM retimed, and must hold what decoding again would give. Shifting every
    // time by the difference would not do: 12345.678 − 0.987 + (0.1 − 12345.678) is not
    // 0.1 − 0.987 in floating point.
    let full = sample().to_bytes().expect("the fixture encodes");
    let compact = sample().to_compact_bytes().expect("the fixture encodes");
    for bytes in [&full[..], &compact[..]] {
        let first = LocalWorldModel::from_bytes(bytes, 12345.678).expect("decodes");
        for t_s in [0.1, -3.3, 12345.678, 1e6 / 3.0] {
            let again = LocalWorldModel::from_bytes(bytes, t_s).expect("decodes");
            let retimed = first.retimed(bytes, t_s).expect("the same bytes");
            assert_eq!(
                bits(&retimed),
                bits(&again),
                "{} bytes at {t_s} s",
                bytes.len()
            );
        }
    }
    let decoded = LocalWorldModel::from_bytes(&full, 1.0).expect("decodes");
    assert!(
        decoded.earlier[1].is_some() && decoded.kick.is_some(),
        "the fixture exercises the batches and the kick"
    );
    assert_eq!(
        decoded.retimed(&full[..40], 2.0),
        None,
        "not an LWM's length"
    );
    assert_eq!(
        decoded.retimed(&compact, 2.0),
        None,
        "a compact message has no batches for this one's"
    );
}

proptest! {
    #[test]
    fn any_lwm_retimed_is_what_decoding_at_that_time_gives(mut bytes in proptest::array::uniform32(any::<u8>()), tail in proptest::array::uniform32(any::<u8>()), end in proptest::array::uniform16(any::<u8>()), flags in 0u8..16, compact in any::<bool>(), t1 in -1e5f64..1e5, t2 in -1e5f64..1e5) {
        let mut all = [0u8; LWM_WIRE_LEN];
        bytes[0] = 0x40 | flags;
        all[..32].copy_from_slice(&bytes);
        all[32..64].copy_from_slice(&tail);
        all[64..].copy_from_slice(&end[..11]);
        // Correlations of zero, so that most draws decode (random ones rarely do).
        for at in [12, 13, 14, 27, 28, 29, 30, 31, 32, 45, 56, 67] {
            all[at] = 0;
        }
        let message: Vec<u8> = if compact {
            let Ok(lwm) = LocalWorldModel::from_bytes(&all, 0.0) else { return Ok(()) };
            let Ok(c) = lwm.to_compact_bytes() else { return Ok(()) };
            c.to_vec()
        } else {
            all.to_vec()
        };
        if let Ok(first) = LocalWorldModel::from_bytes(&message, t1) {
            let again = LocalWorldModel::from_bytes(&message, t2).expect("errors do not depend on the time");
            let retimed = first.retimed(&message, t2).expect("the same bytes");
            prop_assert_eq!(bits(&retimed), bits(&again));
        }
    }
}

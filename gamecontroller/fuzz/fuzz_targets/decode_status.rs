//! RGrt (robot → GameController) on arbitrary bytes: the decoder never panics; whatever
//! decodes re-encodes to bytes that decode again to the same (an infinite float is sent
//! as the largest finite one, so those bytes may differ from the input; nothing else).
#![no_main]

use gamecontroller::StatusMessage;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(m) = StatusMessage::decode(data) {
        let bytes = m.encode();
        let again = StatusMessage::decode(&bytes).expect("its own bytes decode");
        assert_eq!(again.encode(), bytes, "encoding is stable");
        if m.pose
            .iter()
            .chain(&m.ball)
            .chain([&m.ball_age])
            .all(|v| v.is_finite())
        {
            assert_eq!(&bytes[..], data, "finite values re-encode to their bytes");
        }
    }
});

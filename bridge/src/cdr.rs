//! ROS 2 messages in CDR, for `--ros2`: each huddle value type as the `std_msgs`
//! message that carries it, encoded as rmw does (XCDR1, little endian, the 4-byte
//! encapsulation header `00 01 00 00`, alignment counted from after the header).
//!
//! | huddle type | ROS 2 type                      |
//! |-------------|---------------------------------|
//! | `int`       | `std_msgs/msg/Int64`            |
//! | `float`     | `std_msgs/msg/Float64`          |
//! | `bool`      | `std_msgs/msg/Bool`             |
//! | `string`    | `std_msgs/msg/String`           |
//! | `floats`    | `std_msgs/msg/Float64MultiArray` (no `layout.dim`, `data_offset` 0) |
//! | `bytes`     | `std_msgs/msg/UInt8MultiArray`  (no `layout.dim`, `data_offset` 0)  |
//!
//! `tests/cdr_reference.rs` checks these bytes against pycdr2's encoder.

use comms::Value;

/// The ROS 2 type name (`std_msgs/msg/Float64`) of the message for `value`.
pub fn ros2_type(value: &Value) -> &'static str {
    match value {
        Value::Int(_) => "std_msgs/msg/Int64",
        Value::Float(_) => "std_msgs/msg/Float64",
        Value::Bool(_) => "std_msgs/msg/Bool",
        Value::String(_) => "std_msgs/msg/String",
        Value::Floats(_) => "std_msgs/msg/Float64MultiArray",
        Value::Bytes(_) => "std_msgs/msg/UInt8MultiArray",
    }
}

/// The DDS type name of [`ros2_type`] (`std_msgs::msg::dds_::Float64_`), as
/// zenoh-bridge-ros2dds announces it.
pub fn dds_type(value: &Value) -> String {
    let ros = ros2_type(value);
    let (package, name) = ros.split_once("/msg/").unwrap_or(("std_msgs", ros));
    format!("{package}::msg::dds_::{name}_")
}

/// `value` as its `std_msgs` message in CDR.
pub fn encode(value: &Value) -> Vec<u8> {
    let mut w = Writer::new();
    match value {
        Value::Int(i) => w.i64(*i),
        Value::Float(f) => w.f64(*f),
        Value::Bool(b) => w.u8(u8::from(*b)),
        Value::String(s) => w.string(s),
        Value::Floats(v) => {
            w.empty_layout();
            w.u32(len_u32(v.len()));
            for x in v {
                w.f64(*x);
            }
        }
        Value::Bytes(b) => {
            w.empty_layout();
            w.u32(len_u32(b.len()));
            w.buf.extend_from_slice(b);
        }
    }
    w.buf
}

/// A huddle value fits a frame (well under 4 GiB); saturate rather than wrap anyway.
fn len_u32(n: usize) -> u32 {
    u32::try_from(n).unwrap_or(u32::MAX)
}

/// Little-endian CDR writer; alignment is relative to the end of the 4-byte header.
struct Writer {
    buf: Vec<u8>,
}

const HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

impl Writer {
    fn new() -> Writer {
        let mut buf = Vec::with_capacity(32);
        buf.extend_from_slice(&HEADER);
        Writer { buf }
    }

    fn align(&mut self, n: usize) {
        let offset = self.buf.len() - HEADER.len();
        let pad = (n - offset % n) % n;
        self.buf.resize(self.buf.len() + pad, 0);
    }

    fn u8(&mut self, x: u8) {
        self.buf.push(x);
    }

    fn u32(&mut self, x: u32) {
        self.align(4);
        self.buf.extend_from_slice(&x.to_le_bytes());
    }

    fn i64(&mut self, x: i64) {
        self.align(8);
        self.buf.extend_from_slice(&x.to_le_bytes());
    }

    fn f64(&mut self, x: f64) {
        self.align(8);
        self.buf.extend_from_slice(&x.to_le_bytes());
    }

    /// A string: its length with the terminating NUL, its bytes, the NUL.
    fn string(&mut self, s: &str) {
        self.u32(len_u32(s.len() + 1));
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
    }

    /// `std_msgs/MultiArrayLayout` with no dimensions and `data_offset` 0.
    fn empty_layout(&mut self) {
        self.u32(0); // dim: sequence of 0 MultiArrayDimension
        self.u32(0); // data_offset
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn float64_is_the_header_then_eight_bytes() {
        assert_eq!(
            encode(&Value::Float(2.5)),
            [0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 4, 64],
            "2.5 = 0x4004000000000000 little endian"
        );
    }

    #[test]
    fn string_counts_its_nul() {
        assert_eq!(
            encode(&Value::from("hi")),
            [0, 1, 0, 0, 3, 0, 0, 0, b'h', b'i', 0]
        );
    }

    #[test]
    fn float_array_data_is_aligned_to_eight() {
        let bytes = encode(&Value::Floats(vec![1.0]));
        // dim count, data_offset, data length, 4 bytes of padding, one f64.
        assert_eq!(bytes.len(), 4 + 4 + 4 + 4 + 4 + 8);
        assert_eq!(&bytes[12..16], &[1, 0, 0, 0], "one element");
        assert_eq!(
            &bytes[16..20],
            &[0, 0, 0, 0],
            "padding to 8 after the header"
        );
        assert_eq!(&bytes[20..], &1.0f64.to_le_bytes());
    }

    #[test]
    fn type_names() {
        assert_eq!(dds_type(&Value::Bool(true)), "std_msgs::msg::dds_::Bool_");
        assert_eq!(
            ros2_type(&Value::Bytes(vec![])),
            "std_msgs/msg/UInt8MultiArray"
        );
    }
}

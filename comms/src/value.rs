//! Blackboard values and their type names.

use std::fmt;
use std::str::FromStr;

use thiserror::Error;

/// A value bound to a key: the seed's four scalar types plus a float vector and bytes
/// for structured data (a world model, a path).
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    /// A signed 64-bit integer. Literal: `42`, `-1`.
    Int(i64),
    /// A 64-bit float. Literal: `4.2`, `1e-3`, `-0.0`, `inf`, `NaN`.
    Float(f64),
    /// A boolean. Literal: `true`, `false`.
    Bool(bool),
    /// UTF-8 text. Literal: `"text"` with `\"`, `\\`, `\n`, `\r`, `\t`, `\u{..}` escapes.
    String(String),
    /// A vector of 64-bit floats, kept exactly as set (8 bytes per element on the wire).
    /// Literal: `[1.5, 2, -3e-2]`.
    Floats(Vec<f64>),
    /// Opaque bytes (e.g. an encoded world model). Literal: `0x0a0b` (lowercase hex out,
    /// either case in; `0x` is empty).
    Bytes(Vec<u8>),
}

/// The type of a [`Value`], named as in the relay protocol.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum ValueType {
    /// `int`
    Int,
    /// `float`
    Float,
    /// `bool`
    Bool,
    /// `string`
    String,
    /// `floats`
    Floats,
    /// `bytes`
    Bytes,
}

/// A type name that is not one of `int|float|bool|string|floats|bytes`.
#[derive(Clone, Debug, PartialEq, Eq, Error)]
#[error("unknown type {0:?}: expected int, float, bool, string, floats or bytes")]
pub struct UnknownType(pub String);

impl ValueType {
    /// Every type, in wire-tag order.
    pub const ALL: [ValueType; 6] = [
        ValueType::Int,
        ValueType::Float,
        ValueType::Bool,
        ValueType::String,
        ValueType::Floats,
        ValueType::Bytes,
    ];

    /// The relay protocol's name for this type.
    pub fn name(self) -> &'static str {
        match self {
            ValueType::Int => "int",
            ValueType::Float => "float",
            ValueType::Bool => "bool",
            ValueType::String => "string",
            ValueType::Floats => "floats",
            ValueType::Bytes => "bytes",
        }
    }
}

impl fmt::Display for ValueType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for ValueType {
    type Err = UnknownType;
    fn from_str(s: &str) -> Result<ValueType, UnknownType> {
        ValueType::ALL
            .into_iter()
            .find(|t| t.name() == s)
            .ok_or_else(|| UnknownType(s.to_owned()))
    }
}

impl Value {
    /// This value's type.
    pub fn value_type(&self) -> ValueType {
        match self {
            Value::Int(_) => ValueType::Int,
            Value::Float(_) => ValueType::Float,
            Value::Bool(_) => ValueType::Bool,
            Value::String(_) => ValueType::String,
            Value::Floats(_) => ValueType::Floats,
            Value::Bytes(_) => ValueType::Bytes,
        }
    }

    /// Equality for "did the value change?": floats compare by bits (so `0.0` and
    /// `-0.0` differ) except that every NaN is the same as every other NaN.
    pub fn same_as(&self, other: &Value) -> bool {
        fn same64(a: f64, b: f64) -> bool {
            (a.is_nan() && b.is_nan()) || a.to_bits() == b.to_bits()
        }
        match (self, other) {
            (Value::Float(a), Value::Float(b)) => same64(*a, *b),
            (Value::Floats(a), Value::Floats(b)) => {
                a.len() == b.len() && a.iter().zip(b).all(|(x, y)| same64(*x, *y))
            }
            _ => self == other,
        }
    }
}

impl From<i64> for Value {
    fn from(v: i64) -> Value {
        Value::Int(v)
    }
}
impl From<f64> for Value {
    fn from(v: f64) -> Value {
        Value::Float(v)
    }
}
impl From<bool> for Value {
    fn from(v: bool) -> Value {
        Value::Bool(v)
    }
}
impl From<&str> for Value {
    fn from(v: &str) -> Value {
        Value::String(v.to_owned())
    }
}
impl From<String> for Value {
    fn from(v: String) -> Value {
        Value::String(v)
    }
}
impl From<Vec<f64>> for Value {
    fn from(v: Vec<f64>) -> Value {
        Value::Floats(v)
    }
}
impl From<Vec<u8>> for Value {
    fn from(v: Vec<u8>) -> Value {
        Value::Bytes(v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn type_names_round_trip() {
        for t in ValueType::ALL {
            assert_eq!(t.name().parse::<ValueType>(), Ok(t));
        }
        assert!("integer".parse::<ValueType>().is_err());
        assert_eq!(Value::Floats(vec![1.0]).value_type().name(), "floats");
    }

    #[test]
    fn nan_is_the_same_as_itself_for_change_detection() {
        assert!(Value::Float(f64::NAN).same_as(&Value::Float(f64::NAN)));
        assert!(!Value::Float(0.0).same_as(&Value::Float(-0.0)));
        assert!(!Value::Int(1).same_as(&Value::Float(1.0)));
    }
}

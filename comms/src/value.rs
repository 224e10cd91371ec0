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

    /// The integer, if this is an [`Value::Int`].
    pub fn as_i64(&self) -> Option<i64> {
        match self {
            Value::Int(v) => Some(*v),
            _ => None,
        }
    }

    /// The number as an `f64`: a [`Value::Float`], or a [`Value::Int`] converted (a
    /// relay client's `SETV key 2` binds an int where a float was meant; the conversion
    /// rounds beyond 2^53).
    pub fn as_f64(&self) -> Option<f64> {
        match self {
            Value::Float(v) => Some(*v),
            Value::Int(v) => Some(*v as f64),
            _ => None,
        }
    }

    /// The boolean, if this is a [`Value::Bool`].
    pub fn as_bool(&self) -> Option<bool> {
        match self {
            Value::Bool(v) => Some(*v),
            _ => None,
        }
    }

    /// The text, if this is a [`Value::String`].
    pub fn as_str(&self) -> Option<&str> {
        match self {
            Value::String(v) => Some(v),
            _ => None,
        }
    }

    /// The floats, if this is a [`Value::Floats`].
    pub fn as_floats(&self) -> Option<&[f64]> {
        match self {
            Value::Floats(v) => Some(v),
            _ => None,
        }
    }

    /// The bytes, if this is a [`Value::Bytes`].
    pub fn as_bytes(&self) -> Option<&[u8]> {
        match self {
            Value::Bytes(v) => Some(v),
            _ => None,
        }
    }
}

/// A [`Value`] of another type than the one asked for (`f64::try_from(&value)`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Error)]
#[error("expected a value of type {expected}, found {found}")]
pub struct WrongType {
    /// The type asked for.
    pub expected: ValueType,
    /// The value's type.
    pub found: ValueType,
}

/// `TryFrom<&Value>` for a Rust type through one of the `as_*` accessors.
macro_rules! try_from_value {
    ($ty:ty, $expected:ident, $get:expr) => {
        impl TryFrom<&Value> for $ty {
            type Error = WrongType;

            fn try_from(value: &Value) -> Result<$ty, WrongType> {
                let get: fn(&Value) -> Option<$ty> = $get;
                get(value).ok_or(WrongType {
                    expected: ValueType::$expected,
                    found: value.value_type(),
                })
            }
        }

        impl TryFrom<Value> for $ty {
            type Error = WrongType;

            fn try_from(value: Value) -> Result<$ty, WrongType> {
                <$ty>::try_from(&value)
            }
        }
    };
}

try_from_value!(i64, Int, Value::as_i64);
try_from_value!(f64, Float, Value::as_f64);
try_from_value!(bool, Bool, Value::as_bool);
try_from_value!(String, String, |v| v.as_str().map(str::to_owned));
try_from_value!(Vec<f64>, Floats, |v| v.as_floats().map(<[f64]>::to_vec));
try_from_value!(Vec<u8>, Bytes, |v| v.as_bytes().map(<[u8]>::to_vec));

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

    #[test]
    fn typed_reads_take_their_type_and_name_the_other() {
        let ball = Value::Floats(vec![1.5, -2.0]);
        assert_eq!(Vec::<f64>::try_from(&ball), Ok(vec![1.5, -2.0]));
        assert_eq!(ball.as_floats(), Some(&[1.5, -2.0][..]));
        assert_eq!(
            f64::try_from(&ball),
            Err(WrongType {
                expected: ValueType::Float,
                found: ValueType::Floats
            }),
            "a vector is not a number"
        );
        // A relay client's `SETV x 2` binds an int: a float reader still gets its 2.0,
        // but an int reader never gets a truncated float.
        assert_eq!(f64::try_from(Value::Int(2)), Ok(2.0));
        assert_eq!(Value::Float(2.5).as_i64(), None);
        assert_eq!(bool::try_from(&Value::Bool(true)), Ok(true));
        assert_eq!(Value::from("go").as_str(), Some("go"));
        assert_eq!(String::try_from(Value::from("go")).as_deref(), Ok("go"));
        assert_eq!(Vec::<u8>::try_from(&Value::Bytes(vec![7])), Ok(vec![7]));
        let err = i64::try_from(&Value::from("7")).unwrap_err();
        assert_eq!(
            err.to_string(),
            "expected a value of type int, found string"
        );
    }
}

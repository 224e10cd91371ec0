//! The value literal syntax shared by `config.dat`, the relay line protocol and the CLI.
//!
//! | type     | literal                                 |
//! |----------|-----------------------------------------|
//! | `int`    | `42`, `-1`, `+7` (decimal, fits i64)    |
//! | `float`  | `4.2`, `1e-3`, `-0.0`, `inf`, `-inf`, `NaN` (has `.`, `e` or is a special) |
//! | `bool`   | `true`, `false`                         |
//! | `string` | `"text"`; escapes `\"` `\\` `\n` `\r` `\t` `\u{1f}` |
//! | `floats` | `[1.5, 2, -3e-2]` (each element an f64; `[]` is empty) |
//! | `bytes`  | `0x0a0b` (hex pairs; `0x` is empty)     |
//!
//! Formatting (`Value`'s `Display`) always produces a literal that parses back to the same
//! value, bit for bit (floats print their shortest round-trip form and always carry a
//! `.` or an exponent, so `1.0` never comes back as the integer `1`).

use std::fmt::{self, Write as _};

use thiserror::Error;

use crate::value::Value;

/// Why text is not a value literal.
#[derive(Clone, Debug, PartialEq, Eq, Error)]
pub enum LiteralError {
    /// Nothing (or only whitespace) where a value was expected.
    #[error("missing value")]
    Empty,
    /// A string without its closing quote.
    #[error("unterminated string")]
    UnterminatedString,
    /// A backslash escape other than `\" \\ \n \r \t \u{..}`.
    #[error("bad escape {0:?} in string")]
    BadEscape(String),
    /// A decimal integer outside i64.
    #[error("integer {0} does not fit in 64 bits")]
    IntOutOfRange(String),
    /// A token that looked numeric but is not a number.
    #[error("bad number {0:?}")]
    BadNumber(String),
    /// A `[...]` list without `]`, or with a bad separator.
    #[error("bad float list: {0}")]
    BadList(String),
    /// `0x` followed by an odd number of digits or a non-hex digit.
    #[error("bad hex bytes {0:?}")]
    BadHex(String),
    /// A word that is no literal (strings need quotes).
    #[error("unrecognised value {0:?} (strings must be \"quoted\")")]
    Unrecognized(String),
    /// A complete literal followed by more text.
    #[error("unexpected text after value: {0:?}")]
    Trailing(String),
}

/// Parses a whole literal; surrounding whitespace is ignored, anything else after the
/// value is an error.
pub fn parse_literal(s: &str) -> Result<Value, LiteralError> {
    let (value, rest) = parse_literal_prefix(s)?;
    if rest.trim().is_empty() {
        Ok(value)
    } else {
        Err(LiteralError::Trailing(rest.trim().to_owned()))
    }
}

/// Parses one literal at the start of `s` (after leading whitespace) and returns it with
/// the unparsed rest, so callers can allow trailing comments.
pub fn parse_literal_prefix(s: &str) -> Result<(Value, &str), LiteralError> {
    let s = s.trim_start();
    match s.as_bytes().first() {
        None => Err(LiteralError::Empty),
        Some(b'"') => parse_string(s),
        Some(b'[') => parse_floats(s),
        Some(_) => {
            let end = s
                .find(|c: char| c.is_whitespace() || c == ',' || c == ']' || c == '#')
                .unwrap_or(s.len());
            let (token, rest) = s.split_at(end);
            if token.is_empty() {
                return Err(LiteralError::Unrecognized(s.chars().take(16).collect()));
            }
            Ok((parse_token(token)?, rest))
        }
    }
}

fn parse_token(token: &str) -> Result<Value, LiteralError> {
    match token {
        "true" => return Ok(Value::Bool(true)),
        "false" => return Ok(Value::Bool(false)),
        _ => {}
    }
    if let Some(hex) = token
        .strip_prefix("0x")
        .or_else(|| token.strip_prefix("0X"))
    {
        return parse_hex(hex).map(Value::Bytes);
    }
    let unsigned = token.trim_start_matches(['+', '-']);
    if !unsigned.is_empty() && unsigned.bytes().all(|b| b.is_ascii_digit()) {
        if token.len() - unsigned.len() > 1 {
            return Err(LiteralError::BadNumber(token.to_owned()));
        }
        return token
            .parse::<i64>()
            .map(Value::Int)
            .map_err(|_| LiteralError::IntOutOfRange(token.to_owned()));
    }
    parse_float::<f64>(token).map(Value::Float)
}

fn parse_float<F: std::str::FromStr>(token: &str) -> Result<F, LiteralError> {
    let unsigned = token.strip_prefix(['+', '-']).unwrap_or(token);
    let special = ["inf", "nan"]
        .iter()
        .any(|s| unsigned.eq_ignore_ascii_case(s));
    let numeric = unsigned.starts_with(|c: char| c.is_ascii_digit() || c == '.');
    if !(special || numeric) {
        return Err(LiteralError::Unrecognized(token.to_owned()));
    }
    token
        .parse::<F>()
        .map_err(|_| LiteralError::BadNumber(token.to_owned()))
}

fn parse_hex(hex: &str) -> Result<Vec<u8>, LiteralError> {
    let bad = || LiteralError::BadHex(format!("0x{hex}"));
    if !hex.len().is_multiple_of(2) {
        return Err(bad());
    }
    hex.as_bytes()
        .chunks(2)
        .map(|pair| {
            let digit = |b: u8| (b as char).to_digit(16).ok_or_else(bad);
            Ok((digit(pair[0])? * 16 + digit(pair[1])?) as u8)
        })
        .collect()
}

fn parse_string(s: &str) -> Result<(Value, &str), LiteralError> {
    let mut out = String::new();
    let mut chars = s.char_indices().skip(1);
    while let Some((i, c)) = chars.next() {
        match c {
            '"' => return Ok((Value::String(out), &s[i + 1..])),
            '\\' => {
                let (_, e) = chars.next().ok_or(LiteralError::UnterminatedString)?;
                match e {
                    '"' => out.push('"'),
                    '\\' => out.push('\\'),
                    'n' => out.push('\n'),
                    'r' => out.push('\r'),
                    't' => out.push('\t'),
                    'u' => {
                        let mut code = String::new();
                        if chars.next().map(|(_, c)| c) != Some('{') {
                            return Err(LiteralError::BadEscape("\\u".into()));
                        }
                        loop {
                            match chars.next() {
                                Some((_, '}')) => break,
                                Some((_, c)) if code.len() < 6 => code.push(c),
                                _ => return Err(LiteralError::BadEscape(format!("\\u{{{code}"))),
                            }
                        }
                        let ch = u32::from_str_radix(&code, 16)
                            .ok()
                            .and_then(char::from_u32)
                            .ok_or_else(|| LiteralError::BadEscape(format!("\\u{{{code}}}")))?;
                        out.push(ch);
                    }
                    other => return Err(LiteralError::BadEscape(format!("\\{other}"))),
                }
            }
            c => out.push(c),
        }
    }
    Err(LiteralError::UnterminatedString)
}

fn parse_floats(s: &str) -> Result<(Value, &str), LiteralError> {
    let mut rest = s[1..].trim_start();
    let mut out = Vec::new();
    if let Some(after) = rest.strip_prefix(']') {
        return Ok((Value::Floats(out), after));
    }
    loop {
        let end = rest
            .find(|c: char| c.is_whitespace() || c == ',' || c == ']')
            .ok_or_else(|| LiteralError::BadList("missing ']'".into()))?;
        let (token, after) = rest.split_at(end);
        if token.is_empty() {
            return Err(LiteralError::BadList(format!(
                "element {} is missing",
                out.len()
            )));
        }
        out.push(parse_float::<f64>(token)?);
        rest = after.trim_start();
        if let Some(after) = rest.strip_prefix(',') {
            rest = after.trim_start();
        } else if let Some(after) = rest.strip_prefix(']') {
            return Ok((Value::Floats(out), after));
        } else {
            return Err(LiteralError::BadList("expected ',' or ']'".into()));
        }
    }
}

/// Writes `x` so that it parses back to the same bits and never looks like an integer.
fn write_f64(f: &mut fmt::Formatter<'_>, x: f64) -> fmt::Result {
    // Debug prints the shortest round-trip form and keeps a ".0" or an exponent.
    write!(f, "{x:?}")
}

impl fmt::Display for Value {
    /// The literal form; see the module docs.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Value::Int(v) => write!(f, "{v}"),
            Value::Float(v) => write_f64(f, *v),
            Value::Bool(v) => write!(f, "{v}"),
            Value::String(s) => {
                f.write_char('"')?;
                for c in s.chars() {
                    match c {
                        '"' => f.write_str("\\\"")?,
                        '\\' => f.write_str("\\\\")?,
                        '\n' => f.write_str("\\n")?,
                        '\r' => f.write_str("\\r")?,
                        '\t' => f.write_str("\\t")?,
                        c if c.is_control() => write!(f, "\\u{{{:x}}}", c as u32)?,
                        c => f.write_char(c)?,
                    }
                }
                f.write_char('"')
            }
            Value::Floats(v) => {
                f.write_char('[')?;
                for (i, x) in v.iter().enumerate() {
                    if i > 0 {
                        f.write_str(", ")?;
                    }
                    write!(f, "{x:?}")?;
                }
                f.write_char(']')
            }
            Value::Bytes(b) => {
                f.write_str("0x")?;
                for byte in b {
                    write!(f, "{byte:02x}")?;
                }
                Ok(())
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn the_relay_protocols_examples_parse() {
        assert_eq!(parse_literal("42"), Ok(Value::Int(42)));
        assert_eq!(parse_literal(" -1 "), Ok(Value::Int(-1)));
        assert_eq!(parse_literal("4.2"), Ok(Value::Float(4.2)));
        assert_eq!(parse_literal("1e-3"), Ok(Value::Float(1e-3)));
        assert_eq!(parse_literal("true"), Ok(Value::Bool(true)));
        assert_eq!(
            parse_literal(r#""say \"hi\"\\\n""#),
            Ok(Value::String("say \"hi\"\\\n".into()))
        );
        assert_eq!(
            parse_literal("[1.5, 2,-3e-2]"),
            Ok(Value::Floats(vec![1.5, 2.0, -3e-2]))
        );
        assert_eq!(parse_literal("[ ]"), Ok(Value::Floats(vec![])));
        assert_eq!(parse_literal("0x0A0b"), Ok(Value::Bytes(vec![10, 11])));
        assert_eq!(parse_literal("0x"), Ok(Value::Bytes(vec![])));
        assert!(matches!(parse_literal("-inf"), Ok(Value::Float(x)) if x == f64::NEG_INFINITY));
        assert!(matches!(parse_literal("NaN"), Ok(Value::Float(x)) if x.is_nan()));
    }

    #[test]
    fn bad_literals_say_what_is_wrong() {
        assert_eq!(parse_literal(""), Err(LiteralError::Empty));
        assert_eq!(
            parse_literal("\"open"),
            Err(LiteralError::UnterminatedString)
        );
        assert_eq!(
            parse_literal(r#""\q""#),
            Err(LiteralError::BadEscape("\\q".into()))
        );
        assert!(matches!(
            parse_literal("99999999999999999999"),
            Err(LiteralError::IntOutOfRange(_))
        ));
        assert!(matches!(
            parse_literal("1.2.3"),
            Err(LiteralError::BadNumber(_))
        ));
        assert!(matches!(
            parse_literal("--1"),
            Err(LiteralError::BadNumber(_))
        ));
        assert!(matches!(
            parse_literal("hello"),
            Err(LiteralError::Unrecognized(_))
        ));
        assert!(matches!(parse_literal("0x0"), Err(LiteralError::BadHex(_))));
        assert!(matches!(
            parse_literal("0xzz"),
            Err(LiteralError::BadHex(_))
        ));
        assert!(matches!(
            parse_literal("[1, 2"),
            Err(LiteralError::BadList(_))
        ));
        assert!(matches!(
            parse_literal("[1,,2]"),
            Err(LiteralError::BadList(_))
        ));
        assert!(matches!(
            parse_literal("[1 2]"),
            Err(LiteralError::BadList(_))
        ));
        assert!(matches!(
            parse_literal("42 43"),
            Err(LiteralError::Trailing(_))
        ));
    }

    #[test]
    fn whole_floats_print_as_floats() {
        assert_eq!(Value::Float(1.0).to_string(), "1.0");
        assert_eq!(Value::Float(1e300).to_string(), "1e300");
        assert_eq!(Value::Floats(vec![2.0, 0.1]).to_string(), "[2.0, 0.1]");
        // Elements are f64: nothing is narrowed on the way through the printer.
        let wide = Value::Floats(vec![123456789.123, 1e-50, 1e300]);
        assert_eq!(wide.to_string(), "[123456789.123, 1e-50, 1e300]");
        assert_eq!(parse_literal(&wide.to_string()), Ok(wide));
        assert_eq!(
            Value::String("a\"b\u{1}".into()).to_string(),
            r#""a\"b\u{1}""#
        );
        assert_eq!(Value::Bytes(vec![0, 255]).to_string(), "0x00ff");
    }

    fn any_value() -> impl Strategy<Value = Value> {
        prop_oneof![
            any::<i64>().prop_map(Value::Int),
            any::<f64>().prop_map(Value::Float),
            any::<bool>().prop_map(Value::Bool),
            any::<String>().prop_map(Value::String),
            proptest::collection::vec(any::<f64>(), 0..8).prop_map(Value::Floats),
            proptest::collection::vec(any::<u8>(), 0..16).prop_map(Value::Bytes),
        ]
    }

    proptest! {
        #[test]
        fn every_value_prints_a_literal_that_parses_back_bit_for_bit(v in any_value()) {
            let text = v.to_string();
            let back = parse_literal(&text).map_err(|e| TestCaseError::fail(format!("{text:?}: {e}")))?;
            prop_assert!(back.same_as(&v), "{text:?} parsed back as {back:?}, not {v:?}");
        }

        #[test]
        fn arbitrary_text_never_panics(s in "\\PC{0,40}") {
            let _ = parse_literal(&s);
        }
    }
}

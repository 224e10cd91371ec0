//! The client's side of the relay's binding replies: one `VAL`/`UPD` line parsed back.

/// One `VAL`/`UPD` line, `WORD key type value age_ms [flag ...]`, as a session writes it.
/// The value is a literal and may hold spaces, so it is everything between the type and
/// the age; the age is the last all-digit word, and the words after it are flags (only
/// `departed` so far; unknown flags are skipped, so newer relays stay readable).
#[derive(Clone, Debug, PartialEq)]
pub struct Binding {
    /// The key as stored.
    pub key: String,
    /// The type name.
    pub ty: String,
    /// The value literal.
    pub value: String,
    /// Age in milliseconds when the line was written.
    pub age_ms: u64,
    /// The `departed` flag: the owner is departed (silent for longer than the
    /// departure limit), so the value is old news however young its age.
    pub departed: bool,
}

impl Binding {
    /// Parses `VAL ...` or `UPD ...`; `None` for any other line.
    pub fn parse(line: &str) -> Option<Binding> {
        let rest = line
            .strip_prefix("VAL ")
            .or_else(|| line.strip_prefix("UPD "))?;
        let (key, rest) = rest.split_once(' ')?;
        let (ty, mut rest) = rest.split_once(' ')?;
        let mut departed = false;
        // Flags are words of letters after the age; the age is all digits.
        let (value, age) = loop {
            let (before, last) = rest.rsplit_once(' ')?;
            if !last.is_empty() && last.bytes().all(|b| b.is_ascii_digit()) {
                break (before, last);
            }
            if last.is_empty() || !last.bytes().all(|b| b.is_ascii_alphabetic()) {
                return None;
            }
            departed |= last == "departed";
            rest = before;
        };
        Some(Binding {
            key: key.to_owned(),
            ty: ty.to_owned(),
            value: value.to_owned(),
            age_ms: age.parse().ok()?,
            departed,
        })
    }

    /// The owner: the key's first level (`3`, `local`).
    pub fn owner(&self) -> &str {
        self.key.split('.').next().unwrap_or("")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_string_value_with_spaces_parses_back_whole() {
        let b = Binding::parse(r#"VAL local.var.name string "say \"hi\" twice" 250"#)
            .expect("a VAL line");
        assert_eq!(b.key, "local.var.name");
        assert_eq!(b.ty, "string");
        assert_eq!(b.value, r#""say \"hi\" twice""#);
        assert_eq!(b.age_ms, 250);
        assert_eq!(b.owner(), "local");
        assert_eq!(
            Binding::parse("UPD 3.var.pose float 2.0 5").map(|b| b.age_ms),
            Some(5)
        );
        let departed = Binding::parse("UPD 3.var.pose float 2.0 5 departed").unwrap();
        assert_eq!(
            (departed.value.as_str(), departed.age_ms, departed.departed),
            ("2.0", 5, true)
        );
        assert!(!b.departed);
        let s = Binding::parse(r#"VAL 3.var.s string "a departed 7" 12 departed future"#)
            .expect("unknown flags are skipped");
        assert_eq!(
            (s.value.as_str(), s.age_ms, s.departed),
            (r#""a departed 7""#, 12, true)
        );
        for other in [
            "OK",
            "ERR 404 no such key",
            "VAL 3.var.x int 1 soon",
            "VAL 3.var.x int 1 5 de-parted",
            "VAL 3.var.x departed",
            "VAL x",
            "LOST 3.talk.q 4 7",
        ] {
            assert_eq!(Binding::parse(other), None, "{other:?} is not a binding");
        }
    }
}

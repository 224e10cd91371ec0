//! The client's side of the relay's binding replies: one `VAL`/`UPD` line parsed back.

/// One `VAL`/`UPD` line, `WORD key type value age_ms`, as a session writes it (the value
/// is a literal and may hold spaces, so it is everything between the type and the age).
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
}

impl Binding {
    /// Parses `VAL ...` or `UPD ...`; `None` for any other line.
    pub fn parse(line: &str) -> Option<Binding> {
        let rest = line
            .strip_prefix("VAL ")
            .or_else(|| line.strip_prefix("UPD "))?;
        let (key, rest) = rest.split_once(' ')?;
        let (ty, rest) = rest.split_once(' ')?;
        let (value, age) = rest.rsplit_once(' ')?;
        Some(Binding {
            key: key.to_owned(),
            ty: ty.to_owned(),
            value: value.to_owned(),
            age_ms: age.parse().ok()?,
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
        for other in [
            "OK",
            "ERR 404 no such key",
            "VAL 3.var.x int 1 soon",
            "VAL x",
        ] {
            assert_eq!(Binding::parse(other), None, "{other:?} is not a binding");
        }
    }
}

//! Strings across the boundary: reading the caller's NUL-terminated UTF-8, writing into
//! the caller's fixed buffers.

use std::ffi::{c_char, CStr};

use crate::error::{Failure, HUDDLE_E_UTF8};

/// The caller's string `ptr`, named `what` in errors.
///
/// # Safety
///
/// `ptr` is NULL or points to a NUL-terminated string that outlives `'a` and is not
/// written while it is borrowed.
pub(crate) unsafe fn read_str<'a>(ptr: *const c_char, what: &str) -> Result<&'a str, Failure> {
    if ptr.is_null() {
        return Err(Failure::null(what));
    }
    // SAFETY: non-NULL, and the caller promises a NUL-terminated string alive for 'a.
    let text = unsafe { CStr::from_ptr(ptr) };
    text.to_str()
        .map_err(|e| Failure::new(HUDDLE_E_UTF8, format!("{what} is not UTF-8: {e}")))
}

/// [`read_str`], with NULL meaning `None`.
///
/// # Safety
///
/// As [`read_str`].
pub(crate) unsafe fn read_opt_str<'a>(
    ptr: *const c_char,
    what: &str,
) -> Result<Option<&'a str>, Failure> {
    if ptr.is_null() {
        Ok(None)
    } else {
        // SAFETY: forwarded from the caller.
        unsafe { read_str(ptr, what) }.map(Some)
    }
}

/// Writes `text` into `buf` NUL-terminated, cut at a UTF-8 character boundary if it does
/// not fit; returns whether all of it fit.
pub(crate) fn write_text(buf: &mut [c_char], text: &str) -> bool {
    let Some(room) = buf.len().checked_sub(1) else {
        return text.is_empty();
    };
    let mut end = text.len().min(room);
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    for (dst, &src) in buf.iter_mut().zip(&text.as_bytes()[..end]) {
        *dst = src as c_char;
    }
    buf[end] = 0;
    end == text.len()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn as_string(buf: &[c_char]) -> String {
        let bytes: Vec<u8> = buf
            .iter()
            .take_while(|&&c| c != 0)
            .map(|&c| c as u8)
            .collect();
        String::from_utf8(bytes).expect("valid UTF-8")
    }

    #[test]
    fn text_is_cut_at_a_character_boundary_and_always_terminated() {
        let mut buf = [1 as c_char; 7];
        assert!(write_text(&mut buf, "héllo"), "6 bytes and the NUL");
        assert_eq!(as_string(&buf), "héllo");
        let mut buf = [1 as c_char; 3];
        assert!(!write_text(&mut buf, "éé"), "4 bytes do not fit in 2");
        assert_eq!(as_string(&buf), "é");
        assert!(!write_text(&mut [], "x"));
    }

    #[test]
    fn null_and_non_utf8_strings_are_errors() {
        // SAFETY: NULL, and a NUL-terminated literal.
        let null = unsafe { read_str(std::ptr::null(), "key") }.unwrap_err();
        assert_eq!(null.message, "key is NULL");
        let bad = b"\xff\xfe\0";
        // SAFETY: NUL-terminated static bytes.
        let bad = unsafe { read_str(bad.as_ptr().cast(), "key") }.unwrap_err();
        assert_eq!(bad.code, HUDDLE_E_UTF8);
    }
}
